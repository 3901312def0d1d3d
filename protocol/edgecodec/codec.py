"""The edge codec's API: :class:`EdgeEncoder`, :class:`EdgeDecoder` and the temporal warp both use.

A frame of radial distance (h, w) becomes a payload (see :mod:`.bitstream`) of

* the binary **edge image**: pixels where the Laplacian of the quantized disparity codes is
  significant, two pixels wide so each side of a discontinuity keeps its own value
  (:func:`select_edges`; the server's ``edge_extract`` computes a richer significance);
* one **regular sample** per 32 x 32 cell (:mod:`.regular`);
* the edge samples' **Laplacian signs and values** (:mod:`.values`);
* optionally the **motion** of moving objects (:mod:`.motion`).

The client diffuses the samples into a dense map (``pibr.client.diffusion``).

**Temporal context.** Both ends warp the previous frame's *decoded* samples to the current
view with :func:`warp_samples` (deterministic: same inputs, same bytes) and hand the
result to ``encode`` / ``decode``. The header records whether the encoder used it; a decoder
without it then refuses the payload instead of decoding garbage.

Everything the decoder reads from the payload is checked; a payload that does not decode
raises :class:`~pibr.protocol.errors.CodecError` and nothing else.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from ..depth import DepthQuantizer
from ..errors import CodecError
from ..pose import Pose
from ..projection import EPS as _EPS
from . import bitstream
from .bitstream import FrameHeader, grid_shape
from .edges import decode_edge_image, encode_edge_image, temporal_context
from .motion import decode_motion, encode_motion
from .arith import unmanaged
from .quantize import code_of, quantize_codes
from .regular import decode_regular, encode_regular, nearest_index, sample_positions
from .values import PAD as VALUES_PAD
from .values import ValueWorkspace, decode_values, encode_values

#: Default significance threshold in code units: above the Laplacian of a quantized plane (|L| <= 3).
DEFAULT_THRESHOLD = 3.5
DEFAULT_SPACING_LOG2 = 5


def default_quantizer(bits: int = 12) -> DepthQuantizer:
    """The edge codec's quantizer when none is given: near 0.1 m, far 1000 m, sky = 0, surfaces from 1."""
    return DepthQuantizer(0.1, 1000.0, bits=bits, min_code=1)


# ------------------------------------------------------------------------------------------
# Edge selection (the server's edge_extract builds on these)
# ------------------------------------------------------------------------------------------

@njit(cache=True, nogil=True)
def _beyond(c0, c1, c2, linear_ok):
    """Value one step beyond border value c0 (c1, c2 further inside): linear extrapolation where
    c2, c1, c0 lie on a line (up to quantization), else c0 repeated, so a step right at the border
    still shows."""
    if linear_ok and abs(c0 - 2 * c1 + c2) <= 2:
        return 2 * c0 - c1
    return c0


@njit(cache=True, nogil=True, inline='always')
def _laplacian_at(c, y, x):
    """:func:`laplacian` of codes c (h, w) at pixel (y, x) (pass c through ``unmanaged``)."""
    h, w = c.shape
    v = int(c[y, x])
    up = int(c[y - 1, x]) if y > 0 else _beyond(v, int(c[min(1, h - 1), x]), int(c[min(2, h - 1), x]), h >= 3)
    down = int(c[y + 1, x]) if y + 1 < h else \
        _beyond(v, int(c[max(h - 2, 0), x]), int(c[max(h - 3, 0), x]), h >= 3)
    left = int(c[y, x - 1]) if x > 0 else _beyond(v, int(c[y, min(1, w - 1)]), int(c[y, min(2, w - 1)]), w >= 3)
    right = int(c[y, x + 1]) if x + 1 < w else \
        _beyond(v, int(c[y, max(w - 2, 0)]), int(c[y, max(w - 3, 0)]), w >= 3)
    return up + down + left + right - 4 * v


@njit(cache=True, nogil=True)
def _laplacian_kernel(c, out):
    c, out = unmanaged(c), unmanaged(out)
    h, w = c.shape
    for y in range(h):
        for x in range(w):
            out[y, x] = _laplacian_at(c, y, x)


def laplacian(codes) -> np.ndarray:
    """4-neighbour Laplacian (sum of neighbours - 4 * centre) of codes (h, w): (h, w) int32.

    Outside the image the codes continue linearly where the last three rows (columns) are
    linear, else the border value repeats: a plane running into the border has no Laplacian
    there, a step at the border keeps its own. Positive on the far side of a step in
    disparity, negative on the near side. (Compiled; its numpy definition, which the tests hold it
    to, is ``laplacian_numpy`` in tests/protocol/edgecodec_reference.py.)
    """
    c = np.ascontiguousarray(codes, dtype=np.int32)
    if c.ndim != 2:
        raise ValueError(f"codes must have shape (h, w), got {c.shape}")
    out = np.empty(c.shape, dtype=np.int32)
    _laplacian_kernel(c, out)
    return out


@njit(cache=True, nogil=True)
def _signs_kernel(edges, lap, signs):
    h, w = edges.shape
    for y in range(h):
        for x in range(w):
            signs[y, x] = 0 if not edges[y, x] else (1 if lap[y, x] > 0 else -1)


@njit(cache=True, nogil=True, inline='always')
def _select_at(c, significance, threshold, edges, y, x):
    """The edge selection of :func:`select_edges` at pixel (y, x) of codes c (h, w), whose
    significance is ``significance``: sets edges (h, w) there and at neighbours (pass the
    arrays through ``unmanaged``)."""
    h, w = c.shape
    v = int(c[y, x])
    if significance > threshold:
        edges[y, x] = True
        # the neighbour across the largest jump (first of up, down, left, right on ties)
        best, by, bx = -1, 0, 0
        if y > 0 and abs(v - int(c[y - 1, x])) > best:
            best, by, bx = abs(v - int(c[y - 1, x])), y - 1, x
        if y + 1 < h and abs(v - int(c[y + 1, x])) > best:
            best, by, bx = abs(v - int(c[y + 1, x])), y + 1, x
        if x > 0 and abs(v - int(c[y, x - 1])) > best:
            best, by, bx = abs(v - int(c[y, x - 1])), y, x - 1
        if x + 1 < w and abs(v - int(c[y, x + 1])) > best:
            best, by, bx = abs(v - int(c[y, x + 1])), y, x + 1
        if best > threshold:
            edges[by, bx] = True
    # both pixels of every sky / surface boundary
    if y + 1 < h and (v == 0) != (int(c[y + 1, x]) == 0):
        edges[y, x] = True
        edges[y + 1, x] = True
    if x + 1 < w and (v == 0) != (int(c[y, x + 1]) == 0):
        edges[y, x] = True
        edges[y, x + 1] = True


@njit(cache=True, nogil=True)
def _select_kernel(c, sig, threshold, edges):
    c, sig, edges = unmanaged(c), unmanaged(sig), unmanaged(edges)
    h, w = c.shape
    for y in range(h):
        for x in range(w):
            _select_at(c, sig[y, x], threshold, edges, y, x)


@njit(cache=True, nogil=True)
def _depth_edges_kernel(c, weight, threshold, sig, edges, signs, lap_rows, cand):
    """:func:`depth_edges` in one pass over the rows: a row's Laplacian and significance (the
    interior without border cases, so it vectorises), its selection, and the previous row's
    signs, which the selection can no longer change (lap_rows (2, w) int32: the last two rows'
    Laplacian; cand (w,) uint8: scratch)."""
    c, sig, edges, signs, lap_rows, cand = unmanaged(c), unmanaged(sig), unmanaged(edges), unmanaged(signs), \
        unmanaged(lap_rows), unmanaged(cand)
    h, w = c.shape
    for y in range(h + 1):
        if y < h:
            r = y & 1
            lap = lap_rows[r]
            if 0 < y < h - 1 and w > 2:
                lap[0] = _laplacian_at(c, y, 0)
                lap[w - 1] = _laplacian_at(c, y, w - 1)
                up, mid, down = c[y - 1], c[y], c[y + 1]
                for x in range(1, w - 1):
                    lap[x] = up[x] + down[x] + mid[x - 1] + mid[x + 1] - 4 * mid[x]
            else:
                for x in range(w):
                    lap[x] = _laplacian_at(c, y, x)
            sig_row = sig[y]
            for x in range(w):
                sig_row[x] = weight * np.float32(abs(lap[x]))
            # pixels where _select_at has something to do, flagged without branches (vectorises)
            mid = c[y]
            for x in range(w - 1):
                cand[x] = (sig_row[x] > threshold) | ((mid[x] == 0) != (mid[x + 1] == 0))
            cand[w - 1] = sig_row[w - 1] > threshold
            if y + 1 < h:
                down = c[y + 1]
                for x in range(w):
                    cand[x] |= (mid[x] == 0) != (down[x] == 0)
            for x in range(w):
                if cand[x]:
                    _select_at(c, sig_row[x], threshold, edges, y, x)
        if y > 0:
            r = (y - 1) & 1
            for x in range(w):
                signs[y - 1, x] = 0 if not edges[y - 1, x] else (1 if lap_rows[r, x] > 0 else -1)


def depth_edges(codes, threshold: float = DEFAULT_THRESHOLD,
                weight: float = 1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(edges (h, w) bool, signs (h, w) int8, significance (h, w) float32) of codes (h, w) whose
    significance is ``weight * |laplacian(codes)|`` (float32, as numpy computes it): the same
    as :func:`select_edges` of that significance, in one compiled pass without temporaries."""
    c = np.ascontiguousarray(codes, dtype=np.int32)
    if c.ndim != 2:
        raise ValueError(f"codes must have shape (h, w), got {c.shape}")
    h, w = c.shape
    edges = np.zeros((h, w), dtype=bool)
    signs = np.empty((h, w), dtype=np.int8)
    sig = np.empty((h, w), dtype=np.float32)
    _depth_edges_kernel(c, np.float32(weight), np.float32(threshold), sig, edges, signs,
                        np.empty((2, w), dtype=np.int32), np.empty(w, dtype=np.uint8))
    return edges, signs, sig


def select_edges(codes, threshold: float = DEFAULT_THRESHOLD, significance=None,
                 lap=None) -> tuple[np.ndarray, np.ndarray]:
    """Edge samples of a code image: (edges (h, w) bool, signs (h, w) int8: +1 / -1 on edges, 0 elsewhere).

    codes : (h, w) int quantized disparity (0 = sky); significance : (h, w) float, default |Laplacian|;
    lap : the Laplacian of ``codes`` if already computed.
    A pixel is an edge where its significance exceeds ``threshold``; then the neighbour across
    its largest jump (if that jump exceeds the threshold too), so both sides of a discontinuity
    are sampled; and both pixels of every sky/surface boundary, whatever their significance.
    The sign is that of the Laplacian (0 counts as negative).
    """
    c = np.ascontiguousarray(codes, dtype=np.int32)
    L = laplacian(c) if lap is None else np.asarray(lap, dtype=np.int32)
    sig = np.abs(L) if significance is None else significance
    sig = np.ascontiguousarray(sig, dtype=np.float32)
    if sig.shape != c.shape or L.shape != c.shape:
        raise ValueError(f"significance and Laplacian must have the codes' shape {c.shape}")
    edges = np.zeros(c.shape, dtype=bool)
    _select_kernel(c, sig, np.float32(threshold), edges)
    signs = np.empty(c.shape, dtype=np.int8)
    _signs_kernel(edges, np.ascontiguousarray(L), signs)
    return edges, signs


# ------------------------------------------------------------------------------------------
# Results
# ------------------------------------------------------------------------------------------

@dataclass
class DecodedSamples:
    """Everything a payload carries, as the decoder sees it.

    edges : (h, w) bool edge samples; signs : (h, w) int8, Laplacian sign (+1 / -1) at edges, 0 elsewhere;
    codes : (h, w) uint16 sample codes where ``valid``; valid : (h, w) bool, edges and regular samples;
    regular : (rh, rw) uint16 regular samples at rows ``regular_rows`` (rh,) and cols ``regular_cols`` (rw,)
    (where a regular sample sits on an edge pixel, ``codes`` holds the edge value);
    motion : (h, w, 2) float32 pixels or None; moving : (h, w) bool or None.
    """

    edges: np.ndarray
    signs: np.ndarray
    codes: np.ndarray
    valid: np.ndarray
    regular: np.ndarray
    regular_rows: np.ndarray
    regular_cols: np.ndarray
    bits: int
    min_code: int
    q: int = 1
    motion: np.ndarray | None = None
    moving: np.ndarray | None = None

    @property
    def shape(self) -> tuple[int, int]:
        return self.edges.shape


@dataclass
class EncodeStats:
    """Sizes of one encoded frame (bytes) and its sample counts."""

    header_bytes: int
    edge_bytes: int
    regular_bytes: int
    value_bytes: int
    motion_bytes: int
    n_edges: int
    n_regular: int
    temporal: bool
    four_passes: bool

    @property
    def total_bytes(self) -> int:
        return self.header_bytes + self.edge_bytes + self.regular_bytes + self.value_bytes + self.motion_bytes

    @property
    def total_bits(self) -> int:
        return 8 * self.total_bytes

    def bits(self) -> dict:
        """{part: bits} of header, edge image, regular samples, edge values, motion."""
        return {"header": 8 * self.header_bytes, "edges": 8 * self.edge_bytes, "regular": 8 * self.regular_bytes,
                "values": 8 * self.value_bytes, "motion": 8 * self.motion_bytes}


@dataclass
class EncodedDepth:
    """payload : bytes to send; stats; samples : the decoder's view of the frame (keep it for the next warp)."""

    payload: bytes
    stats: EncodeStats
    samples: DecodedSamples


@dataclass
class WarpedPrevious:
    """The previous frame's edge samples in the current view: edges (h, w) bool, values (h, w) int32, -1 where none."""

    edges: np.ndarray
    values: np.ndarray = field(repr=False)


# ------------------------------------------------------------------------------------------
# Encoder / decoder
# ------------------------------------------------------------------------------------------

def _check_quantizer(quantizer, bits):
    q = default_quantizer(bits) if quantizer is None else quantizer
    if q.bits != bits:
        raise ValueError(f"quantizer has {q.bits} bits, the codec {bits}")
    if not (bitstream.MIN_BITS <= bits <= bitstream.MAX_BITS):
        raise ValueError(f"edge codec bits must be {bitstream.MIN_BITS}..{bitstream.MAX_BITS}, got {bits}")
    return q


def _check_size(width, height):
    if not (1 <= width <= bitstream.MAX_SIZE and 1 <= height <= bitstream.MAX_SIZE):
        raise ValueError(f"edge codec size must be 1..{bitstream.MAX_SIZE} per side, got {width}x{height}")


@njit(cache=True, nogil=True)
def _assemble_kernel(edges, values, off, regular, rows, cols, codes, valid):
    """codes / valid (h, w), written whole: the edges' values (0 elsewhere), then the regular samples."""
    h, w = edges.shape
    uoff = np.uint64(off)
    for y in range(np.uint64(h)):
        # branch-free on unsigned indices, so the loop vectorises (signed ones are wrap-around tested)
        for x in range(np.uint64(w)):
            e = edges[y, x]
            codes[y, x] = values[y + uoff, x + uoff] if e else 0
            valid[y, x] = e
    for i in range(len(rows)):
        for j in range(len(cols)):
            y, x = rows[i], cols[j]
            valid[y, x] = True
            if not edges[y, x]:
                codes[y, x] = regular[i, j]


def _assemble(edges, signs, values, regular, rows, cols, bits, min_code, q, motion=None, moving=None,
              values_pad: int = 0):
    """The DecodedSamples of decoded parts; values (h + 2 pad, w + 2 pad): the edges' values
    with a border of ``values_pad`` (the value coder's padded image, read without a copy)."""
    h, w = edges.shape
    codes = np.empty((h, w), dtype=np.uint16)   # written whole by the kernel
    valid = np.empty((h, w), dtype=bool)
    edges = np.ascontiguousarray(edges, dtype=bool)
    _assemble_kernel(edges, np.ascontiguousarray(values), values_pad, np.ascontiguousarray(regular), rows, cols,
                     codes, valid)
    return DecodedSamples(edges=edges, signs=signs, codes=codes, valid=valid, regular=regular.astype(np.uint16),
                          regular_rows=rows, regular_cols=cols, bits=bits, min_code=min_code, q=q,
                          motion=motion, moving=moving)


class EdgeEncoder:
    """Encoder of one depth stream (keep one per stream: nothing is shared between calls but settings).

    width, height : view size; bits : code bits (10..16); quantizer : a :class:`DepthQuantizer`
    with those bits (default :func:`default_quantizer`); q : residual step (1 = lossless codes);
    temporal : use the warped previous frame as context when given; passes : 4 (interleaved) or
    1 (raster); threshold : default significance threshold (code units).
    """

    def __init__(self, width: int, height: int, bits: int = 12, quantizer: DepthQuantizer | None = None,
                 q: int = 1, temporal: bool = True, passes: int = 4, threshold: float = DEFAULT_THRESHOLD,
                 spacing_log2: int = DEFAULT_SPACING_LOG2, motion_scale: int = 8, motion_block_log2: int = 3):
        _check_size(width, height)
        self.width, self.height, self.bits = int(width), int(height), int(bits)
        self.quantizer = _check_quantizer(quantizer, bits)
        self.max_code = (1 << bits) - 1
        if not (1 <= q <= self.max_code):
            raise ValueError(f"q must be 1..{self.max_code}, got {q}")
        if passes not in (1, 4):
            raise ValueError(f"passes must be 1 or 4, got {passes}")
        if not (bitstream.MIN_SPACING_LOG2 <= spacing_log2 <= bitstream.MAX_SPACING_LOG2):
            raise ValueError(f"spacing_log2 must be {bitstream.MIN_SPACING_LOG2}..{bitstream.MAX_SPACING_LOG2}")
        self.q, self.temporal, self.passes, self.threshold = int(q), bool(temporal), passes, float(threshold)
        self.spacing_log2 = spacing_log2
        self.motion_scale, self.motion_block_log2 = motion_scale, motion_block_log2
        self.rows, self.cols = sample_positions(self.width, self.height, spacing_log2)
        self.nearest_rows = nearest_index(self.rows, self.height)
        self.nearest_cols = nearest_index(self.cols, self.width)
        self._values_workspace = ValueWorkspace(self.height, self.width)

    def codes(self, distance) -> np.ndarray:
        """distance (h, w) -> codes (h, w) int32 of this encoder's quantizer."""
        d = np.asarray(distance)
        if d.shape != (self.height, self.width):
            raise ValueError(f"distance must have shape ({self.height}, {self.width}), got {d.shape}")
        return quantize_codes(d, self.quantizer)

    def encode(self, distance, warped_prev_edges=None, warped_prev_values=None, threshold: float | None = None,
               significance=None, edges=None, signs=None, motion=None, moving=None, codes=None) -> EncodedDepth:
        """Encode one frame.

        distance : (h, w) float radial distance, 0 = sky. warped_prev_edges : (h, w) bool and
        warped_prev_values : (h, w) int (-1 = none), from :func:`warp_samples` of the previous
        frame's ``samples`` (used only with ``temporal``). threshold / significance : edge
        selection (see :func:`select_edges`); or ``edges`` (h, w) bool (and optionally ``signs``)
        chosen by the caller. motion : (h, w, 2) float pixels of moving objects; moving :
        (h, w) bool (default: pixels with non-zero motion). codes : (h, w) int32, this encoder's
        :meth:`codes` of ``distance`` when the caller already has them (the server's edge
        extraction does), so they are not computed twice.
        """
        if codes is None:
            codes = self.codes(distance)
        else:
            codes = np.asarray(codes)
            if codes.shape != (self.height, self.width):
                raise ValueError(f"codes must have shape ({self.height}, {self.width}), got {codes.shape}")
        h, w = codes.shape
        if edges is None:
            thr = self.threshold if threshold is None else float(threshold)
            edges, signs_found = select_edges(codes, thr, significance)
            if signs is None:
                signs = signs_found
        else:
            edges = np.asarray(edges, dtype=bool)
            if edges.shape != (h, w):
                raise ValueError(f"edges must have shape ({h}, {w}), got {edges.shape}")
        edges = np.ascontiguousarray(edges)
        # +1 / -1 on edges (the sign of the Laplacian unless given), 0 elsewhere
        given = laplacian(codes) if signs is None else np.ascontiguousarray(signs)
        signs = np.empty((h, w), dtype=np.int8)
        _signs_kernel(edges, given, signs)
        use_t = self.temporal and warped_prev_edges is not None
        four = self.passes == 4
        tctx = temporal_context(warped_prev_edges, h, w) if use_t else None
        tvals = self._values_workspace.temporal_values(warped_prev_values if use_t else None)

        edge_bytes = encode_edge_image(edges, tctx, four)
        reg_true = codes[np.ix_(self.rows, self.cols)]
        reg_bytes, reg_dec = encode_regular(reg_true, self.q, self.max_code)
        val_bytes, _ = encode_values(edges, codes, signs, reg_dec, self.nearest_rows, self.nearest_cols,
                                           self.q, self.max_code, tvals, workspace=self._values_workspace)
        mot_bytes, mot_dec, mov_dec = b"", None, None
        if motion is not None:
            motion = np.asarray(motion, dtype=np.float64)
            if motion.shape != (h, w, 2):
                raise ValueError(f"motion must have shape ({h}, {w}, 2), got {motion.shape}")
            mov = np.any(motion != 0, axis=-1) & np.all(np.isfinite(motion), axis=-1) if moving is None \
                else np.asarray(moving, dtype=bool)
            mot_bytes, mot_dec, mov_dec = encode_motion(motion, mov, self.motion_scale, self.motion_block_log2)
            if not mot_bytes:
                mot_dec = mov_dec = None
        n_edges = int(np.count_nonzero(edges))
        head = FrameHeader(width=w, height=h, bits=self.bits, min_code=self.quantizer.min_code, q=self.q,
                           n_edges=n_edges, temporal=use_t, four_passes=four, motion=bool(mot_bytes),
                           spacing_log2=self.spacing_log2)
        payload = head.pack((edge_bytes, reg_bytes, val_bytes, mot_bytes))
        stats = EncodeStats(header_bytes=bitstream.HEADER_SIZE, edge_bytes=len(edge_bytes),
                            regular_bytes=len(reg_bytes), value_bytes=len(val_bytes), motion_bytes=len(mot_bytes),
                            n_edges=n_edges, n_regular=reg_true.size, temporal=use_t, four_passes=four)
        # the decoded values, read from the value workspace's padded image
        samples = _assemble(edges, signs, self._values_workspace.V, reg_dec, self.rows, self.cols, self.bits,
                            self.quantizer.min_code, self.q, mot_dec, mov_dec, values_pad=VALUES_PAD)
        return EncodedDepth(payload=payload, stats=stats, samples=samples)


class EdgeDecoder:
    """Decoder of one depth stream: the size and quantizer must match the encoder's (checked)."""

    def __init__(self, width: int, height: int, bits: int = 12, quantizer: DepthQuantizer | None = None):
        _check_size(width, height)
        self.width, self.height, self.bits = int(width), int(height), int(bits)
        self.quantizer = _check_quantizer(quantizer, bits)
        self._values_workspace = ValueWorkspace(self.height, self.width)

    def decode(self, payload, warped_prev_edges=None, warped_prev_values=None) -> DecodedSamples:
        """payload -> :class:`DecodedSamples`. Raises :class:`CodecError` when it does not decode."""
        head, sections = bitstream.parse(payload)
        if (head.width, head.height) != (self.width, self.height):
            raise CodecError(f"edge codec: payload is {head.width}x{head.height}, decoder expects "
                             f"{self.width}x{self.height}")
        if head.bits != self.bits or head.min_code != self.quantizer.min_code:
            raise CodecError(f"edge codec: payload has {head.bits} bits and min_code {head.min_code}, decoder "
                             f"expects {self.bits} and {self.quantizer.min_code}")
        h, w = self.height, self.width
        if head.temporal and warped_prev_edges is None:
            raise CodecError("edge codec: payload was coded against the previous frame, which the decoder lacks")
        tctx = temporal_context(warped_prev_edges, h, w) if head.temporal else None
        tvals = self._values_workspace.temporal_values(warped_prev_values if head.temporal else None)
        max_code = (1 << head.bits) - 1

        edges, ok = decode_edge_image(sections["edges"], h, w, tctx, head.four_passes)
        if not ok:
            raise CodecError("edge codec: edge image stream is corrupt")
        n = int(np.count_nonzero(edges))
        if n != head.n_edges:
            raise CodecError(f"edge codec: edge image has {n} edges, header announces {head.n_edges}")
        shape = grid_shape(w, h, head.spacing_log2)
        regular, ok = decode_regular(sections["regular"], shape, head.q, max_code)
        if not ok:
            raise CodecError("edge codec: regular sample stream is corrupt")
        rows, cols = sample_positions(w, h, head.spacing_log2)
        values, signs, ok = decode_values(sections["values"], edges, regular, nearest_index(rows, h),
                                          nearest_index(cols, w), head.q, max_code, tvals,
                                          workspace=self._values_workspace)
        if not ok:
            raise CodecError("edge codec: edge value stream is corrupt")
        motion = moving = None
        if head.motion:
            motion, moving = decode_motion(sections["motion"], h, w)
        return _assemble(edges, signs, values, regular, rows, cols, head.bits, head.min_code, head.q, motion, moving)


# ------------------------------------------------------------------------------------------
# Temporal warp (both ends)
# ------------------------------------------------------------------------------------------

@njit(cache=True, nogil=True, error_model="numpy")  # no division-by-zero checks: every divisor is > 0
def _warp_kernel(edges, codes, rp, t, rc, near, far, min_code, max_code, eps, values):
    """``warp_samples_numpy`` (tests/protocol/edgecodec_reference.py) per sample, operation for
    operation (so bit-identical): unproject
    (INVERSE), dequantize (DEQUANTIZE), move, project (FORWARD), quantize (QUANTIZE), splat max."""
    h, w = edges.shape
    span = max_code - min_code
    sky_below = 0.5 * min_code if min_code < 1.5 else 0.25 * min_code
    peeled_below = 0.0 if min_code < 1.5 else 0.75 * min_code
    for y in range(h):
        for x in range(w):
            if not edges[y, x]:
                continue
            code = float(codes[y, x])
            vx = (x + 0.5) / w * 2.0 - 1.0
            vy = 1.0 - (y + 0.5) / h * 2.0
            ty = min(max(vy, -1.0), 1.0)
            dx = min(max(vx, -1.0), 1.0) * math.sqrt(max(1.0 - ty * ty, 0.0))
            dy = ty
            dz = -math.sqrt(max(1.0 - dx * dx - ty * ty, 0.0))
            d = max((code - min_code) / span, 0.5 / span)
            r = min(near / d, far)
            if code < peeled_below:
                r = -1.0
            if code < sky_below:
                r = 0.0
            sky = r <= 0.0
            if sky:
                r = 1.0
            ax, ay, az = dx * r, dy * r, dz * r
            wx = rp[0, 0] * ax + rp[0, 1] * ay + rp[0, 2] * az
            wy = rp[1, 0] * ax + rp[1, 1] * ay + rp[1, 2] * az
            wz = rp[2, 0] * ax + rp[2, 1] * ay + rp[2, 2] * az
            if not sky:
                wx = wx + t[0]
                wy = wy + t[1]
                wz = wz + t[2]
            cx = rc[0, 0] * wx + rc[0, 1] * wy + rc[0, 2] * wz
            cy = rc[1, 0] * wx + rc[1, 1] * wy + rc[1, 2] * wz
            cz = rc[2, 0] * wx + rc[2, 1] * wy + rc[2, 2] * wz
            m = max(max(abs(cx), abs(cy)), max(abs(cz), eps))
            qx, qy, qz = cx / m, cy / m, cz / m
            qn = math.sqrt(qx * qx + qy * qy + qz * qz)
            dist = m * qn
            py = min(max(qy / max(qn, eps), -1.0), 1.0)
            px = min(max(qx / max(math.sqrt(qx * qx + qz * qz), eps), -1.0), 1.0)
            col = int(math.floor((px + 1.0) * 0.5 * w))
            row = int(math.floor((1.0 - py) * 0.5 * h))
            if not (cz <= 0.0 and 0 <= col < w and 0 <= row < h):
                continue
            new = code_of(0.0 if sky else dist, near, far, min_code, span)
            if int(new) > values[row, col]:
                values[row, col] = int(new)


def warp_samples(samples: DecodedSamples, prev_pose: Pose, cur_pose: Pose,
                 quantizer: DepthQuantizer) -> WarpedPrevious:
    """Forward-splat the previous frame's decoded edge samples into the current wide-angle view.

    Each edge sample is unprojected through its pixel centre at its decoded distance (sky: a
    direction at infinity), moved from ``prev_pose`` to ``cur_pose`` (camera-to-world poses),
    projected, and splatted to the pixel containing it with its re-quantized code; where
    several land on one pixel the nearest (largest code) wins. Compiled, with the same IEEE
    operations in the same order as its numpy definition (``warp_samples_numpy`` in
    tests/protocol/edgecodec_reference.py; no fused multiply-adds: numba does not contract
    without fastmath), so encoder and decoder get identical results and so does the numpy
    definition (tested).
    """
    h, w = samples.shape
    values = np.full((h, w), -1, dtype=np.int32)
    t = np.asarray(prev_pose.position, dtype=np.float64) - np.asarray(cur_pose.position, dtype=np.float64)
    _warp_kernel(np.ascontiguousarray(samples.edges), np.ascontiguousarray(samples.codes),
                 np.ascontiguousarray(prev_pose.rotation(), dtype=np.float64), t,
                 np.ascontiguousarray(cur_pose.rotation().T, dtype=np.float64), float(quantizer.near),
                 float(quantizer.far), float(quantizer.min_code), float(quantizer.max_code), float(_EPS), values)
    return WarpedPrevious(edges=values >= 0, values=values)
