"""``pibr bench fuzz``: every parser survives a few thousand mutated inputs, and the engine
really counts undocumented exceptions, crashes and hangs (a broken toy parser shows it)."""
import json
import os
import time

import pytest

from pibr.bench import fuzz_targets
from pibr.bench.fuzz import fuzz_parser, make_input, run_fuzz_bench
from pibr.bench.fuzz_targets import Seed, Target

INPUTS = 3000


def test_every_parser_raises_only_documented_errors(tmp_path):
    result = run_fuzz_bench(inputs=INPUTS, seed=0, out_dir=str(tmp_path), progress=False)
    assert set(result["parsers"]) == {"wire", "edge", "quadtree", "proxy", "trace", "scene"}
    for name, r in result["parsers"].items():
        assert r["inputs"] == INPUTS, name
        assert r["undocumented"] == {} and r["undocumented_examples"] == [], (name, r["undocumented_examples"])
        assert r["hangs"] == 0, (name, r["hang_examples"])
        assert r["seeds_rejected"] == [], name
        # the mutants reach both outcomes: some parse, most are refused with a documented error
        assert 0 < r["accepted"] < INPUTS and sum(r["documented_errors"].values()) > INPUTS // 2, name
        assert r["accepted"] + sum(r["documented_errors"].values()) == INPUTS
        assert r["peak_rss_mb"] > 0 and r["workers_started"] == 1
    assert result["ok"]
    with open(tmp_path / "fuzz.json") as f:
        assert json.load(f)["parsers"]["wire"]["inputs"] == INPUTS


class Toy(Target):
    """A deliberately broken parser: documented KeyError, an undocumented ZeroDivisionError, a
    crash, a hang, each on its own rare shape of input."""

    def __init__(self):
        super().__init__("toy", (KeyError,))

    def build(self):
        self.seeds = [Seed("text", b"hello fuzzing world", text=True), Seed("bin", bytes(range(40)))]

    @staticmethod
    def outcome(data: bytes) -> str:
        if data[:1] == b"h" and len(data) == 17:
            return "hang"
        if data[:1] == b"\x00" and len(data) == 38:
            return "crash"
        if b"99" in data:
            return "undocumented"
        return "documented" if len(data) % 3 == 0 else "accepted"

    def run(self, kind, data):
        outcome = self.outcome(data)
        if outcome == "hang":
            time.sleep(600)
        if outcome == "crash":
            os._exit(3)
        if outcome == "undocumented":
            raise ZeroDivisionError("toy")
        if outcome == "documented":
            raise KeyError("toy")


def test_engine_counts_undocumented_exceptions_crashes_and_hangs(tmp_path):
    toy = Toy()
    toy.build()
    n = 400
    expected = [toy.outcome(make_input(toy, 5, i)[1]) for i in range(n)]
    counts = {k: expected.count(k) for k in ("hang", "crash", "undocumented", "documented", "accepted")}
    assert 1 <= counts["hang"] <= 3 and counts["crash"] >= 1 and counts["undocumented"] >= 1, counts

    r = fuzz_parser(toy, n, seed=5, timeout_s=0.5, out_dir=str(tmp_path))
    assert r["inputs"] == n
    assert r["hangs"] == counts["hang"]
    assert r["undocumented"] == {"ZeroDivisionError": counts["undocumented"], "WorkerDied(3)": counts["crash"]}
    assert r["documented_errors"] == {"KeyError": counts["documented"]}
    assert r["accepted"] == counts["accepted"]
    assert r["workers_started"] == 1 + counts["hang"] + counts["crash"]
    hang = r["hang_examples"][0]
    with open(hang["input"], "rb") as f:   # the saved input reproduces: it is input `index` regenerated
        assert f.read() == make_input(toy, 5, hang["index"])[1]
    assert toy.outcome(make_input(toy, 5, hang["index"])[1]) == "hang"
    crash = next(e for e in r["undocumented_examples"] if e["class"] == "WorkerDied(3)")
    assert toy.outcome(make_input(toy, 5, crash["index"])[1]) == "crash"
    zero = next(e for e in r["undocumented_examples"] if e["class"] == "ZeroDivisionError")
    assert "ZeroDivisionError: toy" in zero["traceback"] and os.path.isfile(zero["input"])


def test_cli_fails_on_a_broken_parser_and_replays_its_input(tmp_path, monkeypatch, capsys):
    from pibr.cli import main

    monkeypatch.setitem(fuzz_targets.TARGETS, "toy", Toy)
    out = tmp_path / "out"
    code = main(["bench", "fuzz", "--parsers", "toy", "--inputs", "120", "--seed", "5", "--timeout-s", "0.5",
                 "--out", str(out)])
    text = capsys.readouterr().out
    assert code == 1 and "FAILED" in text and "UNDOCUMENTED ZeroDivisionError" in text
    saved = sorted(p for p in os.listdir(out / "fuzz_inputs") if Toy.outcome((out / "fuzz_inputs" / p).read_bytes())
                   == "undocumented")
    assert saved
    assert main(["bench", "fuzz", "--replay", str(out / "fuzz_inputs" / saved[0])]) == 1
    assert "ZeroDivisionError: toy" in capsys.readouterr().out


def test_cli_passes_on_real_parsers(tmp_path, capsys):
    from pibr.cli import main

    assert main(["bench", "fuzz", "--parsers", "wire,trace", "--inputs", "200", "--out", str(tmp_path)]) == 0
    assert "ok, 0 undocumented exceptions and 0 hangs" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        main(["bench", "fuzz", "--inputs", "0"])


def test_unknown_parser_is_a_config_error(tmp_path):
    from pibr.protocol.errors import ConfigError

    with pytest.raises(ConfigError, match="unknown parser"):
        run_fuzz_bench(parsers=["nope"], inputs=1, out_dir=str(tmp_path))
