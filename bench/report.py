"""One page that shows a run: ``pibr report OUT`` writes ``OUT/report.html``.

The page is a single file that opens from disk in a browser with no server and no internet:
its styles, scripts, plots (PNG as data URIs, time series as inline SVG drawn by its own script)
and data are inside it. Only the run's videos stay beside it as files, referenced by relative
paths, so the folder can be moved or copied whole.

What it shows, from what the folder holds:

* a client run scored by ``pibr evaluate`` (``pibr demo`` writes one): the parameters of the
  session (``session.json``), the metrics table (``metrics.json``), each method's video and the
  side-by-side video playing in sync, a frame scrubber that shows, for the chosen tick, each
  method's image, the ground truth and the error map (cut from ``side_by_side.mp4``, whose rows
  are the methods and whose columns are those three), the per-tick numbers of that tick
  (``metrics_frames.csv``, ``<method>.records.csv``), and plots over time you can hover and
  click to scrub;
* benchmark results (``pibr bench ...`` writes one JSON per benchmark): their tables, rendered
  by the same code as the README's (bench/readme_tables.py), an interactive scatter for
  ``pareto.json`` (hovering a point names the variant), the JSON itself, folded;
* every PNG plot in the folder.
"""
from __future__ import annotations

import base64
import csv
import html
import json
import math
import os
from importlib import resources

from pibr.protocol.errors import ConfigError

REPORT_NAME = "report.html"

#: Benchmark result files -> the README table renderers that read them (bench/readme_tables.py).
BENCH_TABLES = {
    "realtime.json": ("realtime",), "levels.json": ("levels",), "pareto.json": ("pareto", "pareto-windows"),
    "coverage.json": ("coverage",), "dynamic.json": ("dynamic",), "ibr.json": ("ibr",), "split.json": ("split",),
    "codec.json": ("codec-matched", "codec-end-to-end"), "stereo.json": ("stereo", "stereo-server"),
    "predict.json": ("predict", "predict-quality"), "network.json": ("network",),
    "bench_server.json": ("server-projection",), "live.json": ("live",), "cluster.json": ("cluster",),
    "scoring.json": ("scoring", "scoring-stages"),
}
#: Other JSON a benchmark writes: shown folded, without a table.
BENCH_FILES = ("trade.json", "codec_speed.json", "proxy_speed.json", "bench_client.json", "lod.json",
               "offset_search.json", "soak.json", "fuzz.json")
#: The metrics table's columns: (key in metrics.json's per-method entry, heading, scale, format).
METRIC_COLUMNS = (
    ("psnr_mean", "PSNR dB", 1, ".2f"), ("ssim_mean", "SSIM", 1, ".4f"), ("dssim_mean", "DSSIM", 1, ".4f"),
    ("flip_mean", "FLIP", 1, ".4f"), ("geometric_holes_mean", "geo holes %", 100, ".2f"),
    ("hole_fraction_mean", "own holes %", 100, ".2f"), ("client_ms_median", "client ms", 1, ".1f"),
    ("age_ms_mean", "age ms", 1, ".0f"), ("missed_deadlines", "missed ticks", 1, "d"), ("frames", "frames", 1, "d"),
)
#: Per-tick series for the plots: (file, column, plot title).
FRAME_SERIES = (("dssim", "DSSIM (lower is better)"), ("psnr", "PSNR dB (higher is better)"))
RECORD_SERIES = (("age_ms", "frame age ms"), ("client_ms", "client ms per tick"), ("level", "quality level (0 best)"))
#: The session's series from stream.csv (client/live.py), per tick the newest value: (column, title).
STREAM_SERIES = (("server_fps", "server frames/s (last second)"), ("kbps", "kbit/s received (last second)"),
                 ("decode_ms", "decode ms per batch of frames"))


def _esc(x) -> str:
    return html.escape(str(x), quote=True)


def _script_json(data) -> str:
    """JSON safe inside a <script> element (no '</' can close it early)."""
    return json.dumps(data, separators=(",", ":"), allow_nan=False).replace("</", "<\\/")


def _asset(name: str) -> str:
    return resources.files("pibr.bench").joinpath(name).read_text(encoding="utf-8")


def _png_data_uri(path: str) -> str:
    with open(path, "rb") as f:
        return "data:image/png;base64," + base64.b64encode(f.read()).decode("ascii")


def _load_json(path: str):
    from pibr.protocol import bounded_json
    from pibr.protocol.errors import JSONError

    try:
        with open(path, "rb") as f:
            return bounded_json.loads(f.read(bounded_json.MAX_TEXT_BYTES + 1), what=path)
    except (OSError, JSONError) as exc:
        raise ConfigError(f"cannot read {path}: {exc}") from None


def _number(text: str) -> float | None:
    if text in ("", None):
        return None
    try:
        v = float(text)
    except ValueError:
        return None
    return v if math.isfinite(v) else None


def _read_csv(path: str) -> list[dict]:
    try:
        with open(path, newline="") as f:
            return list(csv.DictReader(f))
    except OSError as exc:
        raise ConfigError(f"cannot read {path}: {exc}") from None


def _format(value, scale: float, fmt: str) -> str:
    if value is None:
        return "—"
    if fmt == "d":
        return str(int(value))
    return format(value * scale, fmt)


# -- a client run --------------------------------------------------------------------------------------------------

def _is_run(metrics) -> bool:
    return isinstance(metrics, dict) and isinstance(metrics.get("methods"), dict) and "output" in metrics


def _parameters(out_dir: str, metrics: dict) -> list[tuple[str, str]]:
    """(name, value) rows describing the run: from metrics.json, and session.json when present."""
    out = metrics["output"]
    rows = [("scene", metrics.get("scene")), ("clock", metrics.get("clock")),
            ("output", f"{out['width']}×{out['height']} at {out['rate_hz']:g} Hz, {out['fov_deg']:g}° field of view")]
    trace = metrics.get("trace")
    if isinstance(trace, dict):
        rows.append(("head trace", ", ".join(f"{k} {v}" for k, v in trace.items() if not isinstance(v, (dict, list)))))
    path = os.path.join(out_dir, "session.json")
    if os.path.exists(path):
        info = _load_json(path)
        s, c = info.get("session") or {}, info.get("client") or {}
        if s:
            prim, extra = s.get("primary") or {}, s.get("extra")
            rows += [("server", f"{s.get('server_fps', '?')} frames/s, primary view {prim.get('width')}×"
                                f"{prim.get('height')}" + (f", extra view {extra['width']}×{extra['height']}"
                                                           if isinstance(extra, dict) else ", no extra view")),
                     ("stream", f"colour {s.get('video_bitrate_kbps', '?')} kbit/s, depth codec "
                                f"{s.get('depth_codec', '?')} ({s.get('depth_bits', '?')} bits)")]
        if c:
            rows += [("methods", ", ".join(c.get("methods") or [])),
                     ("trace window", f"{c.get('trace')} from {c.get('start_s')} s for {c.get('duration_s')} s"),
                     ("deadline controller", c.get("deadline")), ("stereo", c.get("stereo") or "off")]
        rows += [("complete", info.get("complete")), ("stopped", info.get("stopped") or "—")]
    rows.append(("FLIP", f"every {metrics.get('flip_every')} frame(s)"))
    return [(k, "—" if v is None else str(v)) for k, v in rows]


def _metrics_table(metrics: dict) -> str:
    head = "".join(f"<th>{_esc(h)}</th>" for _, h, _, _ in METRIC_COLUMNS)
    body = []
    for m, s in metrics["methods"].items():
        cells = []
        for key, _, scale, fmt in METRIC_COLUMNS:
            v = s.get(key)
            raw = "" if v is None else repr(v)
            cells.append(f'<td data-key="{_esc(key)}" data-value="{_esc(raw)}">{_esc(_format(v, scale, fmt))}</td>')
        body.append(f'<tr data-method="{_esc(m)}"><th>{_esc(m)}</th>{"".join(cells)}</tr>')
    stereo = metrics.get("stereo")
    extra = ""
    if isinstance(stereo, dict) and stereo.get("methods"):
        rows = "".join(
            f'<tr data-method="{_esc(m)}"><th>{_esc(m)}</th><td data-key="inconsistent_mean">'
            f'{_esc(_format(c.get("inconsistent_mean"), 100, ".2f"))}</td></tr>' for m, c in stereo["methods"].items())
        extra = (f"<p>Binocular consistency ({_esc(stereo.get('reference'))} references, {_esc(stereo.get('ipd_mm'))} mm): "
                 "the share of surface points both eyes see that the two shown images disagree on.</p>"
                 f'<table id="stereo"><tr><th>method</th><th>inconsistent %</th></tr>{rows}</table>')
    return f'<table id="metrics"><tr><th>method</th>{head}</tr>{"".join(body)}</table>{extra}'


def _series(out_dir: str, methods: list[str]) -> dict:
    """Per method, per-tick series for the plots and the scrubber's readout."""
    series = {m: {"t": [], **{k: [] for k, _ in FRAME_SERIES + RECORD_SERIES}} for m in methods}
    frames_csv = os.path.join(out_dir, "metrics_frames.csv")
    if os.path.exists(frames_csv):
        for row in _read_csv(frames_csv):
            m = row.get("method")
            if m in series:
                series[m]["t"].append(_number(row.get("t")))
                for key, _ in FRAME_SERIES:
                    series[m][key].append(_number(row.get(key)))
    for m in methods:
        path = os.path.join(out_dir, f"{m}.records.csv")
        if os.path.exists(path):
            recs = _read_csv(path)[: len(series[m]["t"]) or None]
            if not series[m]["t"]:
                series[m]["t"] = [_number(r.get("t")) for r in recs]
            for key, _ in RECORD_SERIES:
                series[m][key] = [_number(r.get(key)) for r in recs]
    return series


def _stream_series(out_dir: str, ticks_t: list) -> dict:
    """stream.csv's columns at each tick's time ``ticks_t`` (s): the newest batch decoded by then."""
    path = os.path.join(out_dir, "stream.csv")
    if not os.path.exists(path) or not ticks_t:
        return {}
    rows = [r for r in _read_csv(path) if _number(r.get("t")) is not None]
    rows.sort(key=lambda r: float(r["t"]))
    out = {key: [] for key, _ in STREAM_SERIES}
    k = -1
    for t in ticks_t:
        while t is not None and k + 1 < len(rows) and float(rows[k + 1]["t"]) <= t + 1e-9:
            k += 1
        for key, _ in STREAM_SERIES:
            out[key].append(_number(rows[k].get(key)) if k >= 0 else None)
    return out


def _run_section(out_dir: str, metrics: dict) -> tuple[str, dict]:
    methods = list(metrics["methods"])
    out = metrics["output"]
    params = "".join(f"<tr><th>{_esc(k)}</th><td>{_esc(v)}</td></tr>" for k, v in _parameters(out_dir, metrics))
    parts = ['<section id="run"><h2>Parameters</h2>', f'<table id="parameters">{params}</table>',
             "<h2>Metrics</h2>", _metrics_table(metrics),
             "<p class=note>Means over the displayed ticks; <em>geo holes</em>: pixels no transmitted view saw, "
             "<em>own holes</em>: pixels where the method accepted no transmitted sample. DSSIM = (1 − SSIM) / 2."
             "</p>"]
    if metrics.get("complete") is False:
        parts.append("<p class=warn>The client stopped early: these numbers cover the ticks it recorded.</p>")
    videos = [m for m in methods if os.path.exists(os.path.join(out_dir, f"{m}.mp4"))]
    sbs = os.path.exists(os.path.join(out_dir, "side_by_side.mp4"))
    if videos or sbs:
        parts.append('<h2>Videos</h2><div class="controls"><button id="play">play all</button>'
                     '<button id="pause">pause</button><button id="restart">from the start</button>'
                     '<span id="clock"></span></div><div class="videos">')
        for m in videos:
            parts.append(f'<figure><video class="sync" data-method="{_esc(m)}" src="{_esc(m)}.mp4" muted '
                         f'preload="auto" playsinline></video><figcaption>{_esc(m)}</figcaption></figure>')
        if sbs:
            parts.append('<figure class="wide"><video class="sync" id="sbs-video" src="side_by_side.mp4" muted '
                         'preload="auto" playsinline></video><figcaption>side by side: per method one row — '
                         'what the client showed, ground truth, error</figcaption></figure>')
        parts.append("</div>")
    if sbs:
        n = max((s.get("frames", 0) for s in metrics["methods"].values()), default=0)
        parts.append('<h2>Frame by frame</h2><div class="controls"><label>tick <input type="range" id="tick" '
                     f'min="0" max="{max(n - 1, 0)}" value="0" step="1"></label> <span id="tick-label"></span></div>'
                     '<video id="scrub-video" src="side_by_side.mp4" muted preload="auto" hidden></video>'
                     '<table id="scrubber"><tr><th></th><th>shown</th><th>ground truth</th><th>error</th>'
                     "<th>this tick</th></tr>")
        for r, m in enumerate(methods):
            canvases = "".join(f'<td><canvas data-row="{r}" data-panel="{p}"></canvas></td>' for p in range(3))
            parts.append(f'<tr><th>{_esc(m)}</th>{canvases}<td class="readout" data-method="{_esc(m)}"></td></tr>')
        parts.append("</table>")
    parts.append('<h2>Over time</h2><p class=note>Hover to read a tick, click to show it above.</p>'
                 '<div id="plots"></div>')
    png = os.path.join(out_dir, "quality.png")
    if os.path.exists(png):
        parts.append(f'<details><summary>quality.png</summary><img alt="quality over time" '
                     f'src="{_png_data_uri(png)}"></details>')
    parts.append("</section>")
    series = _series(out_dir, methods)
    data = {"rate_hz": out["rate_hz"], "methods": methods, "series": series,
            "series_titles": dict(FRAME_SERIES + RECORD_SERIES),
            "stream": _stream_series(out_dir, series[methods[0]]["t"]), "stream_titles": dict(STREAM_SERIES)}
    return "".join(parts), data


# -- benchmarks ----------------------------------------------------------------------------------------------------

def _markdown_table_html(lines: list[str]) -> str:
    """A markdown table (bench/readme_tables.py's output) as an HTML table."""
    def cells(line):
        return [c.strip().replace("**", "") for c in line.strip().strip("|").split("|")]
    head, rows = cells(lines[0]), [cells(line) for line in lines[2:]]
    out = ["<table class=bench><tr>", *(f"<th>{_esc(h)}</th>" for h in head), "</tr>"]
    for r in rows:
        out.append("<tr>" + "".join(f"<td>{_esc(c)}</td>" for c in r) + "</tr>")
    out.append("</table>")
    return "".join(out)


def _pareto_points(result: dict) -> list[dict]:
    """(scene, variant, client ms at the first speed size, DSSIM) of every variant of a pareto.json."""
    points = []
    for scene, s in (result.get("scenes") or {}).items():
        for label, v in (s.get("variants") or {}).items():
            speed = v.get("speed") or {}
            size = next(iter(speed), None)
            ms = speed[size].get("ms_median") if size else None
            dssim = (v.get("quality") or {}).get("dssim_mean")
            if ms is not None and dssim is not None:
                points.append({"scene": scene, "variant": label, "ms": ms, "dssim": dssim, "size": size})
    return points


def _bench_sections(out_dir: str) -> tuple[str, dict]:
    from . import readme_tables

    parts, data = [], {}
    for name in [*BENCH_TABLES, *BENCH_FILES]:
        path = os.path.join(out_dir, name)
        if not os.path.exists(path):
            continue
        result = _load_json(path)
        parts.append(f'<section class="bench" data-file="{_esc(name)}"><h2>{_esc(name)}</h2>')
        for renderer in BENCH_TABLES.get(name, ()):
            try:
                lines = readme_tables.RENDERERS[renderer](result)
            except (KeyError, TypeError, ValueError, IndexError, StopIteration) as exc:
                # A run with other options than the README's may lack what a table reads.
                parts.append(f"<p class=note>No {_esc(renderer)} table: this run's file lacks "
                             f"{_esc(type(exc).__name__)} {_esc(exc)}.</p>")
                continue
            parts.append(f"<h3>{_esc(renderer)}</h3>{_markdown_table_html(lines)}")
        if name == "pareto.json":
            points = _pareto_points(result)
            if points:
                data["pareto"] = points
                parts.append('<h3>client ms against DSSIM</h3><p class=note>Hover a point for its variant.</p>'
                             '<div id="pareto-plot"></div>')
        text = json.dumps(result, indent=1)
        parts.append(f"<details><summary>{_esc(name)} ({len(text) // 1024} KiB)</summary><pre>{_esc(text)}</pre>"
                     "</details></section>")
    return "".join(parts), data


def _images(out_dir: str, skip: set[str]) -> str:
    pngs = sorted(f for f in os.listdir(out_dir) if f.lower().endswith(".png") and f not in skip)
    if not pngs:
        return ""
    figs = "".join(f'<figure><img alt="{_esc(f)}" src="{_png_data_uri(os.path.join(out_dir, f))}">'
                   f"<figcaption>{_esc(f)}</figcaption></figure>" for f in pngs)
    return f'<section id="images"><h2>Plots</h2>{figs}</section>'


def build_report(out_dir: str) -> str:
    """The report page of ``out_dir`` as HTML text (ConfigError when the folder has nothing to show)."""
    if not os.path.isdir(out_dir):
        raise ConfigError(f"{out_dir}: no such folder")
    body, data, title = [], {}, os.path.basename(os.path.abspath(out_dir))
    metrics_path = os.path.join(out_dir, "metrics.json")
    skip = set()
    if os.path.exists(metrics_path):
        metrics = _load_json(metrics_path)
        if not _is_run(metrics):
            raise ConfigError(f"{metrics_path}: not the metrics of a scored run (no 'methods' and 'output'); "
                              "is it from 'pibr evaluate'?")
        section, data["run"] = _run_section(out_dir, metrics)
        body.append(section)
        skip.add("quality.png")
        title = f"{metrics.get('scene')} · {', '.join(metrics['methods'])}"
    elif os.path.exists(os.path.join(out_dir, "session.json")):
        raise ConfigError(f"{out_dir} holds a client recording that was not scored; run 'pibr evaluate {out_dir}' "
                          "first")
    bench, bench_data = _bench_sections(out_dir)
    body.append(bench)
    data.update(bench_data)
    body.append(_images(out_dir, skip))
    if not any(body):
        raise ConfigError(f"{out_dir} holds nothing to report: no metrics.json (pibr evaluate, pibr demo), "
                          "no benchmark JSON and no plots")
    return (f'<!DOCTYPE html><html lang="en"><head><meta charset="utf-8"><title>pibr · {_esc(title)}</title>'
            f"<style>{_asset('report.css')}</style></head><body><h1>pibr · {_esc(title)}</h1>"
            f'<p class=note>{_esc(os.path.abspath(out_dir))}</p>{"".join(body)}'
            f'<script type="application/json" id="pibr-data">{_script_json(data)}</script>'
            f"<script>{_asset('report.js')}</script></body></html>")


def write_report(out_dir: str) -> str:
    """Write ``out_dir/report.html``; -> its path."""
    page = build_report(out_dir)
    path = os.path.join(out_dir, REPORT_NAME)
    with open(path, "w", encoding="utf-8") as f:
        f.write(page)
    return path
