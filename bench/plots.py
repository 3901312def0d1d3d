"""Plots of benchmark results (matplotlib, Agg backend, imported lazily)."""
from __future__ import annotations

import numpy as np


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
