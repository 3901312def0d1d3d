"""The report page in a real browser (headless Chromium driven by Playwright, tests/conftest.py):
what a user sees."""
from __future__ import annotations

import io
import json
import os
import pathlib
import shutil

import numpy as np
import pytest

from pibr.bench.report import METRIC_COLUMNS, write_report

from .report_run import METHODS, RATE_HZ, TICKS, make_run, panel_colour

ROOT = pathlib.Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def browser(chromium):
    return chromium


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    out = str(tmp_path_factory.mktemp("run"))
    make_run(out)
    write_report(out)
    return out


class Page:
    """A page of the report with every console error and uncaught exception it raised."""

    def __init__(self, browser, path):
        self.page = browser.new_page(viewport={"width": 1400, "height": 1000})
        self.errors = []
        self.page.on("console", lambda m: self.errors.append(m.text) if m.type == "error" else None)
        self.page.on("pageerror", lambda e: self.errors.append(str(e)))
        self.page.goto(pathlib.Path(path).as_uri())

    def close(self):
        self.page.close()


@pytest.fixture
def page(browser, run_dir):
    p = Page(browser, os.path.join(run_dir, "report.html"))
    yield p
    p.close()


def _mean_colour(png: bytes) -> np.ndarray:
    from PIL import Image

    img = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), np.float64)
    h, w = img.shape[:2]
    return img[h // 4: 3 * h // 4, w // 4: 3 * w // 4].reshape(-1, 3).mean(axis=0)


def _wait_for_tick(page, tick):
    page.wait_for_function(f"Array.from(document.querySelectorAll('#scrubber canvas'))"
                           f".every(c => c.dataset.tick === '{tick}')", timeout=15000)


def test_opens_without_errors_and_the_table_equals_metrics_json(page, run_dir):
    pg = page.page
    pg.wait_for_selector("#metrics")
    metrics = json.load(open(os.path.join(run_dir, "metrics.json")))["methods"]
    shown = pg.evaluate("""Array.from(document.querySelectorAll('#metrics tr[data-method]')).map(tr =>
        [tr.dataset.method, Object.fromEntries(Array.from(tr.querySelectorAll('td')).map(td =>
            [td.dataset.key, td.innerText]))])""")
    assert [m for m, _ in shown] == list(METHODS)
    for m, cells in shown:
        for key, _, scale, fmt in METRIC_COLUMNS:
            digits = 0 if fmt == "d" else int(fmt[1])
            assert float(cells[key]) == pytest.approx(metrics[m][key] * scale, abs=0.51 * 10 ** -digits), (m, key)
    assert page.errors == []


def test_videos_play_and_stay_in_sync(page):
    pg = page.page
    pg.wait_for_function("Array.from(document.querySelectorAll('video.sync')).every(v => v.readyState >= 3)",
                         timeout=15000)
    pg.click("#play")
    pg.wait_for_timeout(1200)
    times = pg.evaluate("Array.from(document.querySelectorAll('video.sync')).map(v => [v.currentTime, v.paused])")
    assert len(times) == len(METHODS) + 1
    assert all(not paused for _, paused in times)
    t = [x for x, _ in times]
    assert min(t) > 0.5, t                               # they play
    assert max(t) - min(t) <= 1.5 / RATE_HZ, t            # within a frame and a half of each other
    pg.click("#pause")
    assert pg.evaluate("Array.from(document.querySelectorAll('video.sync')).every(v => v.paused)")
    assert page.errors == []


@pytest.mark.parametrize("tick", [0, 17, TICKS - 1])
def test_the_scrubber_shows_each_methods_panels_of_the_chosen_tick(page, tick):
    pg = page.page
    _wait_for_tick(pg, 0)
    pg.fill("#tick", str(tick))
    pg.dispatch_event("#tick", "input")
    _wait_for_tick(pg, tick)
    for r in range(len(METHODS)):
        for p in range(3):
            got = _mean_colour(pg.locator(f'#scrubber canvas[data-row="{r}"][data-panel="{p}"]').screenshot())
            want = np.array(panel_colour(r, p, tick), np.float64)
            # blue steps by 3 a tick: a neighbouring tick's panel would be 3 off
            assert np.abs(got - want).max() < 2.9, (r, p, got, want)
    readout = pg.inner_text('#scrubber .readout[data-method="proxy"]')
    assert readout.startswith("DSSIM 0.1") and "level" in readout
    assert f"tick {tick}" in pg.inner_text("#tick-label")
    assert page.errors == []


def test_plots_read_a_tick_on_hover_and_show_it_on_click(page):
    pg = page.page
    _wait_for_tick(pg, 0)
    svg = pg.locator('.plot[data-series="dssim"] svg')
    svg.scroll_into_view_if_needed()
    box = svg.bounding_box()
    # the plot's x axis spans 60..890 of its 900-unit width: three quarters along is tick ~44
    x = box["x"] + box["width"] * (60 + 0.75 * 830) / 900
    pg.mouse.move(x, box["y"] + box["height"] / 2)
    tip = pg.inner_text('.plot[data-series="dssim"] .tip')
    tick = int(tip.split(":")[0].split()[1])
    assert abs(tick - 0.75 * (TICKS - 1)) <= 1 and all(m in tip for m in METHODS)
    pg.mouse.click(x, box["y"] + box["height"] / 2)
    assert pg.input_value("#tick") == str(tick)
    _wait_for_tick(pg, tick)
    assert page.errors == []


def test_a_benchmark_folder_names_the_pareto_variant_under_the_pointer(browser, tmp_path):
    for name in ("pareto.json", "network.json"):
        shutil.copy(ROOT / "docs" / "results" / name, tmp_path / name)
    shutil.copy(ROOT / "docs" / "network.png", tmp_path / "network.png")
    p = Page(browser, write_report(str(tmp_path)))
    try:
        pg = p.page
        pg.locator("#pareto-plot svg").scroll_into_view_if_needed()
        # points may overlap: take one that is on top at its own centre, as the pointer would
        on_top = pg.evaluate("""Array.from(document.querySelectorAll('#pareto-plot circle')).map(c => {
            const r = c.getBoundingClientRect(), x = r.x + r.width / 2, y = r.y + r.height / 2;
            return [c.dataset.variant, x, y, document.elementFromPoint(x, y) === c]; }).filter(v => v[3])""")
        assert len(on_top) >= 10
        for variant, x, y, _ in on_top[:: max(1, len(on_top) // 5)]:
            pg.mouse.move(x, y)
            assert pg.inner_text("#pareto-label").startswith(f"room · {variant}: DSSIM 0.")
        assert pg.locator("section.bench table").count() == 3           # pareto, pareto-windows, network
        assert pg.evaluate("document.querySelector('#images img').naturalWidth") > 100   # the PNG shows
        assert p.errors == []
    finally:
        p.close()
