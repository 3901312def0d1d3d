"""Edge codec payloads pinned as golden bytes in ``golden/edge_*.bin``, and the synthetic depth
maps the edge codec's tests share. Regenerate only when the bitstream changes on purpose:
``python -m tests.protocol.golden_edge`` (then review the diff)."""
from __future__ import annotations

import numpy as np

from pibr.protocol.depth import DepthQuantizer
from pibr.protocol.edgecodec.codec import EdgeEncoder, warp_samples
from pibr.protocol.pose import Pose

from .golden_files import GOLDEN_DIR, write_goldens  # noqa: F401 (GOLDEN_DIR: the tests import it from here)

QUANTIZER = DepthQuantizer(0.1, 1000.0, bits=12, min_code=1)
WIDTH, HEIGHT = 64, 48


def piecewise_planar_codes(height: int, width: int, shift: int = 0, max_code: int = 4095) -> np.ndarray:
    """(h, w) int32 codes: planes in disparity (so planes in space), sky, steps and slanted edges.

    A far wall, a floor rising towards the bottom, a box in front, a tilted square and a sky
    patch in the top-left; ``shift`` moves the box and the square right by that many pixels.
    """
    s = max_code / 4095.0
    y, x = np.indices((height, width), dtype=np.float64)
    u, v = x / max(width - 1, 1), y / max(height - 1, 1)
    d = 300 + 40 * u + 25 * v                                      # far wall
    floor = v > 0.62
    d = np.where(floor, 420 + 900 * (v - 0.62) + 30 * u, d)        # floor
    box = (np.abs(x - (0.3 * width + shift)) < 0.12 * width) & (np.abs(y - 0.45 * height) < 0.2 * height)
    d = np.where(box, 1500 + 300 * u - 200 * v, d)                 # box in front (step edges)
    cx, cy = 0.72 * width + shift, 0.35 * height
    rot = np.abs(x - cx) + np.abs(y - cy) < 0.25 * min(width, height)
    d = np.where(rot, 2600 - 150 * u + 80 * v, d)                  # tilted square (diagonal edges)
    sky = (x < 0.2 * width) & (y < 0.25 * height)
    codes = np.where(sky, 0, np.round(d * s))
    return codes.astype(np.int32)


def cluttered_codes(height: int, width: int, n: int = 40, seed: int = 0, max_code: int = 4095) -> np.ndarray:
    """(h, w) int32 codes: a floor and a wall with ``n`` random planar boxes and diamonds in front."""
    rng = np.random.default_rng(seed)
    s = max_code / 4095.0
    y, x = np.indices((height, width), dtype=np.float64)
    d = np.where(y > 0.6 * height, 400 + 1500 * (y / height - 0.6), 300 + 30 * x / width)
    for _ in range(n):
        cx, cy = rng.random() * width, rng.random() * height
        r = (0.03 + 0.12 * rng.random()) * min(width, height)
        inside = (np.abs(x - cx) + np.abs(y - cy) < 1.4 * r) if rng.random() < 0.4 else \
            (np.abs(x - cx) < r) & (np.abs(y - cy) < 0.7 * r)
        base, gx, gy = 500 + 3000 * rng.random(), rng.normal(0, 3), rng.normal(0, 3)
        d = np.where(inside, np.maximum(base + gx * (x - cx) + gy * (y - cy), 1.0), d)
    d = np.where((y < 0.1 * height) & (x > 0.7 * width), 0.0, d)
    return np.clip(np.round(d * s), 0, max_code).astype(np.int32)


def piecewise_planar(height: int = HEIGHT, width: int = WIDTH, shift: int = 0,
                     quantizer: DepthQuantizer = QUANTIZER) -> np.ndarray:
    """Radial distance (h, w) float32 whose codes under ``quantizer`` are :func:`piecewise_planar_codes`."""
    codes = piecewise_planar_codes(height, width, shift, quantizer.max_code)
    return quantizer.dequantize(codes)


POSE = Pose.make((0.0, 1.6, 0.0))


def _motion(height, width):
    m = np.zeros((height, width, 2), np.float32)
    y, x = np.indices((height, width))
    box = (np.abs(x - 0.3 * width) < 0.12 * width) & (np.abs(y - 0.45 * height) < 0.2 * height)
    m[box, 0] = 1.5 + 0.02 * x[box]
    m[box, 1] = -0.25
    return m


def golden_payload(name: str) -> bytes:
    distance = piecewise_planar()
    if name == "edge_intra":
        return EdgeEncoder(WIDTH, HEIGHT, 12, QUANTIZER).encode(distance).payload
    if name == "edge_raster":
        return EdgeEncoder(WIDTH, HEIGHT, 12, QUANTIZER, passes=1).encode(distance).payload
    if name == "edge_lossy":
        return EdgeEncoder(WIDTH, HEIGHT, 12, QUANTIZER, q=4).encode(distance).payload
    if name == "edge_motion":
        return EdgeEncoder(WIDTH, HEIGHT, 12, QUANTIZER).encode(distance, motion=_motion(HEIGHT, WIDTH)).payload
    if name == "edge_temporal":
        enc = EdgeEncoder(WIDTH, HEIGHT, 12, QUANTIZER)
        first = enc.encode(distance)
        warped = warp_samples(first.samples, POSE, POSE, QUANTIZER)
        return enc.encode(piecewise_planar(shift=2), warped.edges, warped.values).payload
    raise KeyError(name)


NAMES = ("edge_intra", "edge_raster", "edge_lossy", "edge_motion", "edge_temporal")


if __name__ == "__main__":
    write_goldens(NAMES, golden_payload)
