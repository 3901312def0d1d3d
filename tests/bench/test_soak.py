"""``pibr bench soak`` end to end: legitimate clients beside hostile peers, real processes on loopback."""
import json

import pytest

from pibr.bench.hostile import KINDS
from pibr.bench.soak import _differences, print_soak, run_soak

pytestmark = [pytest.mark.integration, pytest.mark.gl]


def test_a_short_soak_with_every_hostile_kind_passes(tmp_path, capsys):
    r = run_soak(str(tmp_path), duration_s=12.0, clients=2, kinds=KINDS, run_s=0.5, view_size="128x128",
                 slow_byte_s=1.0, log=lambda *a: None)
    print_soak(r)
    shown = capsys.readouterr().out
    assert r["failures"] == [], shown
    assert r["legitimate_runs"] >= 2 and r["runs_equal_to_solo"] == r["legitimate_runs"], shown
    assert r["server"]["tracebacks"] == 0 and r["server"]["internal_errors"] == 0, shown
    assert r["server"]["open_files_after"] <= r["server"]["open_files_before"] + 2, shown
    for kind in KINDS:
        assert r["hostile"][kind]["connections"] >= 1, (kind, shown)
        # the server closes every hostile connection itself; none waits for the peer to give up
        assert r["hostile"][kind]["server_never_closed"] == 0, (kind, shown)
    # Malformed input is answered with an error naming the problem, never an internal error.
    answers = {k: " ".join(r["hostile"][k]["answers"]) for k in KINDS}
    assert "nesting" in answers["nested-json"].lower() or "deep" in answers["nested-json"].lower(), shown
    assert "internal" not in " ".join(answers.values()), shown
    assert r["passed"], shown
    saved = json.load(open(tmp_path / "soak.json"))
    assert saved["passed"] and saved["clients"] == 2


def test_a_soaked_run_that_differs_from_its_solo_run_is_caught():
    solo = {"frames_received": 5, "ticks": 5, "missed_deadlines": 0, "frame_arrivals_s": [0.1, 0.2],
            "records": [{"tick": "0", "frame_id": "3"}, {"tick": "1", "frame_id": "4"}]}
    assert _differences(solo, dict(solo)) == []
    later = dict(solo, records=[{"tick": "0", "frame_id": "3"}, {"tick": "1", "frame_id": "3"}])
    assert _differences(solo, later) == ["tick 1: frame_id solo 4 soak 3"]
    assert _differences(solo, dict(solo, frames_received=4)) == ["frames_received: solo 5 soak 4"]
