"""The README's benchmark tables against the result files under docs/results/ (issue 26, item 7):
every table of the benchmark section is announced by a marker naming its file, and renders from
it to what the README shows."""
from __future__ import annotations

import os
import shutil

import pytest

from pibr.bench.readme_tables import check, main, render

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
README = os.path.join(ROOT, "README.md")


def test_every_benchmark_table_matches_its_result_file():
    problems = check(README, ROOT)
    assert problems == [], "\n".join(problems)


def _copy(tmp_path):
    shutil.copytree(os.path.join(ROOT, "docs", "results"), tmp_path / "docs" / "results")
    with open(README) as f:
        return f.read()


def _new_problems(tmp_path, text, baseline):
    """The problems ``check`` finds in ``text`` that are not in ``baseline`` (line numbers aside)."""
    (tmp_path / "README.md").write_text(text)
    known = {p.split(": ", 1)[1] for p in baseline}
    return [p for p in check(str(tmp_path / "README.md"), str(tmp_path)) if p.split(": ", 1)[1] not in known]


def test_a_changed_figure_or_an_unannounced_table_is_reported(tmp_path):
    text = _copy(tmp_path)
    baseline = _new_problems(tmp_path, text, [])
    rows = render("levels", ["docs/results/levels.json"], ROOT)
    row = rows[2]                                    # the first level's row
    assert row in text
    cells = row.split(" | ")
    cells[4] = "9.99"                                # its "x top" figure
    problems = _new_problems(tmp_path, text.replace(row, " | ".join(cells), 1), baseline)
    assert len(problems) == 1 and "'levels'" in problems[0] and "9.99" in problems[0], problems

    marker = "<!-- table: levels from docs/results/levels.json -->\n"
    problems = _new_problems(tmp_path, text.replace(marker, "", 1), baseline)
    assert len(problems) == 1 and "no result file announced" in problems[0], problems

    problems = _new_problems(tmp_path, text.replace(marker, marker.replace("levels.json", "gone.json"), 1), baseline)
    assert len(problems) == 1 and "gone.json" in problems[0], problems


def test_write_brings_a_stale_table_back_from_its_file(tmp_path):
    text = _copy(tmp_path)
    rows = render("levels", ["docs/results/levels.json"], ROOT)
    stale = text.replace(rows[2], rows[2].replace("full", "whole", 1), 1)
    assert stale != text
    readme = tmp_path / "README.md"
    readme.write_text(text)
    baseline = check(str(readme), str(tmp_path))
    readme.write_text(stale)
    assert len(check(str(readme), str(tmp_path))) == len(baseline) + 1
    main(["--readme", str(readme), "--root", str(tmp_path), "--write"])
    assert check(str(readme), str(tmp_path)) == baseline
    assert rows[2] in readme.read_text() and "whole" not in readme.read_text().split(rows[1])[1].split("\n\n")[0]


def test_unknown_table_names_are_reported():
    with pytest.raises(KeyError, match="unknown README table"):
        render("nonsense", [], ROOT)
