"""Plots of benchmark results (matplotlib, Agg backend, imported lazily)."""
from __future__ import annotations

import os

import numpy as np

from .variants import ORACLE, pareto_front, sweep_labels


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_quality_over_time(rows: list[dict], path: str) -> None:
    """DSSIM, PSNR and frame age per displayed tick, one line per method."""
    plt = _pyplot()
    methods = list(dict.fromkeys(r["method"] for r in rows))
    fig, axes = plt.subplots(3, 1, figsize=(10, 8), sharex=True)
    for m in methods:
        rs = [r for r in rows if r["method"] == m]
        t = np.array([r["t"] for r in rs])
        axes[0].plot(t, [r["dssim"] for r in rs], label=m, lw=1)
        axes[1].plot(t, [r["psnr"] for r in rs], label=m, lw=1)
        axes[2].plot(t, [r["age_ms"] for r in rs], label=m, lw=1)
    axes[0].set_ylabel("DSSIM (lower is better)")
    axes[1].set_ylabel("PSNR dB (higher is better)")
    axes[2].set_ylabel("frame age ms")
    axes[2].set_xlabel("time s")
    for a in axes:
        a.grid(alpha=0.3)
    axes[0].legend(loc="upper right")
    axes[0].set_title("Quality against ground truth over time")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_coverage(result: dict, path: str, variants: tuple, labels: dict) -> None:
    """Missing-pixel fraction over time per variant (one panel per window) and the means;
    ``variants`` the coverage bench's, ``labels`` their names (and the floor's)."""
    plt = _pyplot()
    windows = list(result["per_window"])
    cols = min(4, len(windows) + 1)
    rows = -(-(len(windows) + 1) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.5 * cols, 3.6 * rows), squeeze=False)
    flat = axes.ravel()
    for ax, label in zip(flat, windows):
        d = result["per_window"][label]
        for v in variants + ("floor",):
            ax.plot(d["times"], 100 * np.array(d["missing"][v]), label=labels[v], lw=1,
                    ls=":" if v == "floor" else "-")
        ax.set_title(label, fontsize=9)
        ax.set_xlabel("time s")
        ax.set_ylabel("pixels no view covers %")
        ax.grid(alpha=0.3)
    flat[0].legend(fontsize=7)
    ax = flat[len(windows)]
    x = np.arange(len(variants))
    ax.bar(x, [100 * result["means"][v] for v in variants], 0.4, label="all pixels")
    ax.bar(x + 0.4, [100 * result["means"][v + ":geometry"] for v in variants], 0.4, label="geometry only")
    ax.set_xticks(x + 0.2)
    ax.set_xticklabels([labels[v].replace(": ", ":\n") for v in variants], fontsize=7)
    ax.set_ylabel("mean missing %")
    ax.set_title(f"{result['scene']}, {result['latency_ms']:g} ms, all windows", fontsize=9)
    ax.legend(fontsize=8)
    for extra in flat[len(windows) + 1:]:
        extra.axis("off")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def plot_offset_search(result: dict, path: str) -> None:
    """The offset search's surface: mean missing % over forward x up, one panel per tilt."""
    plt = _pyplot()
    grid = result["grid"]
    fw, up, tilt = (np.array(grid[k]) for k in ("forward", "up", "tilt"))
    values = np.array(result["surface"])  # (forward, up, tilt), NaN where not evaluated
    fig, axes = plt.subplots(1, len(tilt), figsize=(2.6 * len(tilt) + 1.5, 3.6), squeeze=False,
                             layout="constrained")
    finite = values[np.isfinite(values)]
    vmin, vmax = (100 * finite.min(), 100 * finite.max()) if finite.size else (0, 1)
    for k, ax in enumerate(axes[0]):
        im = ax.imshow(100 * values[:, :, k].T, origin="lower", aspect="auto", vmin=vmin, vmax=vmax,
                       extent=[fw[0], fw[-1], up[0], up[-1]] if len(fw) > 1 and len(up) > 1 else None,
                       cmap="viridis_r")
        ax.set_title(f"tilt {tilt[k]:g} deg", fontsize=9)
        ax.set_xlabel("forward m")
        if k == 0:
            ax.set_ylabel("up m")
    best = result["best"]
    fig.suptitle(f"mean missing % ({result['scene']}); best: forward {best['forward']:g} m, up {best['up']:g} m, "
                 f"tilt {best['tilt']:g} deg -> {100 * best['missing']:.2f} %", fontsize=10)
    fig.colorbar(im, ax=axes[0].tolist(), shrink=0.8, label="missing %")
    fig.savefig(path, dpi=100)
    plt.close(fig)


def plot_pareto(result: dict, path: str) -> None:
    """Reinert et al.'s Figure 9 per scene and output size: client ms per frame (log) against
    DSSIM, one marker per method and knob, the Pareto front drawn, the zero-latency oracle as a
    horizontal line."""

    plt = _pyplot()
    scenes = list(result["scenes"])
    sizes = list(next(iter(result["scenes"][scenes[0]]["variants"].values()))["speed"])
    fig, axes = plt.subplots(len(scenes), max(1, len(sizes)), figsize=(7 * max(1, len(sizes)), 5.5 * len(scenes)),
                             squeeze=False)
    methods = sorted({v["method"] for s in result["scenes"].values() for v in s["variants"].values()})
    markers = dict(zip(methods, "os^vD<>phH*Xd8P"))
    colours = dict(zip(methods, plt.get_cmap("tab20").colors))
    for row, scene in enumerate(scenes):
        variants = result["scenes"][scene]["variants"]
        for col, size in enumerate(sizes):
            ax = axes[row][col]
            points = {}
            for label, v in variants.items():
                if label == ORACLE or size not in v["speed"]:
                    continue
                ms, dssim = v["speed"][size]["ms_median"], v["quality"]["dssim_mean"]
                points[label] = (ms, dssim)
                ax.scatter(ms, dssim, marker=markers[v["method"]], color=colours[v["method"]], s=46,
                           label=v["method"], zorder=3)
                ax.annotate(label, (ms, dssim), fontsize=7, xytext=(4, 3), textcoords="offset points")
            front = pareto_front(points)
            ax.plot([points[k][0] for k in front], [points[k][1] for k in front], "k--", lw=1, alpha=0.6,
                    label="Pareto front", zorder=2)
            if ORACLE in variants:
                ax.axhline(variants[ORACLE]["quality"]["dssim_mean"], color="grey", lw=1, ls=":",
                           label="zero-latency oracle (coding loss)")
            ax.set_xscale("log")
            ax.set_xlabel(f"client ms per frame at {size} (median, log scale)")
            ax.set_ylabel("DSSIM to ground truth (lower is better)")
            ax.set_title(f"{scene}: {result['latency_ms']:g} ms latency, 10 fps stream")
            ax.grid(alpha=0.3, which="both")
            handles, labels = ax.get_legend_handles_labels()
            unique = dict(zip(labels, handles))
            ax.legend(unique.values(), unique.keys(), fontsize=7, loc="upper right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_dynamic(result: dict, path: str) -> None:
    """``pibr bench dynamic``: per event (a reversal, a stop) the DSSIM of the object's pixels over
    time for every ``proxy`` variant (at a fixed head pose ``rotation`` shows what ``static`` does);
    per scene the DSSIM of moving pixels against latency for every variant."""
    plt = _pyplot()
    events = [(scene, e) for scene, s in result["scenes"].items() for e in s["events"]]
    scenes = list(result["scenes"])
    cols = max(len(events), len(scenes), 1)
    fig, axes = plt.subplots(2, cols, figsize=(4.8 * cols, 7.5), squeeze=False)
    for ax, (scene, e) in zip(axes[0], events):
        kinds = next(iter(result["scenes"][scene]["latency"].values()), {}).get("methods", {})
        for label, m in e["methods"].items():
            if kinds.get(label, {}).get("method", "proxy") != "proxy":
                continue
            ax.plot(e["times"], m["dssim_object"], label=label, lw=1.2, ls="--" if label == "oracle" else "-")
        ax.axvline(0.0, color="k", lw=0.8, ls=":")
        ax.set_title(f"{scene}: {e['object']} {e['kind']} at {e['t']:.2f} s ({e['latency_ms']:g} ms)", fontsize=9)
        ax.set_xlabel("display time - event time, s")
        ax.set_ylabel("DSSIM of the object's pixels")
        ax.grid(alpha=0.3)
    for ax in axes[0][len(events):]:
        ax.axis("off")
    for ax, scene in zip(axes[1], scenes):
        lat = result["scenes"][scene]["latency"]
        xs = [float(k) for k in lat]
        labels = list(next(iter(lat.values()))["methods"]) if lat else []
        for label in labels:
            ax.plot(xs, [lat[k]["methods"][label]["dssim_moving"] for k in lat], marker="o", label=label, lw=1.2,
                    ls="--" if label == "oracle" else "-")
        ax.set_title(f"{scene}: moving objects' pixels", fontsize=9)
        ax.set_xlabel("round trip ms")
        ax.set_ylabel("DSSIM (lower is better)")
        ax.grid(alpha=0.3)
    for ax in axes[1][len(scenes):]:
        ax.axis("off")
    axes[0][0].legend(fontsize=7)
    axes[1][0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def plot_depth_rd(result: dict, path: str) -> None:
    """``pibr bench codec``: bits per frame against disparity PSNR and against the share of pixels
    more than 1 % off in distance, one curve per depth codec; and proxy DSSIM against the total
    bitrate (colour + depth), one line per codec (infeasible totals left out)."""
    plt = _pyplot()
    e2e = result.get("end_to_end")
    fig, axes = plt.subplots(1, 3 if e2e else 2, figsize=(17 if e2e else 12, 4.6))
    styles = {"edge": "o-", "edge-8bit": "o:", "edge-10bit": "o-.", "edge-rc": "o--", "h264-8bit": "s-", "h264-10bit": "D-", "log-zstd": "^-",
              "zstd-lossless": "*", "h264-8bit-atlas": "x-"}
    for name, pts in result["curves"].items():
        x = np.array([p["bits_per_frame"] for p in pts]) / 1000
        axes[0].plot(x, [p["psnr_db"] for p in pts], styles.get(name, "o-"), label=name, ms=5)
        axes[1].plot(x, [100 * p["outliers_1pct"] for p in pts], styles.get(name, "o-"), label=name, ms=5)
    for ax in axes[:2]:
        ax.set_xscale("log")
        ax.set_xlabel("depth kbit per frame (primary view, log)")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
    axes[0].set_ylabel("disparity PSNR dB (higher is better)")
    axes[0].set_title("rate-distortion: disparity PSNR")
    axes[1].set_ylabel("% of pixels > 1 % off in distance (lower is better)")
    axes[1].set_title("rate-distortion: 1 % outliers")
    if e2e:
        ax = axes[2]
        codecs = list(dict.fromkeys(v["codec"] for v in e2e["results"].values()))
        for c in codecs:
            rows = sorted((v for v in e2e["results"].values() if v["codec"] == c and v["feasible"]),
                          key=lambda v: v["total_kbps"])
            if rows:
                label = f"{c} ({e2e['edge_share']:.0%} of the total)" if c == "edge-rc" else c
                ax.plot([v["total_kbps"] / 1000 for v in rows], [v["dssim_mean"] for v in rows],
                        styles.get(c, "o-"), label=label, ms=5)
        ax.set_xscale("log")
        totals = sorted({v["total_kbps"] for v in e2e["results"].values()})
        ax.set_xticks([t / 1000 for t in totals], [f"{t / 1000:g}" for t in totals])
        ax.minorticks_off()
        never = sorted({v["codec"] for v in e2e["results"].values()} -
                       {v["codec"] for v in e2e["results"].values() if v["feasible"]})
        if never:
            rates = {c: max(v["depth_kbps"] for v in e2e["results"].values() if v["codec"] == c) for c in never}
            ax.text(0.02, 0.02, "infeasible at every total (depth alone):\n" + "\n".join(
                f"{c}{' (%d-bit)' % e2e['log_bits'] if c == 'log-zstd' else ''} {rates[c] / 1000:.1f} Mbit/s"
                for c in never), transform=ax.transAxes, fontsize=8,
                va="bottom")
        ax.set_xlabel("total Mbit/s (colour + depth + motion)")
        ax.set_ylabel("proxy DSSIM (lower is better)")
        ax.set_title(f"end to end at equal total bitrate, {e2e['latency_ms']:g} ms")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
    fig.suptitle(f"depth codecs, scene {result['scene']}, {result['view_size'][0]}x{result['view_size'][1]}, "
                 f"{result['frames']} frames", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_trade(result: dict, knob: str, path: str, client: bool, unit: str) -> None:
    """One knob of ``pibr bench trade``: DSSIM against the knob's value, against the total
    Mbit/s sent, and against ms (the server's CPU ms per frame for stream knobs, the client's
    display pass for client knobs: ``client``), one curve per method, per scene; ``unit``: the
    knob's, for its axis."""

    plt = _pyplot()
    scenes = list(result["scenes"])
    fig, axes = plt.subplots(len(scenes), 3, figsize=(16, 4.6 * len(scenes)), squeeze=False)
    for row, scene in enumerate(scenes):
        rows = result["scenes"][scene]["sweeps"][knob]
        values = [r["value"] for r in rows]
        if knob == "cap":   # 0 is no cap: not the left end of the axis
            values = ["none" if v == 0 else v for v in values]
        categorical = any(isinstance(v, str) for v in values)
        xs = list(range(len(values))) if categorical else values
        for label in sweep_labels(rows):
            dssim = [r["methods"][label]["dssim"] for r in rows]
            mbps = [r["stream"]["kbps"] / 1e3 for r in rows]
            ms = [r["methods"][label]["client_cpu_ms"] if client else r["stream"]["server_cpu_ms"] for r in rows]
            for ax, x in zip(axes[row], (xs, mbps, ms)):
                ax.plot(x, dssim, "o-", label=label, ms=4)
            if label == "proxy":   # which point is which value, on the panels not ordered by it
                for ax, x in zip(axes[row][1:], (mbps, ms)):
                    for xi, yi, v in zip(x, dssim, values):
                        ax.annotate(f"{v:g}" if isinstance(v, float) else str(v), (xi, yi), fontsize=7,
                                    xytext=(3, 3), textcoords="offset points")
        for r, x, in zip(rows, xs):
            if r["default"]:
                axes[row][0].axvline(x, color="grey", ls=":", lw=1)
        axes[row][0].set_xlabel(f"{knob} ({unit})" if unit else knob)
        if categorical:
            axes[row][0].set_xticks(xs, [str(v) for v in values])
        elif all(isinstance(v, (int, float)) and v > 0 for v in values) and max(values) / min(values) >= 8:
            axes[row][0].set_xscale("log")
        axes[row][1].set_xlabel("total Mbit/s sent (colour + depth + motion)")
        axes[row][2].set_xlabel("client CPU ms per display pass (median)" if client
                                else "server CPU ms per frame (render + encode, median)")
        for ax in axes[row]:
            ax.set_ylabel("DSSIM to ground truth (lower is better)")
            ax.grid(alpha=0.3)
        axes[row][0].set_title(f"{scene}: {knob} (dotted: the default)")
        axes[row][0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def plot_stereo(result: dict, path: str) -> None:
    """``pibr bench stereo``: per scene, each method's per-eye DSSIM and binocular inconsistency by
    server reference (mono: one view at the head's centre, its consistency that of one image shown
    to both eyes)."""
    plt = _pyplot()
    scenes = list(result["scenes"])
    fig, axes = plt.subplots(2, max(1, len(scenes)), figsize=(5.5 * max(1, len(scenes)), 7), squeeze=False)
    modes, methods = result["modes"], result["methods"]
    width = 0.8 / max(1, len(modes))
    for col, scene in enumerate(scenes):
        variants = result["scenes"][scene]["variants"]
        for row, (key, title) in enumerate((("dssim_mean", "per-eye DSSIM (lower is better)"),
                                            ("inconsistent_mean", "binocular pairs inconsistent"))):
            ax = axes[row][col]
            for j, mode in enumerate(modes):
                values = [variants[f"{m} {mode}"][key] or 0.0 for m in methods]
                ax.bar(np.arange(len(methods)) + (j - (len(modes) - 1) / 2) * width, values, width, label=mode)
            ax.set_xticks(np.arange(len(methods)))
            ax.set_xticklabels(methods)
            ax.set_title(f"{scene}: {title}", fontsize=9)
            ax.grid(alpha=0.3, axis="y")
    axes[0][0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def plot_predict(result: dict, path: str) -> None:
    """``pibr bench predict``: mean angular and position error against look-ahead, per predictor."""
    plt = _pyplot()
    look = result["look_aheads_ms"]
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for name, p in result["predictors"].items():
        axes[0].plot(look, [p["overall"][f"{a:g}"]["angle_deg_mean"] for a in look], marker="o", label=name)
        axes[1].plot(look, [p["overall"][f"{a:g}"]["position_mm_mean"] for a in look], marker="o", label=name)
    for ax, unit in zip(axes, ("mean angular error, degrees", "mean position error, mm")):
        ax.set_xlabel("look-ahead, ms")
        ax.set_ylabel(unit)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    axes[0].set_title(f"{result['windows']['purpose']} windows", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def plot_network(result: dict, path: str) -> None:
    """``pibr bench network``: per link (a column each), above: the link's rate (averaged over
    each series step) and the colour bitrate the adapting stream chose; below: the oldest frame
    shown in each step, adapting against every static bitrate."""
    from pibr.common.bandwidth import load_bandwidth_trace

    plt = _pyplot()
    links = list(result["links"])
    fig, axes = plt.subplots(2, len(links), figsize=(4.2 * len(links), 6.4), squeeze=False, sharex=True)
    rtt = result["settings"]["latency_ms"]
    for col, link in enumerate(links):
        runs = result["links"][link]["runs"]
        adapt_name = next((k for k in runs if k.startswith("adapt")), None)
        step = next(iter(runs.values()))["series"]["step_s"]
        n = len(next(iter(runs.values()))["series"]["age_ms_max"])
        t = np.arange(n) * step
        trace = load_bandwidth_trace(link)
        edges_us = (np.arange(n + 1) * step * 1e6).astype(np.int64)
        bits = trace.bits_until(edges_us)
        link_kbps = np.diff(bits) / np.diff(edges_us) * 1e3
        top, bottom = axes[0, col], axes[1, col]
        top.step(t, link_kbps / 1e3, where="post", color="k", lw=1, label="link")
        if adapt_name:
            chosen = np.array([np.nan if v is None else v for v in runs[adapt_name]["series"]["stream_kbps"]])
            top.step(t, chosen / 1e3, where="post", color="C3", lw=1.2, label="adapting: colour target")
        top.set_title(os.path.basename(link), fontsize=10)
        top.set_ylabel("Mbit/s")
        top.grid(alpha=0.3)
        for k, (name, r) in enumerate(runs.items()):
            ages = np.array([np.nan if v is None else v for v in r["series"]["age_ms_max"]])
            adapting = name == adapt_name
            colour = "C3" if adapting else f"C{(0, 1, 2, 4, 5, 6, 7, 8, 9)[k % 9]}"   # red: the adapting one
            bottom.plot(t, ages, lw=1.6 if adapting else 0.9, color=colour,
                        alpha=1.0 if adapting else 0.6, label=name)
        bottom.axhline(rtt + result["goals"]["age_p95_over_rtt_ms_max"], color="k", ls=":", lw=1,
                       label="goal: p95 age")
        bottom.set_yscale("log")
        bottom.set_ylabel("frame age shown, ms")
        bottom.set_xlabel("time s")
        bottom.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=7)
    axes[1, 0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
