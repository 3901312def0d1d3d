"""Reference diffusion for the tests of ``client/diffusion.py``.

* The edge-aware diffusion as it was before its finest level was restricted to the regions (main
  at c715502, ``client/diffusion.py``): every region push-pulled over its whole bounding box.
  Kept verbatim (numba kernels included, so a later change to the shared push-pull cannot move
  both sides at once) for tests that require the current diffusion to equal it bit for bit.
* The vectorised numpy push-pull (:func:`push_pull_numpy`, moved here from
  ``client/diffusion.py``, where nothing used it): the definition ``push_pull_fast`` equals to
  rounding.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from pibr.client.diffusion import DEFAULT_ITERATIONS, _label_regions, push_pull_fast

_C_SELF, _C_NEIGHBOUR = 0.5, 0.125
_MAX_ITERATIONS = 64
_AXIAL = ((-1, 0), (1, 0), (0, -1), (0, 1))
_DIAGONAL = ((-1, -1), (-1, 1), (1, -1), (1, 1))


@njit(nogil=True)
def _smooth_simple(u, m, iterations):
    """numba twin of :func:`_smooth_np` (in place), straight from its definition."""
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


@njit(nogil=True)
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
        for k in range(k_first, k_last + 1):
            v = 0.25 * (o[y - 1, k] + o[y + 1, k] + o[y, k - 1 + p] + o[y, k + p])
            t[y, k] = t[y, k] if f[y, k] else v
        if p == 0 and not f[y, 0]:  # x = 0: the 1-D equation along the border column
            t[y, 0] = 0.5 * (o[y - 1, 0] + o[y + 1, 0])
        if ((w - 1 - p) & 1) == 0:  # x = w - 1 has this colour
            k = (w - 1 - p) // 2
            if not f[y, k]:
                t[y, k] = 0.5 * (o[y - 1, k] + o[y + 1, k])


@njit(nogil=True)
def _smooth_nb(u, m, iterations, sf=None, su=None):
    """numba twin of :func:`_smooth_np` (in place).

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
    for y in range(h):
        pr = y & 1
        for k in range((w - pr + 1) >> 1):
            red[y, k] = u[y, 2 * k + pr]
            fred[y, k] = 1 if m[y, 2 * k + pr] else 0
        for k in range((w - 1 + pr + 1) >> 1):
            black[y, k] = u[y, 2 * k + 1 - pr]
            fblack[y, k] = 1 if m[y, 2 * k + 1 - pr] else 0
    for _ in range(iterations):
        _half_sweep(red, black, fred, h, w, 0)
        _half_sweep(black, red, fblack, h, w, 1)
    for y in range(h):
        pr = y & 1
        for k in range((w - pr + 1) >> 1):
            u[y, 2 * k + pr] = red[y, k]
        for k in range((w - 1 + pr + 1) >> 1):
            u[y, 2 * k + 1 - pr] = black[y, k]


@njit(nogil=True)
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


@njit(nogil=True)
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
        for y in range(h):
            for x in range(w):
                if mm[y, x]:
                    n_valid += 1
        if n_valid == hw or (h == 1 and w == 1):  # the coarsest level
            for y in range(h):
                for x in range(w):
                    out[y, x] = vv[y, x] if mm[y, x] else 0.0
            break
        qv = fpool[fo + hw:fo + 2 * hw].reshape((h, w))
        qm = upool[uo:uo + hw].reshape((h, w))
        for y in range(h):
            for x in range((y & 1), w, 2):
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
        cv = fpool[fo + 2 * hw:fo + 2 * hw + ch * cw].reshape((ch, cw))
        cm = upool[uo + hw:uo + hw + ch * cw].reshape((ch, cw))
        for i in range(ch):
            for j in range(cw):
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
        for y in range(0, h, 2):
            for x in range(0, w, 2):
                if not qm[y, x]:
                    q[y, x] = coarse[y // 2, x // 2]
        for y in range(1, h, 2):
            for x in range(1, w, 2):
                if not qm[y, x]:
                    s = 0.0
                    n = 0
                    for dy in (-1, 1):
                        for dx in (-1, 1):
                            yy, xx = y + dy, x + dx
                            if 0 <= yy < h and 0 <= xx < w:
                                s += q[yy, xx]
                                n += 1
                    q[y, x] = s / n
        for y in range(h):
            border_row = y == 0 or y == h - 1
            for x in range(w):
                if mm[y, x]:
                    out[y, x] = vv[y, x]
                elif (y + x) % 2 == 0:
                    out[y, x] = q[y, x]
                elif not border_row and 0 < x < w - 1:  # the same sums as below, without the bounds tests
                    out[y, x] = (((0.0 + q[y - 1, x]) + q[y + 1, x]) + q[y, x - 1] + q[y, x + 1]) / 4
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
        _smooth_nb(out, fx, lit[l], sf, su)
    return fpool[:v.shape[0] * v.shape[1]].reshape(v.shape)


@njit(nogil=True)
def _diffuse_regions(codes, valid, edges, labels, n, boxes, max_work, iterations, out, done, fws, uws):
    """Push-pull every region from its own samples into ``out`` (h, w) (which also gets the samples),
    marking the pixels set in ``done``; regions without samples or beyond the work budget are left
    alone. Returns how many pixels are set (samples included). fws (float64) / uws (uint8): flat
    memory of at least :func:`_workspace_sizes` (h, w) elements, reused by every region."""
    h, w = codes.shape
    budget = max_work * h * w
    used = 0
    n_done = 0
    for y in range(h):
        for x in range(w):
            out[y, x] = codes[y, x]
            if valid[y, x]:
                n_done += 1
    # memory reused by every region (see _push_pull_pooled), sized for the whole image, which
    # covers any box's pyramid (each level fits inside the image's)
    nf, nu = _pool_sizes(h, w)
    ns = 2 * h * ((w + 1) // 2)
    fpool = fws[:nf]
    sf = fws[nf:nf + ns]
    lv_pool = fws[nf + ns:nf + ns + h * w]
    upool = uws[:nu]
    su = uws[nu:nu + ns]
    lm_pool = uws[nu + ns:nu + ns + h * w]
    lf_pool = uws[nu + ns + h * w:nu + ns + 2 * h * w]
    for c in range(1, n + 1):
        # one pixel of margin: the region's boundary edge samples
        y0, y1 = max(boxes[c, 0] - 1, 0), min(boxes[c, 1] + 1, h - 1)
        x0, x1 = max(boxes[c, 2] - 1, 0), min(boxes[c, 3] + 1, w - 1)
        bh, bw = y1 - y0 + 1, x1 - x0 + 1
        if used + bh * bw > budget:
            continue
        used += bh * bw
        lv = lv_pool[:bh * bw].reshape((bh, bw))
        lm = lm_pool[:bh * bw].reshape((bh, bw))
        # The finest level's sweeps need only the region's own pixels: they read nothing but
        # their 4-neighbours, which are the region's pixels or its samples, so the rest of the
        # box is held fixed there (the same result for the region, ~half the sweeps' work).
        lf = lf_pool[:bh * bw].reshape((bh, bw))
        n_samples = 0
        n_unknown = 0
        for y in range(y0, y1 + 1):
            for x in range(x0, x1 + 1):
                own = False
                lf[y - y0, x - x0] = 1
                if labels[y, x] == c:
                    if valid[y, x]:
                        own = True
                    else:
                        n_unknown += 1
                        lf[y - y0, x - x0] = 0
                elif edges[y, x] and valid[y, x]:
                    if (y > 0 and labels[y - 1, x] == c) or (y + 1 < h and labels[y + 1, x] == c) or \
                            (x > 0 and labels[y, x - 1] == c) or (x + 1 < w and labels[y, x + 1] == c):
                        own = True
                if own:
                    lv[y - y0, x - x0] = codes[y, x]
                    lm[y - y0, x - x0] = 1
                    n_samples += 1
                else:
                    lv[y - y0, x - x0] = 0.0
                    lm[y - y0, x - x0] = 0
        if n_samples == 0 or n_unknown == 0:
            continue
        filled = _push_pull_pooled(lv, lm, iterations, lf, fpool, upool, sf, su)
        for y in range(y0, y1 + 1):
            for x in range(x0, x1 + 1):
                if labels[y, x] == c and not valid[y, x]:
                    out[y, x] = filled[y - y0, x - x0]
                    done[y, x] = 1
                    n_done += 1
    return n_done


def reference_diffuse(samples, max_work: float = 16.0, iterations: int = 4) -> np.ndarray:
    """Dense codes (h, w) float32, each region push-pulled over its bounding box (the old ``diffuse``)."""
    codes = np.ascontiguousarray(samples.codes)
    valid = np.ascontiguousarray(samples.valid, dtype=bool).view(np.uint8)
    edges = np.ascontiguousarray(samples.edges, dtype=bool).view(np.uint8)
    h, w = edges.shape
    labels = np.zeros(edges.shape, dtype=np.int32)
    n, boxes, _ = _label_regions(edges, labels)
    out = np.empty(edges.shape, dtype=np.float32)
    done = np.zeros(edges.shape, dtype=np.uint8)
    nf, nu = _pool_sizes(h, w)
    ns = 2 * h * ((w + 1) // 2)
    fws, uws = np.empty(nf + ns + h * w), np.empty(nu + ns + 2 * h * w, dtype=np.uint8)
    n_done = _diffuse_regions(codes, valid, edges, labels, n, boxes, float(max_work), int(iterations), out, done,
                              fws, uws)
    if n_done < out.size:
        missing = ~(done.view(bool) | samples.valid)
        out[missing] = push_pull_fast(samples.codes, samples.valid, iterations)[missing]
    return out


def reference_push_pull(values, valid, iterations: int = 4) -> np.ndarray:
    """The old ``push_pull_fast``: (h, w) float64 values, (h, w) bool valid -> filled (h, w) float64."""
    v = np.ascontiguousarray(values, dtype=np.float64)
    m = np.ascontiguousarray(valid, dtype=np.uint8)
    if not m.any():
        return np.zeros_like(v)
    h, w = v.shape
    nf, nu = _pool_sizes(h, w)
    wh = (w + 1) // 2
    return _push_pull_pooled(v, m, int(iterations), m, np.empty(nf), np.empty(nu, dtype=np.uint8),
                             np.empty(2 * h * wh), np.empty(2 * h * wh, dtype=np.uint8)).copy()


# ------------------------------------------------------------------------------------------
# numpy push-pull: the definition the numba push_pull_fast is held to (to rounding), as it
# was in client/diffusion.py
# ------------------------------------------------------------------------------------------

def _shift(a: np.ndarray, dy: int, dx: int) -> np.ndarray:
    """b[y, x] = a[y + dy, x + dx], 0 outside."""
    h, w = a.shape
    b = np.zeros_like(a)
    b[max(0, -dy):min(h, h - dy), max(0, -dx):min(w, w - dx)] = a[max(0, dy):min(h, h + dy), max(0, dx):min(w, w + dx)]
    return b


def _gather(wv: np.ndarray, wm: np.ndarray, offsets) -> tuple[np.ndarray, np.ndarray]:
    """Weighted sums (values, weights) of self (1/2) and the neighbours at ``offsets`` (1/8 each)."""
    num = _C_SELF * wv
    den = _C_SELF * wm
    for dy, dx in offsets:
        num = num + _C_NEIGHBOUR * _shift(wv, dy, dx)
        den = den + _C_NEIGHBOUR * _shift(wm, dy, dx)
    return num, den


def _mean_inside(a: np.ndarray, offsets) -> np.ndarray:
    """Mean of a over the neighbours at ``offsets`` that are inside the image."""
    ones = np.ones_like(a)
    total = sum(_shift(a, dy, dx) for dy, dx in offsets)
    count = sum(_shift(ones, dy, dx) for dy, dx in offsets)
    return total / np.maximum(count, 1.0)


def _smooth_np(u, fixed, iterations):
    """Red-black Gauss-Seidel sweeps of the Laplace equation on the pixels that are not ``fixed``.

    On the image border the missing neighbour is extrapolated linearly (zero second
    derivative, exact for planes), which reduces to a 1-D Laplace equation along the border;
    corners stay as they are.
    """
    h, w = u.shape
    yy, xx = np.indices((h, w))
    row_border = (yy == 0) | (yy == h - 1)
    col_border = (xx == 0) | (xx == w - 1)
    horizontal = row_border & ~col_border & (w > 1)
    vertical = col_border & ~row_border & (h > 1)
    interior = ~row_border & ~col_border
    for _ in range(iterations):
        for colour in (0, 1):
            sel = ((yy + xx) % 2 == colour) & ~fixed
            u = np.where(sel & interior, _mean_inside(u, _AXIAL), u)
            u = np.where(sel & horizontal, 0.5 * (_shift(u, 0, -1) + _shift(u, 0, 1)), u)
            u = np.where(sel & vertical, 0.5 * (_shift(u, -1, 0) + _shift(u, 1, 0)), u)
    return u


def push_pull_numpy(values, valid, iterations: int = DEFAULT_ITERATIONS) -> np.ndarray:
    """Fill the pixels where ``valid`` is False: values (h, w) float, valid (h, w) bool -> (h, w) float64.

    Samples keep their values; with no sample at all the result is 0. ``iterations`` red-black
    Gauss-Seidel sweeps follow the pull at the finest level, twice as many at each coarser one.
    """
    v = np.asarray(values, dtype=np.float64)
    m = np.asarray(valid, dtype=bool)
    if v.shape != m.shape or v.ndim != 2:
        raise ValueError(f"values and valid must be (h, w) arrays of one shape, got {v.shape} and {m.shape}")
    if not m.any():
        return np.zeros_like(v)
    return _push_pull_np(v, m, int(iterations))


def _push_pull_np(v, m, iterations):
    h, w = v.shape
    if m.all() or (h == 1 and w == 1):
        return np.where(m, v, 0.0)
    yy, xx = np.indices((h, w))
    quincunx = (yy + xx) % 2 == 0
    even = (yy % 2 == 0) & (xx % 2 == 0)
    # push, step 1: the quincunx lattice gathers its axial neighbours
    num, den = _gather(np.where(m, v, 0.0), m.astype(np.float64), _AXIAL)
    qm = quincunx & (den > 0)
    qv = np.where(qm, num / np.where(den > 0, den, 1.0), 0.0)
    # push, step 2: the even lattice gathers its diagonal neighbours (all on the quincunx lattice)
    num, den = _gather(qv, qm.astype(np.float64), _DIAGONAL)
    cm = (den > 0)[::2, ::2]
    cv = np.where(cm, num[::2, ::2] / np.where(cm, den[::2, ::2], 1.0), 0.0)
    coarse = _push_pull_np(cv, cm, min(2 * iterations, _MAX_ITERATIONS))
    # pull: even pixels from the coarse level, odd-odd ones from their diagonals, the rest from axial neighbours
    q = np.zeros((h, w))
    q[::2, ::2] = coarse
    q = np.where(qm, qv, q)
    q = np.where(quincunx & ~even & ~qm, _mean_inside(np.where(even, q, 0.0), _DIAGONAL), q)
    full = np.where(quincunx, q, _mean_inside(np.where(quincunx, q, 0.0), _AXIAL))
    return _smooth_np(np.where(m, v, full), m, iterations)
