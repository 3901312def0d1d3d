"""Motion flow as edge samples, Pajak et al. 2011's way (Sections 3.1, 3.2 and 3.5).

The flow of moving objects (pixels per server frame, x right, y down; 0 on everything the
camera alone moves) is quantized non-linearly per component, ``c = sign(v) round(s sqrt|v|)``
(:func:`.motion.quantize_motion`: slow motion gets fine steps), and sent as the depth is:

* the **edge image**: pixels where the Laplacian of the quantized flow is significant
  (``|L(c_x)| + |L(c_y)| > threshold``) together with the neighbour across the largest jump,
  so both sides of a flow discontinuity keep their own value; and both pixels of every
  boundary between a moving and a static pixel, whatever the jump (a slow object's outline
  would otherwise fall below the threshold and its flow would leak into the background);
* one **regular sample** per 2^k x 2^k cell (32 x 32 by default, Paeth-coded), so diffusion
  has an anchor away from edges;
* the edge samples' **values**, per component, with the depth codec's predictor and
  adaptive residual coder (:mod:`.values`: the Laplacian sign of each sample steers the
  prediction to samples of the same side), lossless by default (``q`` = 1) or with a residual
  step ``q``.

The client diffuses each component from its samples with the edge-aware push-pull of the
depth (``pibr.client.motion_flow``): inside a closed outline the flow is interpolated
harmonically from the object's own samples (affine flow, as a rigid object's is to first
order, comes back exactly up to quantization), and outside it every sample is 0, so the
background stays exactly still. The decoder returns the samples; the moving mask is where
the diffused flow is not 0.

Values are coded as ``c + OFFSET`` (OFFSET = :data:`.motion.MAX_CODE`), so that every code is
non-negative, as the value coder expects.

Section layout (little-endian): u8 scale s (1..255), u8 log2 of the regular spacing
(MIN_SPACING_LOG2..MAX_SPACING_LOG2), u8 residual step q (1..255), u32 number of edge samples,
u32 byte lengths of the edge image, the regular samples and the x values; then those three
streams and the y values (the rest). Every length is checked before use; a section that does
not decode raises :class:`~pibr.protocol.errors.CodecError`.
"""
from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np
from numba import njit

from ..errors import CodecError
from .bitstream import MAX_SPACING_LOG2, MIN_SPACING_LOG2, grid_shape
from .codec import laplacian
from .edges import decode_edge_image, encode_edge_image
from .motion import MAX_CODE, dequantize_motion, quantize_motion
from .regular import decode_regular, encode_regular, nearest_index, sample_positions
from .values import decode_values, encode_values

_HEAD = struct.Struct("<BBBIIII")
#: Codes are sent as c + OFFSET (non-negative); the largest is 2 OFFSET.
OFFSET = MAX_CODE
MAX_VALUE_CODE = 2 * OFFSET
#: Significance threshold in code units: at s = 8 a rigid object's flow bends the square-root
#: codes by a few units per pixel only near its zero crossings.
DEFAULT_THRESHOLD = 3.0
DEFAULT_SPACING_LOG2 = 5


@dataclass
class FlowSamples:
    """What a flow section carries, as the decoder sees it.

    edges : (h, w) bool edge samples; valid : (h, w) bool edge and regular samples;
    flow : (h, w, 2) float32 pixels at ``valid`` (0 elsewhere), dequantized;
    signs : (h, w, 2) int8 Laplacian sign per component at edges (+1 / -1, 0 elsewhere).
    """

    edges: np.ndarray
    valid: np.ndarray
    flow: np.ndarray
    signs: np.ndarray
    scale: int

    @property
    def shape(self) -> tuple[int, int]:
        return self.edges.shape


@njit(cache=True, nogil=True)
def _select_kernel(cx, cy, moving, threshold, edges):
    """Edge samples of the quantized flow (see the module docstring)."""
    h, w = cx.shape
    for y in range(h):
        for x in range(w):
            vx, vy = int(cx[y, x]), int(cy[y, x])
            lap = 0
            for c, v in ((cx, vx), (cy, vy)):
                up = int(c[y - 1, x]) if y > 0 else v
                down = int(c[y + 1, x]) if y + 1 < h else v
                left = int(c[y, x - 1]) if x > 0 else v
                right = int(c[y, x + 1]) if x + 1 < w else v
                lap += abs(up + down + left + right - 4 * v)
            if lap > threshold:
                edges[y, x] = True
                best, by, bx = -1, 0, 0
                for dy, dx in ((-1, 0), (1, 0), (0, -1), (0, 1)):
                    yy, xx = y + dy, x + dx
                    if 0 <= yy < h and 0 <= xx < w:
                        jump = abs(vx - int(cx[yy, xx])) + abs(vy - int(cy[yy, xx]))
                        if jump > best:
                            best, by, bx = jump, yy, xx
                if best > threshold:
                    edges[by, bx] = True
            # both pixels of every moving / static boundary
            if y + 1 < h and moving[y, x] != moving[y + 1, x]:
                edges[y, x] = True
                edges[y + 1, x] = True
            if x + 1 < w and moving[y, x] != moving[y, x + 1]:
                edges[y, x] = True
                edges[y, x + 1] = True


def flow_codes(flow, moving, scale: int) -> tuple[np.ndarray, np.ndarray]:
    """(c_x, c_y) (h, w) int32 quantized flow components, 0 where not ``moving``."""
    q = quantize_motion(np.where(np.asarray(moving, bool)[..., None], flow, 0.0), scale)
    return np.ascontiguousarray(q[..., 0]), np.ascontiguousarray(q[..., 1])


def select_flow_edges(cx, cy, moving, threshold: float = DEFAULT_THRESHOLD) -> np.ndarray:
    """Edge samples (h, w) bool of quantized flow components cx, cy (h, w) and the moving mask (h, w)."""
    edges = np.zeros(cx.shape, dtype=bool)
    _select_kernel(np.ascontiguousarray(cx, np.int32), np.ascontiguousarray(cy, np.int32),
                   np.ascontiguousarray(moving, bool), np.float64(threshold), edges)
    return edges


def _signs(edges, codes) -> np.ndarray:
    lap = laplacian(codes)
    return np.where(edges, np.where(lap > 0, 1, -1), 0).astype(np.int8)


def encode_flow_edges(flow, moving, scale: int = 8, threshold: float = DEFAULT_THRESHOLD,
                      spacing_log2: int = DEFAULT_SPACING_LOG2, q: int = 1) -> tuple[bytes, FlowSamples]:
    """Flow section of one frame.

    flow : (h, w, 2) float pixels per frame; moving : (h, w) bool (the flow is taken as 0 elsewhere).
    Returns (section bytes, the decoder's :class:`FlowSamples`).
    """
    moving = np.asarray(moving, dtype=bool)
    h, w = moving.shape
    if np.shape(flow) != (h, w, 2):
        raise ValueError(f"flow must have shape ({h}, {w}, 2), got {np.shape(flow)}")
    if not (1 <= scale <= 255 and 1 <= q <= 255 and MIN_SPACING_LOG2 <= spacing_log2 <= MAX_SPACING_LOG2):
        raise ValueError(f"flow scale and q must be 1..255 and spacing_log2 {MIN_SPACING_LOG2}..{MAX_SPACING_LOG2}")
    cx, cy = flow_codes(flow, moving, scale)
    edges = select_flow_edges(cx, cy, moving, threshold)
    rows, cols = sample_positions(w, h, spacing_log2)
    nr, nc = nearest_index(rows, h), nearest_index(cols, w)
    edge_bytes = encode_edge_image(edges, None, True)
    codes = (cx + OFFSET, cy + OFFSET)
    # both components' regular samples in one stream, the x grid above the y grid
    reg_bytes, both = encode_regular(np.concatenate([c[np.ix_(rows, cols)] for c in codes]), q, MAX_VALUE_CODE)
    regular = (both[:len(rows)], both[len(rows):])
    value_bytes, values, signs = [], [], []
    for c, reg in zip(codes, regular):
        s = _signs(edges, c)
        data, dec = encode_values(edges, c, s, reg, nr, nc, q, MAX_VALUE_CODE)
        value_bytes.append(data)
        values.append(dec)
        signs.append(s)
    head = _HEAD.pack(scale, spacing_log2, q, int(edges.sum()), len(edge_bytes), len(reg_bytes), len(value_bytes[0]))
    section = head + edge_bytes + reg_bytes + value_bytes[0] + value_bytes[1]
    return section, _assemble(edges, rows, cols, regular, values, signs, scale)


def _assemble(edges, rows, cols, regular, values, signs, scale) -> FlowSamples:
    h, w = edges.shape
    valid = edges.copy()
    valid[np.ix_(rows, cols)] = True
    codes = np.zeros((h, w, 2), dtype=np.int64)
    for k in range(2):
        c = np.where(edges, values[k], 0).astype(np.int64)
        grid = np.zeros((h, w), dtype=np.int64)
        grid[np.ix_(rows, cols)] = regular[k]
        reg = np.zeros((h, w), dtype=bool)
        reg[np.ix_(rows, cols)] = True
        codes[..., k] = np.where(edges, c, np.where(reg, grid, OFFSET)) - OFFSET
    flow = np.where(valid[..., None], dequantize_motion(codes, scale), 0.0).astype(np.float32)
    return FlowSamples(edges=edges, valid=valid, flow=flow, signs=np.stack(signs, axis=-1), scale=scale)


def decode_flow_edges(section, height: int, width: int) -> FlowSamples:
    """Section bytes -> :class:`FlowSamples` of a ``width`` x ``height`` view. Raises CodecError."""
    view = memoryview(section).cast("B")
    if len(view) < _HEAD.size:
        raise CodecError(f"motion flow: edge section of {len(view)} bytes is shorter than its {_HEAD.size}-byte head")
    scale, spacing_log2, q, n_edges, n_image, n_regular, n_x = _HEAD.unpack_from(view, 0)
    if scale < 1 or q < 1:
        raise CodecError(f"motion flow: scale {scale} and step q {q} must be at least 1")
    if not (MIN_SPACING_LOG2 <= spacing_log2 <= MAX_SPACING_LOG2):
        raise CodecError(f"motion flow: regular spacing 2^{spacing_log2} outside "
                         f"2^{MIN_SPACING_LOG2}..2^{MAX_SPACING_LOG2}")
    if n_edges > height * width:
        raise CodecError(f"motion flow: {n_edges} edge samples in a {width}x{height} view")
    rest = len(view) - _HEAD.size
    if n_image > rest or n_regular > rest - n_image or n_x > rest - n_image - n_regular:
        raise CodecError(f"motion flow: stream lengths {n_image} + {n_regular} + {n_x} exceed the "
                         f"{rest} bytes of the section")
    pos = _HEAD.size
    image = view[pos:pos + n_image]
    pos += n_image
    regular_data = view[pos:pos + n_regular]
    pos += n_regular
    value_data = (view[pos:pos + n_x], view[pos + n_x:])
    edges, ok = decode_edge_image(image, height, width, None, True)
    if not ok:
        raise CodecError("motion flow: edge image stream is corrupt")
    if int(edges.sum()) != n_edges:
        raise CodecError(f"motion flow: edge image has {int(edges.sum())} edges, the head announces {n_edges}")
    shape = grid_shape(width, height, spacing_log2)
    rows, cols = sample_positions(width, height, spacing_log2)
    nr, nc = nearest_index(rows, height), nearest_index(cols, width)
    # both components' regular samples share one stream, one after the other
    both, ok = decode_regular(regular_data, (2 * shape[0], shape[1]), q, MAX_VALUE_CODE)
    if not ok:
        raise CodecError("motion flow: regular sample stream is corrupt")
    regular = [both[:shape[0]], both[shape[0]:]]
    values, signs = [], []
    for k in range(2):
        v, s, ok = decode_values(value_data[k], edges, regular[k], nr, nc, q, MAX_VALUE_CODE)
        if not ok:
            raise CodecError(f"motion flow: {'xy'[k]} value stream is corrupt")
        values.append(v)
        signs.append(s)
    return _assemble(edges, rows, cols, regular, values, signs, scale)
