"""The deadline controller (pibr.common.quality) with the client's levels (client/deadline.py):
levels chosen against a cost table, hysteresis, the fallback, the cost model, the cost table's
round trip (no GL: it is arithmetic)."""
import json

import pytest

from pibr.client.deadline import FALLBACK, levels_for
from pibr.common.quality import CHEAPEST, DOWN, HELD, TOP, UP, DeadlineController, Level, read_cost_table
from pibr.protocol.errors import ConfigError

PROXY = levels_for("proxy")
NAMES = [lv.name for lv in PROXY]


def _table(ms):
    return {"proxy": dict(zip(NAMES, ms))}


def test_every_level_fits_on_a_fast_machine_so_the_top_level_is_kept():
    c = DeadlineController({"proxy": PROXY}, 1000 / 90, costs=_table([2.0, 1.8, 1.5, 1.2, 1.1, 1.0, 0.9, 0.5]),
                           adapt=False)
    choices = [c.choose()["proxy"] for _ in range(200)]
    assert set(choices) == {(0, TOP)}
    assert c.summary()["methods"]["proxy"]["share_at_level"]["full"] == 1.0


def test_the_best_level_that_fits_is_chosen_and_stays():
    costs = [90.0, 75.0, 60.0, 40.0, 30.0, 25.0, 20.0, 8.0]     # 33.3 ms ticks, 1 ms margin: 30 fits
    c = DeadlineController({"proxy": PROXY}, 1000 / 30, costs=_table(costs), adapt=False)
    first = c.choose()["proxy"]
    assert first == (4, DOWN)
    later = [c.choose()["proxy"] for _ in range(100)]
    assert set(later) == {(4, HELD)}      # the level above (40 ms) never fits
    assert c.budget_ms == pytest.approx(1000 / 30 - 1.0)


def test_nothing_fits_so_the_cheapest_is_shown():
    c = DeadlineController({"proxy": PROXY}, 1000 / 120, costs=_table([90, 80, 70, 60, 50, 40, 30, 20]), adapt=False)
    assert c.choose()["proxy"] == (len(PROXY) - 1, CHEAPEST)
    assert PROXY[-1] == FALLBACK and FALLBACK.method == "rotation"


def test_hysteresis_goes_down_at_once_and_up_only_after_room_for_long_enough():
    levels = {"m": (Level("a", "m"), Level("b", "m", 0.5))}
    c = DeadlineController(levels, 30.0, adapt=True, margin_ms=0.0, up_after=10, up_headroom=0.85, alpha=0.5)
    c.observe("m", 0, 20.0)
    c.observe("m", 1, 5.0)
    assert c.choose()["m"] == (0, TOP)
    for _ in range(3):
        c.observe("m", 0, 40.0)          # the top level got slow: over the budget
    assert c.choose()["m"] == (1, DOWN)
    for _ in range(20):
        c.observe("m", 0, 10.0)          # fast again (as if measured elsewhere): room, but not at once
    got = [c.choose()["m"] for _ in range(12)]
    assert got[:9] == [(1, HELD)] * 9 and got[9] == (0, UP)
    assert got[10:] == [(0, TOP)] * 2


def test_costs_that_straddle_the_budget_do_not_make_the_level_flicker():
    levels = {"m": (Level("a", "m"), Level("b", "m", 0.5))}
    c = DeadlineController(levels, 30.0, adapt=True, margin_ms=0.0)
    c.observe("m", 1, 10.0)
    changes, last = 0, None
    for k in range(600):
        c.observe("m", 0, 27.0 if k % 2 else 31.0)    # around a 30 ms budget
        level = c.choose()["m"][0]
        changes += last is not None and level != last
        last = level
    assert last == 1 and changes <= 2


def test_two_methods_the_costlier_gives_way_first():
    levels = {"proxy": PROXY, "rotation": levels_for("rotation")}
    costs = {**_table([28.0, 20.0, 15.0, 10.0, 9.0, 8.0, 7.0, 3.0]), "rotation": {"full": 6.0, "1/2": 4.0, "1/3": 3.0}}
    c = DeadlineController(levels, 1000 / 30, costs=costs, adapt=False)
    chosen = c.choose()
    assert chosen["rotation"] == (0, TOP)               # 28 + 6 > 32.3: the proxy goes down, not the rotation
    assert chosen["proxy"] == (1, DOWN)


def test_without_estimates_the_top_levels_are_drawn_and_unmeasured_levels_are_scaled():
    c = DeadlineController({"proxy": PROXY}, 1000 / 30)
    assert c.choose()["proxy"] == (0, TOP)
    c.observe("proxy", 2, 40.0)                       # 3/4: 40 ms
    assert c.predicted("proxy", 3) == pytest.approx(40.0 * (0.5 / 0.75) ** 2)
    assert c.predicted("proxy", 0) == pytest.approx(40.0 * (1 / 0.75) ** 2)
    assert c.predicted("proxy", 7) is None              # the fallback is another method: not guessed


def test_adapt_off_keeps_the_table():
    c = DeadlineController({"proxy": PROXY}, 1000 / 30, costs=_table([90, 75, 60, 40, 30, 25, 20, 8]), adapt=False)
    before = c.choose()
    c.observe("proxy", 4, 500.0)
    c.observe_overhead(30.0)
    assert c.choose()["proxy"][0] == before["proxy"][0] and c.budget_ms == pytest.approx(1000 / 30 - 1)


def test_the_cost_table_round_trips_through_files(tmp_path):
    c = DeadlineController({"proxy": PROXY}, 1000 / 30)
    for k, ms in enumerate([50, 45, 38, 27, 25, 18, 16, 8]):
        c.observe("proxy", k, ms)
    table = c.cost_table()
    assert table["proxy"]["1/2, no inpainting"] == 27
    (tmp_path / "session.json").write_text(json.dumps({"deadline": {"costs_ms": table}}))
    (tmp_path / "levels.json").write_text(json.dumps({"costs_ms": table}))
    (tmp_path / "table.json").write_text(json.dumps(table))
    for name in ("session.json", "levels.json", "table.json"):
        again = DeadlineController({"proxy": PROXY}, 1000 / 30, costs=read_cost_table(str(tmp_path / name)))
        assert again.cost_table() == table


@pytest.mark.parametrize("table, message", [
    ({"proxy": {"huge": 3.0}}, "has no level 'huge'"),
    ({"proxy": {"full": -1}}, "expected ms in"),
    ({"proxy": {"full": True}}, "expected ms in"),
    ({"proxy": [1, 2]}, "must be an object"),
])
def test_bad_cost_tables_are_named(table, message):
    with pytest.raises(ConfigError, match=message):
        DeadlineController({"proxy": PROXY}, 1000 / 30, costs=table)


def test_a_file_that_is_no_cost_table_is_refused(tmp_path):
    (tmp_path / "x.json").write_text("[1, 2]")
    with pytest.raises(ConfigError, match="expected an object"):
        read_cost_table(str(tmp_path / "x.json"))
    with pytest.raises(ConfigError, match="cost table"):
        read_cost_table(str(tmp_path / "missing.json"))


def test_a_level_measured_slow_before_the_clock_is_tried_again_when_the_drawn_one_says_it_fits():
    levels = {"m": (Level("a", "m"), Level("b", "m", 0.75), Level("c", "m", 0.5))}
    c = DeadlineController(levels, 33.3, margin_ms=0.0, up_after=5)
    for k, ms in enumerate((100.0, 50.0, 20.0)):     # calibrated while the machine was busy
        c.calibrate("m", k, ms)
    assert c.choose()["m"] == (2, DOWN)
    for _ in range(40):
        c.observe("m", 2, 10.0)                     # now the drawn level runs twice as fast
        level = c.choose()["m"][0]
    assert c.predicted("m", 1) == pytest.approx(25.0, rel=0.05)   # 50 x 0.5: the factor follows
    assert level == 1


def test_the_fallback_says_nothing_of_how_fast_the_method_itself_runs():
    c = DeadlineController({"proxy": PROXY}, 1000 / 30)
    for k, ms in enumerate([90, 80, 60, 40, 35, 30, 25, 8]):
        c.calibrate("proxy", k, ms)
    for _ in range(30):
        c.observe("proxy", len(PROXY) - 1, 16.0)      # the rotation fallback runs at half its speed
    assert c.predicted("proxy", len(PROXY) - 1) > 15.0
    assert c.predicted("proxy", len(PROXY) - 2) == pytest.approx(25.0)   # proxy's own levels keep their base


def test_one_slow_first_tick_moves_the_estimate_a_step_not_all_the_way():
    c = DeadlineController({"proxy": PROXY}, 1000 / 30)
    for k, ms in enumerate([61, 48, 38, 24.6, 28, 15.6, 13, 5.4]):
        c.calibrate("proxy", k, ms)
    assert c.choose()["proxy"] == (3, DOWN)
    c.observe("proxy", 3, 39.0)                      # the clock's first tick: 1.6x its calibration
    assert c.predicted("proxy", 3) < 24.6 * 1.3
    assert c.choose()["proxy"] == (3, HELD)
    factors = c.summary()["speed_factor"]["proxy"]
    assert factors["rotation"] is None and factors["proxy"] > 1.0    # the fallback never measured: no factor


def test_a_method_pushed_to_its_fallback_by_a_burst_is_tried_again():
    c = DeadlineController({"proxy": PROXY}, 1000 / 30)
    for k, ms in enumerate([61, 48, 38, 24, 20, 15.6, 13, 5.4]):
        c.calibrate("proxy", k, ms)
    last = len(PROXY) - 1
    level = c.choose()["proxy"][0]
    for _ in range(12):                              # a burst: the machine runs the proxy 3x slower
        c.observe("proxy", level, 3 * c._base["proxy"][level])
        level = c.choose()["proxy"][0]
    assert level == last
    back = None
    for tick in range(300):                          # the burst is over: only the fallback is measured
        level = c.choose()["proxy"][0]
        if level != last:
            back = tick
            break
        c.observe("proxy", level, 5.4)
    assert back is not None and back < 150            # before: the proxy's factor stayed at 3x for ever
    for _ in range(200):                             # and at its calibrated speed it climbs back
        c.observe("proxy", level, c._base["proxy"][level])
        level = c.choose()["proxy"][0]
    assert level == 3

