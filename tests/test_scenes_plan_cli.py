"""``pibr scenes --plan``: the plan as a table and as JSON, and bad input as one clear line."""
import json

import pytest

from pibr.cli import main

pytestmark = pytest.mark.gl


def test_plan_table_for_a_builtin_scene(capsys):
    assert main(["scenes", "--plan", "sphere", "--output", "1280x720", "--fov", "70"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("plan for scene sphere\n")
    lines = {line.split()[0]: line for line in out.splitlines()[2:7]}
    assert list(lines) == ["extra_view", "motion", "proxies", "view_size", "depth_codec"]
    assert lines["extra_view"].split()[1] == "off" and "geometry pixels uncovered" in lines["extra_view"]
    assert lines["motion"].split()[1] == "off"
    assert "2048x2048" in lines["view_size"]          # Reinert et al.'s size for 1280x720 at 70 degrees
    assert "1 proxy, 0 box" in lines["proxies"]
    assert "sphere  proxy" in out                      # the per-object table
    lod = next(line for line in out.splitlines() if line.startswith("lod "))
    assert "6.0 px" in lod and "0.0125 rad" in lod and "at every output size" in lod


def test_plan_says_where_each_level_is_drawn_and_the_output_size_does_not_change_it(capsys):
    plans = {}
    for size in ("480x270", "1920x1080"):
        assert main(["scenes", "--plan", "sphere", "--json", "--output", size]) == 0
        plans[size] = json.loads(capsys.readouterr().out)
    lod = plans["480x270"]["lod"]
    assert lod == plans["1920x1080"]["lod"] and lod["target_px"] == 6.0
    sphere = lod["objects"]["sphere"]
    assert 0 < sphere["original_within_m"] < sphere["level_within_m"]


def test_plan_json_with_a_bandwidth_and_a_dynamic_scene(capsys):
    assert main(["scenes", "--plan", "dynamic", "--json", "--bandwidth-kbps", "8000", "--edge-kbps", "500",
                 "--extra-view", "on"]) == 0
    plan = json.loads(capsys.readouterr().out)
    assert plan["scene"] == "dynamic" and plan["extra_view"]["value"] is True
    assert plan["motion"]["value"] is True and plan["motion"]["measured"]["moving_objects"]["spinner"] == "spin"
    assert plan["depth_codec"]["measured"]["bandwidth_kbps"] == 8000
    assert plan["depth_codec"]["value"] == {"codec": "edge", "video_kbps": 7500.0}


@pytest.mark.parametrize("argv, message", [
    (["--plan", "no-such-scene"], "unknown scene 'no-such-scene'; built-in scenes:"),
    (["--plan", "sphere", "--fov", "200"], "field 'fov_deg' = 200.0 is outside [1.0, 170.0]"),
    (["--plan", "sphere", "--bandwidth-kbps", "-1"], "field 'bandwidth_kbps' = -1.0 is outside"),
])
def test_plan_refuses_bad_input_in_one_line(capsys, argv, message):
    assert main(["scenes", *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1 and "Traceback" not in err
