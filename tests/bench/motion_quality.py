"""Quality over a mask, for tests that measure moving objects (moved from bench/motion_eval.py,
whose measurement computes it inline with :func:`~pibr.bench.metrics.masked_metrics`)."""
import numpy as np

from pibr.bench.metrics import masked_metrics


def masked_quality(ref: np.ndarray, test: np.ndarray, mask: np.ndarray) -> tuple:
    """(DSSIM, PSNR dB) over the pixels of ``mask`` (H, W) bool; (None, None) for an empty mask."""
    if not mask.any():
        return None, None
    q = masked_metrics(ref, test, {"mask": mask}, min_pixels=1)
    return q["dssim_mask"], q["psnr_mask"]
