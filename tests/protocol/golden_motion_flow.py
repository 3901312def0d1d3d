"""MOTION_FLOW payloads pinned as golden bytes in ``golden/motion_flow_*.bin``, and the synthetic
flow fields the tests share. Regenerate only when the bitstream changes on purpose:
``python -m tests.protocol.golden_motion_flow`` (then review the diff)."""
from __future__ import annotations

import numpy as np

from pibr.protocol.motion_flow import encode_motion_flow

from .golden_files import GOLDEN_DIR, write_goldens  # noqa: F401 (GOLDEN_DIR: the tests import it from here)

WIDTH, HEIGHT = 64, 48


def moving_field(height: int = HEIGHT, width: int = WIDTH) -> tuple[np.ndarray, np.ndarray]:
    """(flow (h, w, 2) float32, moving (h, w) bool): a disc turning about its centre (flow affine
    in the pixel, from 0 to ~2.4 px), and a box translating by (6.3, -1.2) px, which the disc
    partly covers at one corner."""
    y, x = np.indices((height, width), dtype=np.float64)
    flow = np.zeros((height, width, 2))
    box = (np.abs(x - 0.7 * width) < 0.16 * width) & (np.abs(y - 0.6 * height) < 0.25 * height)
    flow[box] = (6.3, -1.2)
    cx, cy, r = 0.35 * width, 0.45 * height, 0.3 * min(width, height)
    disc = (x - cx) ** 2 + (y - cy) ** 2 < r * r
    flow[disc, 0] = -0.16 * (y[disc] - cy)
    flow[disc, 1] = 0.16 * (x[disc] - cx)
    return flow.astype(np.float32), box | disc


def golden_payload(name: str) -> bytes:
    flow, moving = moving_field()
    if name == "motion_flow_blocks":
        return encode_motion_flow(flow, moving, "blocks")[0]
    if name == "motion_flow_edges":
        return encode_motion_flow(flow, moving, "edges")[0]
    if name == "motion_flow_still":
        return encode_motion_flow(np.zeros_like(flow), np.zeros_like(moving), "edges")[0]
    raise KeyError(name)


NAMES = ("motion_flow_blocks", "motion_flow_edges", "motion_flow_still")


if __name__ == "__main__":
    write_goldens(NAMES, golden_payload)
