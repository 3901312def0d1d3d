"""Dense depth from the edge codec's sparse samples: push-pull diffusion (Pajak et al. 2011, Sec. 5).

**Push-pull** (:func:`push_pull_fast`) fills the pixels without a sample. *Push* builds a pyramid:
each level halves the resolution in two quincunx steps, first every pixel with x + y even
averages itself (weight 1/2) and its four axial neighbours (1/8 each), then every pixel with x
and y even averages itself and its four diagonal neighbours from that lattice; weights are
multiplied by validity, so only samples contribute, and a coarse pixel is valid when anything
contributed. *Pull* goes back down: a coarse value is copied to its even pixel where that
pixel has nothing of its own, the odd-odd pixels take the mean of their four diagonal
neighbours, then the remaining pixels the mean of their four axial neighbours. Samples are
never overwritten. After the pull, every level runs red-black Gauss-Seidel sweeps of the
Laplace equation on its unknown pixels (``iterations`` at the finest level, twice as many
per coarser level, which cost little: a cascadic multigrid), so the result approaches the
harmonic interpolation of the samples, which reproduces planes. On the image border the
missing neighbour is extrapolated linearly (not mirrored), so a slanted plane running into
the border stays a plane. It runs as numba kernels; their vectorised numpy definition, equal to
rounding, is ``push_pull_numpy`` in tests/client/diffusion_reference.py (compared there).

**Edge-aware diffusion** (:func:`diffuse`). Plain push-pull averages samples from both sides of
a depth discontinuity at its coarse levels and smears the step over many pixels. But the
edges are two pixels wide, each side carrying its own value, so the pixels without a sample
fall into regions (4-connected components of non-edge pixels) each of which touches only the
samples of its own side: the edge pixels 4-adjacent to it, and the regular samples inside it.
(Those inner samples are the ones whose Laplacian sign points into the region; the sign
itself is not needed once the components are known.) Each region is push-pulled from its
own samples only, inside its bounding box, so nothing blends across a closed edge; where an
edge line has a gap the two regions are one and may blend there. (The finest level's sweeps
only ever read a region pixel's 4-neighbours, which are its region or its own samples, so
they pull a blended value back towards its own side.) A region without any sample takes the
plain push-pull value. The total work is bounded: regions whose bounding boxes would exceed
``max_work`` times the image area also fall back to plain push-pull.

Measured on a 1024^2 room frame (threshold 3.5, 4.1 % edge samples): edge-aware 62.1 dB PSNR
of the 12-bit codes, max error 37 codes; plain push-pull 54.1 dB, max 276 codes. The boxes sum
to ~1.8 images on room frames (the largest region's box is the whole image), the regions to
~0.96. So only the coarse levels are computed over each box; the finest level (push, pull and
sweeps: about two thirds of a push-pull's work) only on row spans reaching 3 pixels beyond the
region, which is exact (see :func:`_diffuse_regions`), and the regions are found as row runs
(:func:`_label_runs`). That costs about 1.5 plain push-pulls (`pibr bench codec-speed`), with
the same output, bit for bit, as push-pulling every whole box (kept in
tests/client/diffusion_reference.py and compared there). Tried and not
kept (issue 12): one pyramid shared by all regions, whose cells hold one entry per region
present (sum and weight of that region's samples, pushed with bilinear weights, pulled
bilinearly, swept among same-region cells): about as costly as a plain push-pull, but
0.55-0.8 dB below this per-region diffusion in disparity PSNR on room frames; with all pixels
one region it was 2.7 dB below the quincunx push-pull below, so its bilinear pyramid, not the
region bookkeeping, lost the quality. A shared pyramid with this module's quincunx steps per
region entry is the next thing to try; it would change the result (a coarse level no longer
bounded by each region's box).

Codes are diffused (disparity is linear on planes, so diffusion between edge samples
reconstructs planes); :func:`codes_to_distance` turns them into distance, with 0 (sky) where
the sky code dominates (a diffused code below a quarter of min_code) and the peeled marker
below three quarters (protocol/depth.py).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from pibr.protocol.depth import DEQUANTIZE, DepthQuantizer
from pibr.protocol.edgecodec.codec import DecodedSamples

_C_SELF, _C_NEIGHBOUR = 0.5, 0.125
#: Gauss-Seidel sweeps after the pull at the finest level (twice as many per coarser level).
DEFAULT_ITERATIONS = 4
#: Sweeps at a coarse level are capped here.
_MAX_ITERATIONS = 64


# ------------------------------------------------------------------------------------------
# numba push-pull
# ------------------------------------------------------------------------------------------

@njit(cache=True, nogil=True)
def _smooth_simple(u, m, iterations):
    """The sweeps of ``_smooth_np`` (tests/client/diffusion_reference.py) in numba (in place),
    straight from their definition."""
    h, w = u.shape
    for _ in range(iterations):
        for colour in range(2):
            for y in range(1, h - 1):
                for x in range(1 + ((y + colour + 1) & 1), w - 1, 2):
                    if not m[y, x]:
                        u[y, x] = 0.25 * (u[y - 1, x] + u[y + 1, x] + u[y, x - 1] + u[y, x + 1])
            if w > 2:
                for y in (0, h - 1):
                    for x in range(1 + ((y + colour + 1) & 1), w - 1, 2):
                        if not m[y, x]:
                            u[y, x] = 0.5 * (u[y, x - 1] + u[y, x + 1])
                    if h == 1:
                        break
            if h > 2:
                for x in (0, w - 1):
                    for y in range(1 + ((x + colour + 1) & 1), h - 1, 2):
                        if not m[y, x]:
                            u[y, x] = 0.5 * (u[y - 1, x] + u[y + 1, x])
                    if w == 1:
                        break


@njit(cache=True, nogil=True)
def _half_sweep(t, o, f, h, w, p0):
    """Update the pixels of one colour, compacted row by row into t (h, (w + 1) // 2): pixel
    (y, x = 2k + p) with p = (y + p0) & 1 is t[y, k]; the other colour's pixels are o[y, k'] at
    x = 2k' + 1 - p, so its upper and lower neighbours are o[y -+ 1, k], its left one
    o[y, k - 1 + p] and its right one o[y, k + p]. f: the compacted fixed mask of t. The
    arithmetic is :func:`_smooth_simple`'s, term for term. (Indexed in 2-D throughout: row
    views would cost a reference-count update each.)"""
    for y in range(h):
        p = (y + p0) & 1
        k_first = 1 - p          # x >= 1
        k_last = (w - 2 - p) // 2  # x <= w - 2
        if y == 0 or y == h - 1:  # border row: the 1-D equation along it, corners stay
            for k in range(k_first, k_last + 1):
                v = 0.5 * (o[y, k - 1 + p] + o[y, k + p])
                t[y, k] = t[y, k] if f[y, k] else v
            continue
        # unsigned indices: numba tests signed ones for wrap-around on every access, which keeps
        # the loop from being vectorised (k - 1 + p >= 0 since k >= 1 - p)
        uy, up, one = np.uint64(y), np.uint64(p), np.uint64(1)
        for k in range(np.uint64(k_first), np.uint64(k_last + 1)):
            v = 0.25 * (o[uy - one, k] + o[uy + one, k] + o[uy, k + up - one] + o[uy, k + up])
            t[uy, k] = t[uy, k] if f[uy, k] else v
        if p == 0 and not f[y, 0]:  # x = 0: the 1-D equation along the border column
            t[y, 0] = 0.5 * (o[y - 1, 0] + o[y + 1, 0])
        if ((w - 1 - p) & 1) == 0:  # x = w - 1 has this colour
            k = (w - 1 - p) // 2
            if not f[y, k]:
                t[y, k] = 0.5 * (o[y - 1, k] + o[y + 1, k])


@njit(cache=True, nogil=True)
def _smooth_nb(u, m, iterations, sf=None, su=None):
    """The sweeps of ``_smooth_np`` (tests/client/diffusion_reference.py) in numba (in place).

    The two colours are compacted into arrays of their own first, so each half-sweep reads
    and writes contiguous rows (vectorised: measured ~3x faster than striding over the full
    image); the arithmetic is the same, term for term, so results equal :func:`_smooth_simple`'s
    exactly. Small or thin images go straight to :func:`_smooth_simple`. sf (float64) and su
    (uint8), flat, of at least 2 h ceil(w / 2) elements: scratch for the compacted colours
    (allocated here when None).
    """
    h, w = u.shape
    if h < 3 or w < 3 or h * w < 1024 or iterations <= 0:
        _smooth_simple(u, m, iterations)
        return
    wh = (w + 1) // 2
    n = h * wh
    if sf is None or su is None or len(sf) < 2 * n or len(su) < 2 * n:
        sf = np.empty(2 * n)
        su = np.empty(2 * n, dtype=np.uint8)
    red = sf[:n].reshape((h, wh))   # (x + y) even: updated first
    black = sf[n:2 * n].reshape((h, wh))
    fred = su[:n].reshape((h, wh))
    fblack = su[n:2 * n].reshape((h, wh))
    # in and out of the compacted colours a pixel pair (2 k, 2 k + 1) at a time, unsigned: the even
    # column goes to red in even rows, to black in odd ones
    one, uw = np.uint64(1), np.uint64(w)
    for y in range(np.uint64(h)):
        even_row = (y & one) == 0
        first, second = (red, black) if even_row else (black, red)
        ffirst, fsecond = (fred, fblack) if even_row else (fblack, fred)
        for k in range(uw >> one):
            first[y, k] = u[y, k + k]
            ffirst[y, k] = 1 if m[y, k + k] else 0
            second[y, k] = u[y, k + k + one]
            fsecond[y, k] = 1 if m[y, k + k + one] else 0
        if uw & one:
            first[y, uw >> one] = u[y, uw - one]
            ffirst[y, uw >> one] = 1 if m[y, uw - one] else 0
    for _ in range(iterations):
        _half_sweep(red, black, fred, h, w, 0)
        _half_sweep(black, red, fblack, h, w, 1)
    for y in range(np.uint64(h)):
        first, second = (red, black) if (y & one) == 0 else (black, red)
        for k in range(uw >> one):
            u[y, k + k] = first[y, k]
            u[y, k + k + one] = second[y, k]
        if uw & one:
            u[y, uw - one] = first[y, uw >> one]


@njit(cache=True, nogil=True)
def _pool_sizes(h, w):
    """(float64, uint8) pool elements :func:`_push_pull_pooled` needs for an (h, w) image; enough
    for any smaller one too."""
    nf = 0
    nu = 0
    while True:
        ch, cw = (h + 1) // 2, (w + 1) // 2
        nf += 2 * h * w + ch * cw
        nu += h * w + ch * cw
        if h == 1 and w == 1:
            return nf, nu
        h, w = ch, cw


@njit(cache=True, nogil=True, inline="always")
def _gather_axial_at(vv, mm, qv, qm, y, x, h, w):
    """Push step 1 at quincunx pixel (y, x) of an (h, w) level: self (1/2) and axial neighbours (1/8)."""
    num = 0.0
    den = 0.0
    if mm[y, x]:
        num += _C_SELF * vv[y, x]
        den += _C_SELF
    if y > 0 and mm[y - 1, x]:
        num += _C_NEIGHBOUR * vv[y - 1, x]
        den += _C_NEIGHBOUR
    if y + 1 < h and mm[y + 1, x]:
        num += _C_NEIGHBOUR * vv[y + 1, x]
        den += _C_NEIGHBOUR
    if x > 0 and mm[y, x - 1]:
        num += _C_NEIGHBOUR * vv[y, x - 1]
        den += _C_NEIGHBOUR
    if x + 1 < w and mm[y, x + 1]:
        num += _C_NEIGHBOUR * vv[y, x + 1]
        den += _C_NEIGHBOUR
    if den > 0:
        qv[y, x] = num / den
        qm[y, x] = 1
    else:
        qv[y, x] = 0.0
        qm[y, x] = 0


@njit(cache=True, nogil=True, inline="always")
def _gather_diagonal_at(qv, qm, cv, cm, i, j, h, w):
    """Push step 2 into coarse pixel (i, j) from even pixel (2 i, 2 j) (1/2) and its diagonals (1/8)."""
    y, x = 2 * i, 2 * j
    num = 0.0
    den = 0.0
    if qm[y, x]:
        num += _C_SELF * qv[y, x]
        den += _C_SELF
    for dy in (-1, 1):
        for dx in (-1, 1):
            yy, xx = y + dy, x + dx
            if 0 <= yy < h and 0 <= xx < w and qm[yy, xx]:
                num += _C_NEIGHBOUR * qv[yy, xx]
                den += _C_NEIGHBOUR
    if den > 0:
        cv[i, j] = num / den
        cm[i, j] = 1
    else:
        cv[i, j] = 0.0
        cm[i, j] = 0


@njit(cache=True, nogil=True, inline="always")
def _pull_diagonal_at(q, y, x, h, w):
    """Pull at odd-odd pixel (y, x): the mean of its diagonal neighbours inside the level."""
    s = 0.0
    n = 0
    for dy in (-1, 1):
        for dx in (-1, 1):
            yy, xx = y + dy, x + dx
            if 0 <= yy < h and 0 <= xx < w:
                s += q[yy, xx]
                n += 1
    q[y, x] = s / n


@njit(cache=True, nogil=True, inline="always")
def _pull_axial_at(vv, mm, q, out, y, x, h, w):
    """The pulled value at (y, x): its sample, its quincunx value, or the mean of its axial neighbours."""
    if mm[y, x]:
        out[y, x] = vv[y, x]
    elif (y + x) % 2 == 0:
        out[y, x] = q[y, x]
    else:
        s = 0.0
        n = 0
        if y > 0:
            s += q[y - 1, x]
            n += 1
        if y + 1 < h:
            s += q[y + 1, x]
            n += 1
        if x > 0:
            s += q[y, x - 1]
            n += 1
        if x + 1 < w:
            s += q[y, x + 1]
            n += 1
        out[y, x] = s / n


@njit(cache=True, nogil=True)
def _push_pull_pooled(v, m, iterations, fixed, fpool, upool, sf, su):
    """(h, w) float64 values and uint8 validity -> filled (h, w) float64.

    fixed : (h, w) uint8, the pixels the finest level's sweeps leave alone: ``m``, or more when
    the caller needs only some pixels (see :func:`_diffuse_regions`).
    Every level's arrays are views into the flat pools fpool (float64) and upool (uint8) of
    :func:`_pool_sizes`, sf / su the sweeps' scratch (see :func:`_smooth_nb`): a caller that
    diffuses many boxes reuses memory instead of faulting fresh pages in for every level of
    every box (perf: ~20 % of the diffusion was the kernel's page handling). Every element of
    those views that is read was written first (qv / qm only on the quincunx lattice, the only
    one read). The levels are walked down and up in loops, not by recursion (numba's cache
    cannot load a cached caller of a recursive function). Returns a view into fpool.
    """
    # level l: size (lh, lw), values / validity (the input at level 0, else the parent's cv / cm),
    # arrays out, qv at fpool[fo:], then cv; qm at upool[uo:], then cm
    one, two = np.uint64(1), np.uint64(2)
    max_levels = 64
    lh = np.empty(max_levels, dtype=np.int64)
    lw = np.empty(max_levels, dtype=np.int64)
    lfo = np.empty(max_levels, dtype=np.int64)
    luo = np.empty(max_levels, dtype=np.int64)
    lit = np.empty(max_levels, dtype=np.int64)
    h, w = v.shape
    fo = 0
    uo = 0
    it = iterations
    n_levels = 0
    vv = v
    mm = m
    while True:
        l = n_levels
        n_levels += 1
        lh[l], lw[l], lfo[l], luo[l], lit[l] = h, w, fo, uo, it
        hw = h * w
        ch, cw = (h + 1) // 2, (w + 1) // 2
        out = fpool[fo:fo + hw].reshape((h, w))
        n_valid = 0
        for y in range(np.uint64(h)):
            for x in range(np.uint64(w)):
                n_valid += mm[y, x] != 0
        if n_valid == hw or (h == 1 and w == 1):  # the coarsest level
            for y in range(h):
                for x in range(w):
                    out[y, x] = vv[y, x] if mm[y, x] else 0.0
            break
        qv = fpool[fo + hw:fo + 2 * hw].reshape((h, w))
        qm = upool[uo:uo + hw].reshape((h, w))
        # The interior runs branch-free on unsigned indices (a missing term adds +0.0, which changes
        # no sum: the results are those of _gather_axial_at, bit for bit).
        for y in range(h):
            if y == 0 or y == h - 1 or w < 3:
                for x in range(y & 1, w, 2):
                    _gather_axial_at(vv, mm, qv, qm, y, x, h, w)
                continue
            if y & 1 == 0:
                _gather_axial_at(vv, mm, qv, qm, y, 0, h, w)
            uy = np.uint64(y)
            for x in range(np.uint64(2 - (y & 1)), np.uint64(w - 1), two):
                num = (((0.0 + (_C_SELF * vv[uy, x] if mm[uy, x] else 0.0))
                        + (_C_NEIGHBOUR * vv[uy - one, x] if mm[uy - one, x] else 0.0))
                       + (_C_NEIGHBOUR * vv[uy + one, x] if mm[uy + one, x] else 0.0)) \
                    + (_C_NEIGHBOUR * vv[uy, x - one] if mm[uy, x - one] else 0.0)
                num = num + (_C_NEIGHBOUR * vv[uy, x + one] if mm[uy, x + one] else 0.0)
                den = (((0.0 + (_C_SELF if mm[uy, x] else 0.0)) + (_C_NEIGHBOUR if mm[uy - one, x] else 0.0))
                       + (_C_NEIGHBOUR if mm[uy + one, x] else 0.0)) + (_C_NEIGHBOUR if mm[uy, x - one] else 0.0)
                den = den + (_C_NEIGHBOUR if mm[uy, x + one] else 0.0)
                qv[uy, x] = num / (den if den > 0 else 1.0)  # 0.0 where nothing contributed
                qm[uy, x] = 1 if den > 0 else 0
            if (w - 1 - (y & 1)) & 1 == 0:
                _gather_axial_at(vv, mm, qv, qm, y, w - 1, h, w)
        cv = fpool[fo + 2 * hw:fo + 2 * hw + ch * cw].reshape((ch, cw))
        cm = upool[uo + hw:uo + hw + ch * cw].reshape((ch, cw))
        for i in range(ch):
            y = 2 * i
            if y == 0 or y + 1 >= h or w < 3:
                for j in range(cw):
                    _gather_diagonal_at(qv, qm, cv, cm, i, j, h, w)
                continue
            _gather_diagonal_at(qv, qm, cv, cm, i, 0, h, w)
            j_last = (w - 2) // 2  # the last j with x + 1 inside
            uy, ui = np.uint64(y), np.uint64(i)
            for j in range(one, np.uint64(j_last) + one):
                x = j + j
                num = (((0.0 + (_C_SELF * qv[uy, x] if qm[uy, x] else 0.0))
                        + (_C_NEIGHBOUR * qv[uy - one, x - one] if qm[uy - one, x - one] else 0.0))
                       + (_C_NEIGHBOUR * qv[uy - one, x + one] if qm[uy - one, x + one] else 0.0)) \
                    + (_C_NEIGHBOUR * qv[uy + one, x - one] if qm[uy + one, x - one] else 0.0)
                num = num + (_C_NEIGHBOUR * qv[uy + one, x + one] if qm[uy + one, x + one] else 0.0)
                den = (((0.0 + (_C_SELF if qm[uy, x] else 0.0)) + (_C_NEIGHBOUR if qm[uy - one, x - one] else 0.0))
                       + (_C_NEIGHBOUR if qm[uy - one, x + one] else 0.0)) \
                    + (_C_NEIGHBOUR if qm[uy + one, x - one] else 0.0)
                den = den + (_C_NEIGHBOUR if qm[uy + one, x + one] else 0.0)
                cv[ui, j] = num / (den if den > 0 else 1.0)
                cm[ui, j] = 1 if den > 0 else 0
            for j in range(j_last + 1, cw):
                _gather_diagonal_at(qv, qm, cv, cm, i, j, h, w)
        vv, mm = cv, cm
        fo += 2 * hw + ch * cw
        uo += hw + ch * cw
        h, w = ch, cw
        it = min(2 * it, _MAX_ITERATIONS)
    # back up: pull each level from the one below it, then its sweeps
    for l in range(n_levels - 2, -1, -1):
        h, w, fo, uo = lh[l], lw[l], lfo[l], luo[l]
        hw = h * w
        ch, cw = lh[l + 1], lw[l + 1]
        coarse = fpool[lfo[l + 1]:lfo[l + 1] + ch * cw].reshape((ch, cw))
        out = fpool[fo:fo + hw].reshape((h, w))
        q = fpool[fo + hw:fo + 2 * hw].reshape((h, w))  # qv, pulled into in place
        qm = upool[uo:uo + hw].reshape((h, w))
        if l == 0:
            vv, mm, fx = v, m, fixed
        else:
            vv = fpool[lfo[l - 1] + 2 * lh[l - 1] * lw[l - 1]:lfo[l - 1] + 2 * lh[l - 1] * lw[l - 1] + hw].reshape((h, w))
            mm = upool[luo[l - 1] + lh[l - 1] * lw[l - 1]:luo[l - 1] + lh[l - 1] * lw[l - 1] + hw].reshape((h, w))
            fx = mm
        for y in range(np.uint64(0), np.uint64(h), two):
            for x in range(np.uint64(0), np.uint64(w), two):
                q[y, x] = q[y, x] if qm[y, x] else coarse[y >> one, x >> one]
        for y in range(1, h, 2):
            if y + 1 >= h:
                for x in range(1, w, 2):
                    if not qm[y, x]:
                        _pull_diagonal_at(q, y, x, h, w)
                continue
            uy = np.uint64(y)
            for x in range(one, np.uint64(w - 1), two):  # x + 1 inside
                q[uy, x] = q[uy, x] if qm[uy, x] else \
                    ((((0.0 + q[uy - one, x - one]) + q[uy - one, x + one]) + q[uy + one, x - one])
                     + q[uy + one, x + one]) / 4
            if w % 2 == 0 and not qm[y, w - 1]:
                _pull_diagonal_at(q, y, w - 1, h, w)
        for y in range(h):
            if y == 0 or y == h - 1 or w < 3:
                for x in range(w):
                    _pull_axial_at(vv, mm, q, out, y, x, h, w)
                continue
            _pull_axial_at(vv, mm, q, out, y, 0, h, w)
            uy = np.uint64(y)
            p = np.uint64(y & 1)
            for x in range(two - p, np.uint64(w - 1), two):  # x + y even: the quincunx values
                out[uy, x] = vv[uy, x] if mm[uy, x] else q[uy, x]
            for x in range(one + p, np.uint64(w - 1), two):  # the others: the mean of their axial neighbours
                out[uy, x] = vv[uy, x] if mm[uy, x] else \
                    (((0.0 + q[uy - one, x]) + q[uy + one, x]) + q[uy, x - one] + q[uy, x + one]) / 4
            _pull_axial_at(vv, mm, q, out, y, w - 1, h, w)
        _smooth_nb(out, fx, lit[l], sf, su)
    return fpool[:v.shape[0] * v.shape[1]].reshape(v.shape)


@njit(cache=True, nogil=True)
def _push_pull_nb(v, m, iterations, fixed):
    """:func:`_push_pull_pooled` with pools of its own: filled (h, w) float64."""
    h, w = v.shape
    nf, nu = _pool_sizes(h, w)
    wh = (w + 1) // 2
    out = _push_pull_pooled(v, m, iterations, fixed, np.empty(nf), np.empty(nu, dtype=np.uint8),
                            np.empty(2 * h * wh), np.empty(2 * h * wh, dtype=np.uint8))
    return out.copy()


def push_pull_fast(values, valid, iterations: int = DEFAULT_ITERATIONS) -> np.ndarray:
    """Push-pull (module docstring): values (h, w) float, valid (h, w) bool -> (h, w) float64, the
    numpy definition's result (``push_pull_numpy`` in tests/client/diffusion_reference.py) up to
    float rounding. Samples keep their values; with no sample at all the result is 0.
    ``iterations`` red-black Gauss-Seidel sweeps follow the pull at the finest level, twice as
    many at each coarser one."""
    v = np.ascontiguousarray(values, dtype=np.float64)
    m = np.ascontiguousarray(valid, dtype=np.uint8)
    if v.shape != m.shape or v.ndim != 2:
        raise ValueError(f"values and valid must be (h, w) arrays of one shape, got {v.shape} and {m.shape}")
    if not m.any():
        return np.zeros_like(v)
    return _push_pull_nb(v, m, int(iterations), m)


# ------------------------------------------------------------------------------------------
# Edge-aware diffusion
# ------------------------------------------------------------------------------------------

@njit(cache=True, nogil=True)
def _label_regions(edges, labels):
    """4-connected components of non-edge pixels: labels (h, w) int32 from 1 (0 on edges);
    returns (n, boxes (n + 1, 4) int64 as y0, y1, x0, x1 inclusive, sizes (n + 1,)).

    Components are numbered in the raster order of their first pixel and filled run by run
    (a scanline flood fill: a popped seed labels its whole row run, then pushes one seed per
    unlabelled run above and below it), which touches each pixel a few times in row order
    instead of pushing every pixel through a stack.
    """
    h, w = edges.shape
    stack = np.empty(2 * h * w + 4, dtype=np.int64)  # a pixel is pushed at most once from each side
    # Rows 1..n are written as regions are found (np.empty: zeroing ~20 MB cost more than labelling).
    boxes = np.empty((h * w // 2 + 2, 4), dtype=np.int64)
    sizes = np.empty(h * w // 2 + 2, dtype=np.int64)
    boxes[0, :] = 0
    sizes[0] = 0
    n = 0
    for sy in range(h):
        for sx in range(w):
            if edges[sy, sx] or labels[sy, sx] != 0:
                continue
            n += 1
            if n >= len(sizes):  # cannot happen: components are separated by edges
                return -1, boxes, sizes
            top = 0
            stack[top] = sy * w + sx
            top += 1
            y0, y1, x0, x1 = sy, sy, sx, sx
            size = 0
            while top > 0:
                top -= 1
                p = stack[top]
                y, x = p // w, p % w
                if labels[y, x] != 0:
                    continue
                xl = x
                while xl > 0 and not edges[y, xl - 1] and labels[y, xl - 1] == 0:
                    xl -= 1
                xr = x
                while xr + 1 < w and not edges[y, xr + 1] and labels[y, xr + 1] == 0:
                    xr += 1
                for xx in range(xl, xr + 1):
                    labels[y, xx] = n
                size += xr - xl + 1
                y0, y1, x0, x1 = min(y0, y), max(y1, y), min(x0, xl), max(x1, xr)
                for yy in (y - 1, y + 1):
                    if yy < 0 or yy >= h:
                        continue
                    inside = False
                    for xx in range(xl, xr + 1):
                        free = not edges[yy, xx] and labels[yy, xx] == 0
                        if free and not inside:
                            if top >= len(stack):  # cannot happen: one seed per free run
                                return -1, boxes, sizes
                            stack[top] = yy * w + xx
                            top += 1
                        inside = free
            boxes[n, 0], boxes[n, 1], boxes[n, 2], boxes[n, 3] = y0, y1, x0, x1
            sizes[n] = size
    return n, boxes, sizes


@njit(cache=True, nogil=True)
def _find_root(parent, r):
    while parent[r] != r:
        parent[r] = parent[parent[r]]  # path halving
        r = parent[r]
    return r


@njit(cache=True, nogil=True)
def _label_runs(edges, runs, parent):
    """The regions of :func:`_label_regions` (same numbers, boxes and sizes), as row runs instead of a
    label image: union-find over the runs of non-edge pixels, each joined to the runs it overlaps in
    the row above, a region numbered by its first run in raster order (its first pixel).

    runs : (>= 2 h ceil(w / 2), 3) int32 scratch; parent : (>= h ceil(w / 2),) int32 scratch.
    Returns (n, boxes (n + 1, 4) int64 as in _label_regions, sizes (n + 1,), run_start (n + 2,)):
    region c's runs (y, first, last column) are runs[run_start[c]:run_start[c + 1]], in raster order.
    """
    h, w = edges.shape
    n_runs = 0
    prev = 0  # the previous row's first run
    for y in range(h):
        row = n_runs
        x = 0
        while x < w:
            if edges[y, x]:
                x += 1
                continue
            a = x
            while x + 1 < w and not edges[y, x + 1]:
                x += 1
            runs[n_runs, 0], runs[n_runs, 1], runs[n_runs, 2] = y, a, x
            parent[n_runs] = n_runs
            n_runs += 1
            x += 1
        i, j = prev, row
        while i < row and j < n_runs:  # overlapping runs of two rows are 4-connected
            if runs[i, 2] < runs[j, 1]:
                i += 1
            elif runs[j, 2] < runs[i, 1]:
                j += 1
            else:
                ri, rj = _find_root(parent, i), _find_root(parent, j)
                if ri < rj:  # the root is a region's first run
                    parent[rj] = ri
                elif rj < ri:
                    parent[ri] = rj
                if runs[i, 2] < runs[j, 2]:
                    i += 1
                else:
                    j += 1
        prev = row
    # number the regions by their first runs (a root precedes the rest of its region)
    region = np.empty(n_runs, dtype=np.int64)
    n = 0
    for r in range(n_runs):
        root = _find_root(parent, r)
        if root == r:
            n += 1
            region[r] = n
        else:
            region[r] = region[root]
    boxes = np.empty((n + 1, 4), dtype=np.int64)
    sizes = np.zeros(n + 1, dtype=np.int64)
    run_start = np.zeros(n + 2, dtype=np.int64)
    boxes[0, :] = 0
    for c in range(1, n + 1):
        boxes[c, 0], boxes[c, 1], boxes[c, 2], boxes[c, 3] = h, -1, w, -1
    for r in range(n_runs):
        c = region[r]
        y, a, b = runs[r, 0], runs[r, 1], runs[r, 2]
        boxes[c, 0] = min(boxes[c, 0], y)
        boxes[c, 1] = max(boxes[c, 1], y)
        boxes[c, 2] = min(boxes[c, 2], a)
        boxes[c, 3] = max(boxes[c, 3], b)
        sizes[c] += b - a + 1
        run_start[c + 1] += 1
    for c in range(1, n + 2):
        run_start[c] += run_start[c - 1]
    # grouped by region (stable: raster order within each), through the second half of runs
    fill = run_start[:n + 1].copy()
    for r in range(n_runs):
        c = region[r]
        k = n_runs + fill[c]
        fill[c] += 1
        runs[k, 0], runs[k, 1], runs[k, 2] = runs[r, 0], runs[r, 1], runs[r, 2]
    runs[:n_runs, :] = runs[n_runs:2 * n_runs, :]
    return n, boxes, sizes, run_start


@njit(cache=True, nogil=True)
def _half_sweep_runs(t, o, f, runs, r0, r1, p, y0, y1, x0, x1):
    """:func:`_half_sweep` on the row runs runs[r0:r1] (y, first, last column) of a box y0..y1,
    x0..x1 (inclusive) of a frame compacted by colour: update the pixels with (x + y) & 1 == p,
    t[y, x >> 1], from the other colour's o (f: t's fixed mask), by the same rules and sums."""
    one = np.uint64(1)
    uy0, uy1, ux0, ux1 = np.uint64(y0), np.uint64(y1), np.uint64(x0), np.uint64(x1)
    wide, tall = x1 - x0 > 1, y1 - y0 > 1  # box width, height > 2
    for r in range(r0, r1):
        y, a, b = np.uint64(runs[r, 0]), np.uint64(runs[r, 1]), np.uint64(runs[r, 2])
        xp = (np.uint64(p) + y) & one  # x = 2 k + xp
        first = a + ((a + xp) & one)
        if first > b:
            continue
        k_first, k_last = (first - xp) >> one, (b - xp) >> one
        if uy0 < y < uy1 and a > ux0 and b < ux1:  # interior of the box (so x >= 1)
            for k in range(k_first, k_last + one):
                v = 0.25 * (o[y - one, k] + o[y + one, k] + o[y, k - one + xp] + o[y, k + xp])
                t[y, k] = t[y, k] if f[y, k] else v
            continue
        for k in range(k_first, k_last + one):
            if f[y, k]:
                continue
            x = k + k + xp
            row_edge = y == uy0 or y == uy1
            col_edge = x == ux0 or x == ux1
            if not row_edge and not col_edge:
                t[y, k] = 0.25 * (o[y - one, k] + o[y + one, k] + o[y, k - one + xp] + o[y, k + xp])
            elif row_edge and not col_edge:  # the 1-D equation along the border, corners stay
                if wide:
                    t[y, k] = 0.5 * (o[y, k - one + xp] + o[y, k + xp])
            elif col_edge and not row_edge:
                if tall:
                    t[y, k] = 0.5 * (o[y - one, k] + o[y + one, k])


@njit(cache=True, nogil=True, inline="always")
def _gather_own_at(codes, own, sc, qv, qm, y, x, y0, y1, x0, x1):
    """Push step 1 at quincunx pixel (y, x) of box y0..y1, x0..x1 from the samples stamped sc."""
    one = np.uint64(1)
    num = 0.0
    den = 0.0
    if own[y, x] == sc:
        num += _C_SELF * codes[y, x]
        den += _C_SELF
    if y > y0 and own[y - one, x] == sc:
        num += _C_NEIGHBOUR * codes[y - one, x]
        den += _C_NEIGHBOUR
    if y < y1 and own[y + one, x] == sc:
        num += _C_NEIGHBOUR * codes[y + one, x]
        den += _C_NEIGHBOUR
    if x > x0 and own[y, x - one] == sc:
        num += _C_NEIGHBOUR * codes[y, x - one]
        den += _C_NEIGHBOUR
    if x < x1 and own[y, x + one] == sc:
        num += _C_NEIGHBOUR * codes[y, x + one]
        den += _C_NEIGHBOUR
    if den > 0:
        qv[y, x] = num / den
        qm[y, x] = sc


@njit(cache=True, nogil=True, inline="always")
def _gather_own_diagonal_at(qv, qm, sc, cv, cm, y, x, y0, y1, x0, x1):
    """Push step 2 into the coarse pixel of even pixel (y, x) of box y0..y1, x0..x1 (quincunx values stamped sc)."""
    one = np.uint64(1)
    num = 0.0
    den = 0.0
    if qm[y, x] == sc:
        num += _C_SELF * qv[y, x]
        den += _C_SELF
    up, down = y > y0, y < y1
    left, right = x > x0, x < x1
    if up and left and qm[y - one, x - one] == sc:
        num += _C_NEIGHBOUR * qv[y - one, x - one]
        den += _C_NEIGHBOUR
    if up and right and qm[y - one, x + one] == sc:
        num += _C_NEIGHBOUR * qv[y - one, x + one]
        den += _C_NEIGHBOUR
    if down and left and qm[y + one, x - one] == sc:
        num += _C_NEIGHBOUR * qv[y + one, x - one]
        den += _C_NEIGHBOUR
    if down and right and qm[y + one, x + one] == sc:
        num += _C_NEIGHBOUR * qv[y + one, x + one]
        den += _C_NEIGHBOUR
    if den > 0:
        cv[(y - y0) >> one, (x - x0) >> one] = num / den
        cm[(y - y0) >> one, (x - x0) >> one] = 1


#: How far (pixels, in rows and columns) the finest level's push and pull reach beyond a region:
#: its sweeps read the region and its 4-neighbours, whose pulled values read quincunx values
#: within 2 of the region, and a coarse sample exists only within 3 of it (see _diffuse_regions).
_REACH = 3


@njit(cache=True, nogil=True)
def _diffuse_regions(codes, valid, edges, n, boxes, runs, run_start, max_work, iterations, out, skipped, fws, uws,
                     stamps, stamp_base):
    """Push-pull every region (n, boxes, runs, run_start: see :func:`_label_runs`) from its own
    samples into ``out`` (h, w) (which also gets the samples); regions without samples or beyond
    the work budget are left alone and marked in ``skipped`` (n + 1,) uint8, zero on entry.
    Returns how many pixels are set (samples included). fws (float64) / uws (uint8): flat memory of at least
    :func:`_workspace_sizes` (h, w) elements, reused by every region; stamps: flat int32, 2 h w
    elements, none above stamp_base (see :meth:`DiffusionWorkspace.stamps`).

    Each region's result is exactly that of :func:`_push_pull_pooled` over its bounding box (one
    pixel of margin) with its own samples and the rest of the box fixed at the finest level's
    sweeps, but the finest level is only computed where it can matter, on row spans reaching
    ``_REACH`` pixels beyond the region: the sweeps update the region and read its 4-neighbours;
    their pulled values read the quincunx values within 2 pixels; and the push, which only sees
    the region's samples (the region and its 4-neighbours), leaves every quincunx value farther
    than 2 pixels and every coarse sample farther than 3 pixels from the region empty, so the
    coarse level is the box's, computed in full by :func:`_push_pull_pooled`. The same sums are
    formed in the same order as there, so the result is the same to the bit. Sample and quincunx
    membership are marked with stamp_base + the region's number in two frame-sized int32 arrays
    (nothing to clear between regions or frames).
    """
    h, w = codes.shape
    budget = max_work * h * w
    used = 0
    n_done = 0
    ch_max, cw_max = (h + 1) // 2, (w + 1) // 2
    nf, nu = _pool_sizes(ch_max, cw_max)
    ns = 2 * ch_max * ((cw_max + 1) // 2)
    nc = ch_max * cw_max
    fpool = fws[:nf]
    sf = fws[nf:nf + ns]
    cv_pool = fws[nf + ns:nf + ns + nc]
    qv = fws[nf + ns + nc:nf + ns + nc + h * w].reshape((h, w))  # quincunx values, then pulled in place
    # the finest level's result, compacted by colour: pixel (y, x) is ue[y, x >> 1] where x + y is
    # even, else uo[y, x >> 1]; ve / vo: the same of ``valid``
    wh = (w + 1) // 2
    ue = fws[nf + ns + nc + h * w:nf + ns + nc + h * w + h * wh].reshape((h, wh))
    uo = fws[nf + ns + nc + h * w + h * wh:nf + ns + nc + h * w + 2 * h * wh].reshape((h, wh))
    upool = uws[:nu]
    su = uws[nu:nu + ns]
    cm_pool = uws[nu + ns:nu + ns + nc]
    ve = uws[nu + ns + nc:nu + ns + nc + h * wh].reshape((h, wh))
    vo = uws[nu + ns + nc + h * wh:nu + ns + nc + 2 * h * wh].reshape((h, wh))
    # unsigned and branch-free (both colours of a row in one pass), so the loops vectorise
    uone = np.uint64(1)
    for y in range(np.uint64(h)):
        for x in range(np.uint64(w)):
            out[y, x] = codes[y, x]
            n_done += valid[y, x] != 0
        first = ve if (y & uone) == 0 else vo
        second = vo if (y & uone) == 0 else ve
        for k in range(np.uint64(w) >> uone):
            first[y, k] = valid[y, k + k]
            second[y, k] = valid[y, k + k + uone]
        if np.uint64(w) & uone:
            first[y, np.uint64(w) >> uone] = valid[y, np.uint64(w) - uone]
    own = stamps[:h * w].reshape((h, w))  # == sc: a sample of region c
    qm = stamps[h * w:2 * h * w].reshape((h, w))  # == sc: a quincunx value of region c
    span_a = np.empty(h, dtype=np.int64)
    span_b = np.empty(h, dtype=np.int64)
    row_a = np.empty(h, dtype=np.int64)
    row_b = np.empty(h, dtype=np.int64)
    c_it = min(2 * iterations, _MAX_ITERATIONS)
    one, two = np.uint64(1), np.uint64(2)
    for c in range(1, n + 1):
        # one pixel of margin: the region's boundary edge samples
        ry0, ry1 = boxes[c, 0], boxes[c, 1]
        y0, y1 = max(ry0 - 1, 0), min(ry1 + 1, h - 1)
        x0, x1 = max(boxes[c, 2] - 1, 0), min(boxes[c, 3] + 1, w - 1)
        bh, bw = y1 - y0 + 1, x1 - x0 + 1
        if used + bh * bw > budget:
            skipped[c] = 1
            continue
        used += bh * bw
        r0, r1 = run_start[c], run_start[c + 1]
        sc = stamp_base + c
        # the region's samples: its own valid pixels and the valid edge pixels 4-adjacent to it
        n_samples = 0
        n_unknown = 0
        for y in range(ry0, ry1 + 1):
            row_a[y] = w
            row_b[y] = -1
        for r in range(r0, r1):
            y, a, b = runs[r, 0], runs[r, 1], runs[r, 2]
            row_a[y] = min(row_a[y], a)
            row_b[y] = max(row_b[y], b)
            for x in range(a, b + 1):
                if valid[y, x]:
                    own[y, x] = sc
                    n_samples += 1
                else:
                    n_unknown += 1
                for yy in (y - 1, y + 1):
                    if 0 <= yy < h and edges[yy, x] and valid[yy, x]:
                        own[yy, x] = sc
                        n_samples += 1
            for xx in (a - 1, b + 1):
                if 0 <= xx < w and edges[y, xx] and valid[y, xx]:
                    own[y, xx] = sc
                    n_samples += 1
        if n_samples == 0 or n_unknown == 0:
            skipped[c] = n_unknown > 0
            continue
        # row spans reaching _REACH beyond the region, inside the box
        for y in range(y0, y1 + 1):
            a, b = w, -1
            for yy in range(max(y - _REACH, ry0), min(y + _REACH, ry1) + 1):
                a = min(a, row_a[yy])
                b = max(b, row_b[yy])
            span_a[y] = max(a - _REACH, x0)
            span_b[y] = min(b + _REACH, x1)
        # From here on the hot loops index with unsigned integers: numba wraps negative signed
        # indices around, and that test in every access keeps loops with bounds known only at run
        # time from being vectorised (measured: ~6x slower sweeps).
        uy0, uy1, ux0, ux1 = np.uint64(y0), np.uint64(y1), np.uint64(x0), np.uint64(x1)
        # push, step 1: the quincunx lattice (box parity) gathers its axial neighbours. Neighbours
        # outside the box carry no stamp of this region, so away from the frame's border the
        # loop needs no bounds tests and runs branch-free (an absent term adds +0.0: the same sums).
        for y in range(uy0, uy1 + one):
            sa, sb = np.uint64(span_a[y]), np.uint64(span_b[y])
            first = sa + ((sa - ux0 + y - uy0) & one)
            if y == 0 or y == h - 1 or w < 3:
                for x in range(first, sb + one, two):
                    _gather_own_at(codes, own, sc, qv, qm, y, x, uy0, uy1, ux0, ux1)
                continue
            lo = first
            if first == 0:
                _gather_own_at(codes, own, sc, qv, qm, y, first, uy0, uy1, ux0, ux1)
                lo = two
            hi = sb if sb < w - 1 else np.uint64(w - 2)
            for x in range(lo, hi + one, two):
                num = (((0.0 + (_C_SELF * codes[y, x] if own[y, x] == sc else 0.0))
                        + (_C_NEIGHBOUR * codes[y - one, x] if own[y - one, x] == sc else 0.0))
                       + (_C_NEIGHBOUR * codes[y + one, x] if own[y + one, x] == sc else 0.0)) \
                    + (_C_NEIGHBOUR * codes[y, x - one] if own[y, x - one] == sc else 0.0)
                num = num + (_C_NEIGHBOUR * codes[y, x + one] if own[y, x + one] == sc else 0.0)
                den = (((0.0 + (_C_SELF if own[y, x] == sc else 0.0))
                        + (_C_NEIGHBOUR if own[y - one, x] == sc else 0.0))
                       + (_C_NEIGHBOUR if own[y + one, x] == sc else 0.0)) \
                    + (_C_NEIGHBOUR if own[y, x - one] == sc else 0.0)
                den = den + (_C_NEIGHBOUR if own[y, x + one] == sc else 0.0)
                qv[y, x] = num / (den if den > 0 else 1.0)  # read only where stamped
                qm[y, x] = sc if den > 0 else qm[y, x]
            if sb == w - 1 and ((sb - first) & one) == 0:
                _gather_own_at(codes, own, sc, qv, qm, y, sb, uy0, uy1, ux0, ux1)
        # push, step 2: the even lattice gathers its diagonal neighbours into the coarse level,
        # empty away from the region
        ch, cw = (bh + 1) // 2, (bw + 1) // 2
        cv = cv_pool[:ch * cw].reshape((ch, cw))
        cm = cm_pool[:ch * cw].reshape((ch, cw))
        for i in range(np.uint64(ch * cw)):   # one flat loop over the pools' front (a memset)
            cv_pool[i] = 0.0
            cm_pool[i] = 0
        for y in range(uy0, uy1 + one, two):
            sa, sb = np.uint64(span_a[y]), np.uint64(span_b[y])
            first = sa + ((sa - ux0) & one)
            if y == 0 or y == h - 1 or w < 3:
                for x in range(first, sb + one, two):
                    _gather_own_diagonal_at(qv, qm, sc, cv, cm, y, x, uy0, uy1, ux0, ux1)
                continue
            lo = first
            if first == 0:
                _gather_own_diagonal_at(qv, qm, sc, cv, cm, y, first, uy0, uy1, ux0, ux1)
                lo = two
            hi = sb if sb < w - 1 else np.uint64(w - 2)
            ci = (y - uy0) >> one
            for x in range(lo, hi + one, two):
                num = (((0.0 + (_C_SELF * qv[y, x] if qm[y, x] == sc else 0.0))
                        + (_C_NEIGHBOUR * qv[y - one, x - one] if qm[y - one, x - one] == sc else 0.0))
                       + (_C_NEIGHBOUR * qv[y - one, x + one] if qm[y - one, x + one] == sc else 0.0)) \
                    + (_C_NEIGHBOUR * qv[y + one, x - one] if qm[y + one, x - one] == sc else 0.0)
                num = num + (_C_NEIGHBOUR * qv[y + one, x + one] if qm[y + one, x + one] == sc else 0.0)
                den = (((0.0 + (_C_SELF if qm[y, x] == sc else 0.0))
                        + (_C_NEIGHBOUR if qm[y - one, x - one] == sc else 0.0))
                       + (_C_NEIGHBOUR if qm[y - one, x + one] == sc else 0.0)) \
                    + (_C_NEIGHBOUR if qm[y + one, x - one] == sc else 0.0)
                den = den + (_C_NEIGHBOUR if qm[y + one, x + one] == sc else 0.0)
                cj = (x - ux0) >> one
                cv[ci, cj] = num / (den if den > 0 else 1.0)
                cm[ci, cj] = 1 if den > 0 else 0
            if sb == w - 1 and ((sb - first) & one) == 0:
                _gather_own_diagonal_at(qv, qm, sc, cv, cm, y, sb, uy0, uy1, ux0, ux1)
        coarse = _push_pull_pooled(cv, cm, c_it, cm, fpool, upool, sf, su)
        # pull: even pixels from the coarse level, odd-odd ones from their diagonals, the rest from
        # their axial neighbours
        for y in range(uy0, uy1 + one, two):
            sa = np.uint64(span_a[y])
            for x in range(sa + ((sa - ux0) & one), np.uint64(span_b[y]) + one, two):
                if qm[y, x] != sc:
                    qv[y, x] = coarse[(y - uy0) >> one, (x - ux0) >> one]
        for y in range(uy0 + one, uy1 + one, two):
            sa = np.uint64(span_a[y])
            down = y < uy1
            for x in range(sa + ((sa - ux0 + one) & one), np.uint64(span_b[y]) + one, two):
                if qm[y, x] != sc:
                    left, right = x > ux0, x < ux1
                    s = 0.0
                    k = 0
                    if left:
                        s += qv[y - one, x - one]
                        k += 1
                    if right:
                        s += qv[y - one, x + one]
                        k += 1
                    if down and left:
                        s += qv[y + one, x - one]
                        k += 1
                    if down and right:
                        s += qv[y + one, x + one]
                        k += 1
                    qv[y, x] = s / k
        qp = (y0 + x0) & 1  # quincunx pixels (box parity) have (x + y) & 1 == qp
        for y in range(uy0, uy1 + one):
            sa, sb = np.uint64(span_a[y]), np.uint64(span_b[y])
            inner = uy0 < y < uy1
            # the quincunx pixels: their pulled values
            u = ue if qp == 0 else uo
            for x in range(sa + ((sa + y + np.uint64(qp)) & one), sb + one, two):
                u[y, x >> one] = codes[y, x] if own[y, x] == sc else qv[y, x]
            # the others: the mean of their axial (quincunx) neighbours
            u = uo if qp == 0 else ue
            for x in range(sa + ((sa + y + np.uint64(qp) + one) & one), sb + one, two):
                if own[y, x] == sc:
                    u[y, x >> one] = codes[y, x]
                elif inner and ux0 < x < ux1:
                    u[y, x >> one] = (((0.0 + qv[y - one, x]) + qv[y + one, x]) + qv[y, x - one] + qv[y, x + one]) / 4
                else:
                    s = 0.0
                    k = 0
                    if y > uy0:
                        s += qv[y - one, x]
                        k += 1
                    if y < uy1:
                        s += qv[y + one, x]
                        k += 1
                    if x > ux0:
                        s += qv[y, x - one]
                        k += 1
                    if x < ux1:
                        s += qv[y, x + one]
                        k += 1
                    u[y, x >> one] = s / k
        # the finest level's red-black sweeps, on the region's unknown pixels only, in the
        # frame-wide colour-compacted layout (contiguous reads: see _smooth_nb)
        for _ in range(iterations):
            if (y0 + x0) & 1 == 0:  # box colour 0 (updated first) is x + y even
                _half_sweep_runs(ue, uo, ve, runs, r0, r1, 0, y0, y1, x0, x1)
                _half_sweep_runs(uo, ue, vo, runs, r0, r1, 1, y0, y1, x0, x1)
            else:
                _half_sweep_runs(uo, ue, vo, runs, r0, r1, 1, y0, y1, x0, x1)
                _half_sweep_runs(ue, uo, ve, runs, r0, r1, 0, y0, y1, x0, x1)
        # the region's unknown pixels into out, pixel pairs (2 k, 2 k + 1) from the k-th element of
        # both colours in one branch-free pass (x + y even is ue)
        for r in range(r0, r1):
            y, a, b = np.uint64(runs[r, 0]), np.uint64(runs[r, 1]), np.uint64(runs[r, 2])
            even_first = (y & one) == 0
            first = ue if even_first else uo    # holds the even columns of row y
            second = uo if even_first else ue   # the odd ones
            x = a
            if x & one:
                if not valid[y, x]:
                    out[y, x] = second[y, x >> one]
                x += one
            for k in range(x >> one, (b + one) >> one):
                x = k + k
                out[y, x] = out[y, x] if valid[y, x] else first[y, k]
                out[y, x + one] = out[y, x + one] if valid[y, x + one] else second[y, k]
            if (b & one) == 0 and b >= a + (a & one) and not valid[y, b]:
                out[y, b] = first[y, b >> one]
        n_done += n_unknown
    return n_done


@njit(cache=True, nogil=True)
def _mark_skipped(runs, run_start, skipped, valid, missing):
    """missing (h, w) uint8 = 1 at the unknown pixels of the regions marked in ``skipped``."""
    for c in range(1, len(skipped)):
        if skipped[c]:
            for r in range(run_start[c], run_start[c + 1]):
                y = runs[r, 0]
                for x in range(runs[r, 1], runs[r, 2] + 1):
                    if not valid[y, x]:
                        missing[y, x] = 1


def _check(samples: DecodedSamples):
    if not isinstance(samples, DecodedSamples):
        raise TypeError(f"expected DecodedSamples, got {type(samples).__name__}")


def diffuse_plain(samples: DecodedSamples, iterations: int = DEFAULT_ITERATIONS) -> np.ndarray:
    """Dense codes (h, w) float32 by plain push-pull over all samples (no edge awareness)."""
    _check(samples)
    return push_pull_fast(samples.codes, samples.valid, iterations).astype(np.float32)


def _workspace_sizes(h: int, w: int) -> tuple[int, int, int]:
    """(float64, uint8, int32) elements of memory :func:`_diffuse_regions` needs for an (h, w) frame."""
    ch, cw = (h + 1) // 2, (w + 1) // 2
    nf, nu = _pool_sizes(ch, cw)
    ns = 2 * ch * ((cw + 1) // 2)
    wh = (w + 1) // 2
    return nf + ns + ch * cw + h * w + 2 * h * wh, nu + ns + ch * cw + 2 * h * wh, 7 * h * wh


class DiffusionWorkspace:
    """Memory the edge-aware diffusion reuses from frame to frame: keep one per depth stream (per
    thread: it is not shared safely). Without it every frame faults ~50 MB of fresh pages in at
    1024^2; :func:`diffuse` makes a temporary one when given none."""

    def __init__(self):
        self.release()

    def stamps(self, height: int, width: int, n_regions: int) -> tuple[np.ndarray, int]:
        """(flat int32 array of 2 height width elements, base): :func:`_diffuse_regions`' stamps,
        none above base, for a frame with ``n_regions`` regions to add to their numbers. Kept
        from frame to frame (base advances past this frame's), so never cleared but on wrapping."""
        if len(self._stamps) < 2 * height * width or self._next_stamp + n_regions >= 2 ** 31 - 1:
            self._stamps = np.zeros(max(2 * height * width, len(self._stamps)), dtype=np.int32)
            self._next_stamp = 0
        base = self._next_stamp
        self._next_stamp += n_regions
        return self._stamps, base

    def arrays(self, height: int, width: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(float64, uint8, int32) flat arrays large enough for a (height, width) frame (grown when needed)."""
        nf, nu, ni = _workspace_sizes(height, width)
        if len(self._f) < nf:
            self._f = np.empty(nf)
        if len(self._u) < nu:
            self._u = np.empty(nu, dtype=np.uint8)
        if len(self._i) < ni:
            self._i = np.empty(ni, dtype=np.int32)
        return self._f, self._u, self._i

    def release(self) -> None:
        self._f = np.empty(0)
        self._u = np.empty(0, dtype=np.uint8)
        self._i = np.empty(0, dtype=np.int32)
        self._stamps = np.empty(0, dtype=np.int32)
        self._next_stamp = 0


def diffuse(samples: DecodedSamples, max_work: float = 16.0, iterations: int = DEFAULT_ITERATIONS,
            workspace: DiffusionWorkspace | None = None) -> np.ndarray:
    """Dense codes (h, w) float32 by edge-aware push-pull (module docstring); samples keep their codes.

    workspace : memory to reuse (see :class:`DiffusionWorkspace`); the result is the same without.
    """
    _check(samples)
    # the kernels read the codes and masks as they are (no float64 / uint8 copies of the frame)
    codes = np.ascontiguousarray(samples.codes)
    valid = np.ascontiguousarray(samples.valid, dtype=bool).view(np.uint8)
    edges = np.ascontiguousarray(samples.edges, dtype=bool).view(np.uint8)
    h, w = edges.shape
    workspace = workspace or DiffusionWorkspace()
    fws, uws, iws = workspace.arrays(h, w)
    max_runs = h * ((w + 1) // 2)  # runs are separated by edge pixels
    runs = iws[:6 * max_runs].reshape((2 * max_runs, 3))
    n, boxes, _, run_start = _label_runs(edges, runs, iws[6 * max_runs:7 * max_runs])
    out = np.empty(edges.shape, dtype=np.float32)
    skipped = np.zeros(n + 1, dtype=np.uint8)
    n_done = _diffuse_regions(codes, valid, edges, n, boxes, runs, run_start, float(max_work), int(iterations), out,
                              skipped, fws, uws, *workspace.stamps(h, w, n))
    if n_done < out.size:  # regions without samples or over the work budget, or edge pixels without a sample
        missing = samples.edges & ~samples.valid
        _mark_skipped(runs, run_start, skipped, valid, missing.view(np.uint8))
        out[missing] = push_pull_fast(samples.codes, samples.valid, iterations)[missing]
    return out


def codes_to_distance(dense, quantizer: DepthQuantizer) -> np.ndarray:
    """Dense (fractional) codes (h, w) -> radial distance (h, w) float32; 0 where the sky code dominates."""
    r = DEQUANTIZE.numpy(code=np.asarray(dense, dtype=np.float64), near=quantizer.near, far=quantizer.far,
                         min_code=float(quantizer.min_code), max_code=float(quantizer.max_code))
    return r.astype(np.float32)


def reconstruct_depth(samples: DecodedSamples, quantizer: DepthQuantizer, edge_aware: bool = True,
                      workspace: DiffusionWorkspace | None = None) -> np.ndarray:
    """Decoded samples -> dense radial distance (h, w) float32 (0 = sky). workspace: see :func:`diffuse`."""
    dense = diffuse(samples, workspace=workspace) if edge_aware else diffuse_plain(samples)
    return codes_to_distance(dense, quantizer)
