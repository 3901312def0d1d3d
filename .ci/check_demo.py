"""CI: a demo's metrics.json holds finite figures for every method it was asked to compare.

usage: python check_demo.py OUT_DIR [METHOD,METHOD,...]   (default none,rotation,proxy)
"""
import json
import math
import os
import sys

FIGURES = ("psnr_mean", "ssim_mean", "dssim_mean", "flip_mean", "geometric_holes_mean", "hole_fraction_mean",
           "client_ms_median")


def main() -> int:
    out = sys.argv[1]
    methods = (sys.argv[2] if len(sys.argv) > 2 else "none,rotation,proxy").split(",")
    with open(os.path.join(out, "metrics.json")) as f:
        metrics = json.load(f)["methods"]
    problems = [f"method {m!r} missing" for m in methods if m not in metrics]
    for m in methods:
        s = metrics.get(m, {})
        if s and not s.get("frames", 0) > 0:
            problems.append(f"{m}: no frames")
        for k in FIGURES:
            v = s.get(k) if s else 0.0
            if not (isinstance(v, (int, float)) and math.isfinite(v)):
                problems.append(f"{m}: {k} = {v!r}")
    for m in methods:
        if m in metrics:
            print(f"  {m:>8}: " + "  ".join(f"{k} {metrics[m][k]:.4g}" for k in FIGURES), flush=True)
    if problems:
        print(f"{out}/metrics.json: " + "; ".join(problems), file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
