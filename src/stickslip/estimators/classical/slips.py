"""Slip detection and stick-segment fits on one force trace (numba kernels).

A slip is a drop of the force that is fast compared with the stick phase. It is found
on the windowed difference ``D_w(i) = mean(F[i+1..i+w]) - mean(F[i-w+1..i])`` of the
despiked trace, at the smallest window ``w`` (1, 2, 4, ...) whose detected drops are
comparable with the force range: ``w = 1`` for simulated or AFM pixels (a slip lies
within one pixel), larger for finely sampled recordings whose slips last many samples.
A drop counts when it is below ``-max(5 sigma_w, 3 median|D_w|)``: the noise of
``D_w`` (``sigma_w = sigma sqrt(2/w)``, ``sigma`` from second differences) and three
times the typical stick rise, so smooth sliding, whose descent is as slow as its rise,
has no slips. Nothing assumes that slips are one lattice spacing apart.

Between slips lie stick segments. Each gets a robust quadratic fit (one pass of
outlier rejection at 4 sigma) and a robust straight-line fit of its rising part. The
slip position inside its pixel follows from pixel averaging: the force integral over
the pixels between two segments must equal that of the pre-slip branch up to the slip
and the post-slip branch after it. That gives the force just before (``F_slip``) and
after (``F_after``) each slip free of the pixel-averaging bias.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

MIN_FIT_SAMPLES = 3  # straight line
MIN_QUAD_SAMPLES = 8  # quadratic (end values and peak)
NOISE_SIGMAS = 5.0  # detection threshold on D_w in units of its noise
RISE_FACTOR = 1.5  # ... and in units of the median |D_w| (typical stick rise)
UP_FACTOR = 1.0  # ... and in units of the largest rises' excess over the typical one
SIGNAL_NOISE = 5.0 / 3.0  # typical variation over noise at which sticks dominate a scale
STAT_SAMPLES = 16384  # values per scale that the noise and rise statistics read
OUTLIER_SIGMAS = 4.0
SPIKE_FACTOR = 2.0  # a spike stands out of its neighbours by this times their difference
LOWER_FRACTION = 0.5  # stick slope fitted up to this fraction of the stick's rise
MIN_LOWER_SAMPLES = 4  # ... but on at least this many samples
BEND_FRACTION = 0.15
TAIL_BOUND = 1.5  # largest response time, in units of the time a slip takes to end
TAU_MIN = 0.25
SMOOTH_TAU = 3.0  # response time (samples) from which the restored trace is smoothed

# columns of the per-segment table returned by `analyse_segments`
SEG_START, SEG_END, SEG_SLOPE, SEG_F_LO, SEG_F_HI, SEG_NFIT = 0, 1, 2, 3, 4, 5
SEG_C0, SEG_C1, SEG_C2, SEG_XREF, SEG_PEAK = 6, 7, 8, 9, 10
N_SEG_COLS = 11
# columns of the per-slip table
SLIP_X, SLIP_F, SLIP_F_AFTER, SLIP_PEAK, SLIP_CENTRE = 0, 1, 2, 3, 4
N_SLIP_COLS = 5


@njit(cache=True, error_model="numpy")
def _mad_sigma(v: np.ndarray) -> float:
    if v.size == 0:
        return 0.0
    med = np.median(v)
    s = 1.4826 * np.median(np.abs(v - med))
    if s == 0.0:  # digitised signals: more than half the values equal
        s = 1.2533 * np.mean(np.abs(v - med))
    return s


@njit(cache=True, error_model="numpy")
def noise_sigma(F: np.ndarray) -> float:
    """White-noise standard deviation per sample from second differences (robust)."""
    if F.size < 3:
        return 0.0
    d2 = F[2:] - 2.0 * F[1:-1] + F[:-2]
    return _mad_sigma(d2) / np.sqrt(6.0)


@njit(cache=True, error_model="numpy")
def _despike(F: np.ndarray) -> np.ndarray:
    """Replace isolated one-sample spikes (whose return looks like a slip) by the mean
    of their neighbours.

    A spike leaves its two neighbours close to each other: the sample must stand out on
    the same side of both by more than ``SPIKE_FACTOR`` times their difference. The peak
    sample of a coarse sawtooth, whose neighbours differ by a whole drop, is kept.
    """
    G = F.copy()
    for i in range(1, F.size - 1):
        a, b, c = F[i - 1], F[i], F[i + 1]
        lo = min(b - a, b - c)
        hi = max(b - a, b - c)
        gap = SPIKE_FACTOR * abs(c - a)
        if lo > gap or hi < -gap:
            G[i] = 0.5 * (a + c)
    return G


@njit(cache=True, error_model="numpy")
def _cumsum0(G: np.ndarray) -> np.ndarray:
    """``C[i] = sum(G[:i])`` (length ``n + 1``): any window mean in O(1)."""
    C = np.zeros(G.size + 1)
    for i in range(G.size):
        C[i + 1] = C[i] + G[i]
    return C


@njit(cache=True, error_model="numpy")
def _dw(C: np.ndarray, i: int, w: int) -> float:
    """``D_w(i) = mean(G[i+1..i+w]) - mean(G[i-w+1..i])`` from the cumulative sum."""
    return ((C[i + w + 1] - C[i + 1]) - (C[i + 1] - C[i - w + 1])) / w


@njit(cache=True, error_model="numpy")
def _window_diff(C: np.ndarray, w: int) -> np.ndarray:
    """``D_w`` at every sample; NaN where a window would leave the trace."""
    n = C.size - 1
    D = np.full(n, np.nan)
    for i in range(w - 1, n - w):
        D[i] = _dw(C, i, w)
    return D


@njit(cache=True, error_model="numpy")
def _low_sigma(v: np.ndarray) -> float:
    """Standard deviation of the bulk of ``v`` from its lower quartile of ``|v|``.

    Slips and sharp corners make up to half of a coarse trace's differences large; the
    smallest quarter stays noise. Digitised signals, whose quartile can be 0, fall back
    on the median and then the mean of ``|v|``.
    """
    a = np.abs(v)
    q = np.percentile(a, 25.0)
    if q > 0:
        return q / 0.31864
    q = np.median(a)
    if q > 0:
        return q / 0.67449
    return np.mean(a) / 0.79788


@njit(cache=True, error_model="numpy")
def _scale_stats(C: np.ndarray, w: int) -> tuple[float, float, float]:
    """Typical variation, noise and largest rises of the trace at scale ``w`` (samples).

    ``mag`` is ``median |D_w|``: on a stick-slip trace the stick rise over ``w`` samples
    (sticks fill most of a trace). ``noise`` is the standard deviation of ``D_w`` that
    noise alone gives, measured from the trace's own second differences of ``w``-sample
    means (``D_w(i + w) - D_w(i)``: blind to the stick's linear rise, so it holds white,
    1/f, filtered or digitised noise as it is at that scale). ``up`` is how far the
    largest rises (99.5th percentile of ``D_w``) stand above the typical one: a drop no
    deeper than that is no slip (heavy-tailed noise, spikes, ringing). All three come
    from a stride of at least ``w/4`` samples and at most ~16k values: O(n/w) work.
    """
    n = C.size - 1
    stride = max(max(1, w // 4), (n - 3 * w) // STAT_SAMPLES + 1)
    m = (n - 3 * w) // stride + 1
    if m < 8:
        return np.nan, np.nan, np.nan
    d = np.empty(m)
    e = np.empty(m)
    for j in range(m):
        i = w - 1 + j * stride
        d[j] = _dw(C, i, w)
        e[j] = _dw(C, i + w, w) - d[j]
    med = np.median(d)
    up = np.percentile(d, 99.5) - med
    # second differences of block means: variance 6 s_b^2; D_w has variance 2 s_b^2
    return np.median(np.abs(d)), _low_sigma(e) / np.sqrt(3.0), up


@njit(cache=True, error_model="numpy")
def _threshold(mag: float, noise: float, up: float) -> float:
    """Depth a drop needs at one scale: above noise, above the typical stick rise and
    deeper than the largest rises go."""
    return max(NOISE_SIGMAS * noise, RISE_FACTOR * mag, UP_FACTOR * up)


@njit(cache=True, error_model="numpy")
def _events(C: np.ndarray, w: int, lo: int, hi: int, thr: float,
            out: np.ndarray) -> int:  # fmt: skip
    """Runs of ``D_w < -thr/2`` within ``[lo, hi]`` that reach ``-thr``.

    Rows of ``out``: (first, last, argmin, depth).
    """
    lo = max(lo, w - 1)
    hi = min(hi, C.size - 2 - w)
    k = 0
    i = lo
    while i <= hi:
        di = _dw(C, i, w)
        if not (di < -0.5 * thr):
            i += 1
            continue
        j = i
        imin = i
        dmin = di
        while j + 1 <= hi:
            dj = _dw(C, j + 1, w)
            if not (dj < -0.5 * thr):
                break
            j += 1
            if dj < dmin:
                imin = j
                dmin = dj
        # the drop across the whole run (a slip split between two pixels, or smeared)
        if j + 1 + w <= C.size - 1 and i - w + 1 >= 0:
            whole = ((C[j + 1 + w] - C[j + 1]) - (C[i + 1] - C[i - w + 1])) / w
            dmin = min(dmin, whole)
        if dmin < -thr and k < out.shape[0]:
            out[k, 0] = i
            out[k, 1] = j
            out[k, 2] = imin
            out[k, 3] = -dmin
            k += 1
        i = j + 1
    return k


@njit(cache=True, error_model="numpy")
def _force_range(x: np.ndarray, F: np.ndarray) -> float:
    # 5-95 % range of the linearly detrended force: the size of a typical drop
    n = F.size
    xm = np.mean(x)
    Fm = np.mean(F)
    sxx = np.sum((x - xm) ** 2)
    b = np.sum((x - xm) * (F - Fm)) / sxx if sxx > 0 else 0.0
    r = F - b * (x - xm)
    return np.percentile(r, 95.0) - np.percentile(r, 5.0) if n > 1 else 0.0


@njit(cache=True, error_model="numpy")
def _scales(n: int) -> np.ndarray:
    """Detection scales 1, 2, 3, 4, 6, 8, 11, 16, ... (about sqrt 2 apart) up to n/12."""
    out = np.empty(64, dtype=np.int64)
    k = 0
    w = 1.0
    last = 0
    while k < 64:
        wi = int(np.rint(w))
        if wi > max(1, n // 12):
            break
        if wi != last:
            out[k] = wi
            k += 1
            last = wi
        w *= np.sqrt(2.0)
    return out[:k]


@njit(cache=True, error_model="numpy")
def _stable(a: int, b: int, c: int) -> bool:
    """Three event counts at successive scales that agree (at least MIN_SLIPS)."""
    if min(a, min(b, c)) < 3:
        return False
    tol = max(1, int(0.05 * a + 0.5))
    return abs(a - b) <= tol and abs(a - c) <= tol


@njit(cache=True, error_model="numpy")
def _merge_events(ev: np.ndarray, k: int, gap: int) -> int:
    """Merge events less than ``gap`` samples apart in place (noise splitting one slow
    drop); the merged event keeps the deeper minimum. Returns the new count."""
    if k == 0:
        return 0
    m = 0
    for i in range(1, k):
        if ev[i, 0] - ev[m, 1] <= gap:
            ev[m, 1] = ev[i, 1]
            if ev[i, 3] > ev[m, 3]:
                ev[m, 2] = ev[i, 2]
                ev[m, 3] = ev[i, 3]
        else:
            m += 1
            ev[m, :] = ev[i, :]
    return m + 1


@njit(cache=True, error_model="numpy")
def _events_min(C: np.ndarray, w: int, lo: int, hi: int, thr: float,
                out: np.ndarray) -> int:  # fmt: skip
    """The deepest event of ``D_w`` within ``[lo, hi]`` into ``out[0]`` (0 if none)."""
    buf = np.empty(((hi - lo) // max(w, 1) + 2, 4))
    k = _events(C, w, lo, hi, thr, buf)
    if k == 0:
        return 0
    b = 0
    for i in range(1, k):
        if buf[i, 3] > buf[b, 3]:
            b = i
    out[0, :] = buf[b, :]
    return 1


@njit(cache=True, error_model="numpy")
def detect_slips(x: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, int, float, float]:
    """Find slip events at the trace's own scale (see the module docstring).

    Returns
    -------
    events : ndarray (n_events, 6)
        Rows ``(first, last, centre, depth, scale, tail)``: first/last index of the run
        of ``D_w`` below threshold at the finest scale ``w`` (samples) where the slip
        still stands out, its argmin (slip between samples ``centre`` and
        ``centre+1``), the drop there, ``w``, and how long (samples) the drop lasts past
        its steepest point at the detection scale.
    w : int
        Detection scale (samples), 0 if no scale has a signal above its noise.
    sigma : float
        White noise per sample (second differences).
    snr : float
        Largest ratio over scales of the typical variation to its noise.
    """
    n = F.size
    sigma = noise_sigma(F)
    if n < 12:
        return np.empty((0, 6)), 0, sigma, 0.0
    C = _cumsum0(_despike(F))
    ws = _scales(n)
    ns = ws.size
    mag = np.full(ns, np.nan)
    noise = np.full(ns, np.nan)
    up = np.full(ns, np.nan)
    count = np.zeros(ns, dtype=np.int64)
    buf = np.empty((n // 2 + 2, 4))
    snr = 0.0
    cross = -1
    jbest = -1
    for j in range(ns):
        mag[j], noise[j], up[j] = _scale_stats(C, ws[j])
        if np.isnan(mag[j]):
            break
        if j > 0:  # near the slip spacing the statistic measures the sticks, not noise
            noise[j] = min(noise[j], noise[j - 1])
        r = mag[j] / noise[j] if noise[j] > 0 else np.inf
        snr = max(snr, r)
        # the first scale at which the stick's variation, not noise, dominates
        if cross < 0 and mag[j] >= SIGNAL_NOISE * noise[j]:
            cross = j
        thr = _threshold(mag[j], noise[j], up[j])
        count[j] = _merge_events(buf, _events(C, ws[j], 0, n, thr, buf), 2 * ws[j])
        # slips persist over scales, noise events do not: the finest scale from which
        # on the count holds over the next two
        if j >= 2 and _stable(count[j - 2], count[j - 1], count[j]):
            jbest = j - 2
            break
    if jbest < 0:
        if cross < 0:
            return np.empty((0, 6)), 0, sigma, snr
        # no plateau (few slips, or slips only a few samples apart): the scale, up to
        # the one where the sticks dominate the noise, that separates the most slips
        jbest = cross
        for j in range(cross + 1):
            if count[j] > count[jbest]:
                jbest = j
    best = jbest
    w = ws[best]
    k = _merge_events(buf, _events(C, w, 0, n, _threshold(mag[best], noise[best], up[best]),
                                   buf), 2 * w)  # fmt: skip
    ev = np.empty((k, 6))
    ev[:, :4] = buf[:k]
    ev[:, 4] = w
    for e in range(k):  # how long the drop lasts past its steepest point, at this scale
        ev[e, 5] = ev[e, 1] - ev[e, 2] + w
    # refine each slip at finer scales while it still stands out there
    one = np.empty((1, 4))
    for e in range(k):
        for j in range(best - 1, -1, -1):
            wj = ws[j]
            tj = _threshold(mag[j], noise[j], up[j])
            wp = int(ev[e, 1] - ev[e, 0]) // 2 + ws[j + 1]
            c = int(ev[e, 2])
            if _events_min(C, wj, c - wp, c + wp, tj, one) == 0:
                break
            ev[e, :4] = one[0, :]
            ev[e, 4] = wj
    return ev, w, sigma, snr


@njit(cache=True, error_model="numpy")
def _polyfit(x: np.ndarray, F: np.ndarray, lo: int, hi: int, xref: float, deg: int,
             mask: np.ndarray) -> tuple[float, float, float]:  # fmt: skip
    """Least-squares polynomial (degree 1 or 2) on samples lo..hi (inclusive) with mask."""
    s0 = s1 = s2 = s3 = s4 = t0 = t1 = t2 = 0.0
    for i in range(lo, hi + 1):
        if not mask[i - lo]:
            continue
        u = x[i] - xref
        u2 = u * u
        s0 += 1.0
        s1 += u
        s2 += u2
        s3 += u2 * u
        s4 += u2 * u2
        t0 += F[i]
        t1 += u * F[i]
        t2 += u2 * F[i]
    # Cramer's rule on the 3x3 normal equations (no recursion: numba's cache breaks on it)
    det = s0 * (s2 * s4 - s3 * s3) - s1 * (s1 * s4 - s3 * s2) + s2 * (s1 * s3 - s2 * s2)
    if deg == 1 or s0 < MIN_QUAD_SAMPLES or det <= 0:
        det = s0 * s2 - s1 * s1
        if s0 < 2 or det <= 0:
            return (t0 / s0 if s0 > 0 else np.nan), 0.0, 0.0
        return (s2 * t0 - s1 * t1) / det, (s0 * t1 - s1 * t0) / det, 0.0
    c0 = t0 * (s2 * s4 - s3 * s3) - s1 * (t1 * s4 - s3 * t2) + s2 * (t1 * s3 - s2 * t2)
    c1 = s0 * (t1 * s4 - t2 * s3) - t0 * (s1 * s4 - s3 * s2) + s2 * (s1 * t2 - t1 * s2)
    c2 = s0 * (s2 * t2 - s3 * t1) - s1 * (s1 * t2 - s3 * t0) + t0 * (s1 * s3 - s2 * s2)
    return c0 / det, c1 / det, c2 / det


@njit(cache=True, error_model="numpy")
def _robust_fit(x: np.ndarray, F: np.ndarray, lo: int, hi: int, xref: float, deg: int,
                sigma: float, mask: np.ndarray) -> tuple[float, float, float]:  # fmt: skip
    c0, c1, c2 = _polyfit(x, F, lo, hi, xref, deg, mask)
    m = hi - lo + 1
    res = np.empty(m)
    for i in range(lo, hi + 1):
        u = x[i] - xref
        res[i - lo] = F[i] - (c0 + c1 * u + c2 * u * u)
    cut = OUTLIER_SIGMAS * max(sigma, _mad_sigma(res[mask[:m]]))
    if cut <= 0:
        return c0, c1, c2
    mask2 = mask.copy()
    changed = False
    for j in range(m):
        if mask2[j] and abs(res[j]) > cut:
            mask2[j] = False
            changed = True
    if not changed or mask2.sum() < MIN_FIT_SAMPLES:
        return c0, c1, c2
    return _polyfit(x, F, lo, hi, xref, deg, mask2)


@njit(cache=True, error_model="numpy")
def _fit_segment(x: np.ndarray, F: np.ndarray, lo: int, hi: int, sigma: float,
                 row: np.ndarray) -> None:  # fmt: skip
    """Fill one row of the segment table (NaN slope if too short)."""
    row[:] = np.nan
    row[SEG_START] = lo
    row[SEG_END] = hi
    m = hi - lo + 1
    row[SEG_NFIT] = max(m, 0)
    if m < MIN_FIT_SAMPLES:
        return
    xref = 0.5 * (x[lo] + x[hi])
    mask = np.ones(m, dtype=np.bool_)
    c0, c1, c2 = _robust_fit(x, F, lo, hi, xref, 2, sigma, mask)
    row[SEG_C0], row[SEG_C1], row[SEG_C2], row[SEG_XREF] = c0, c1, c2, xref
    # the slope is fitted on the rising part only (up to the quadratic's vertex)
    hi_r = hi
    if c2 < 0:
        xv = xref - c1 / (2.0 * c2)
        while hi_r > lo and x[hi_r] > xv:
            hi_r -= 1
    if hi_r - lo + 1 < MIN_FIT_SAMPLES:
        hi_r = hi
    # ... and on its lower part: the top of a stick softens (creep, precursor slips)
    if c2 < 0 and hi_r - lo + 1 > MIN_LOWER_SAMPLES:
        f_lo = c0 + c1 * (x[lo] - xref) + c2 * (x[lo] - xref) ** 2
        u = x[hi_r] - xref
        cut = f_lo + LOWER_FRACTION * (c0 + c1 * u + c2 * u * u - f_lo)
        hi_l = hi_r
        while hi_l > lo + MIN_LOWER_SAMPLES - 1:
            u = x[hi_l] - xref
            if c0 + c1 * u + c2 * u * u <= cut:
                break
            hi_l -= 1
        hi_r = hi_l
    b0, b1, _ = _robust_fit(x, F, lo, hi_r, xref, 1, sigma, mask[: hi_r - lo + 1].copy())
    row[SEG_SLOPE] = b1
    row[SEG_F_LO] = b0 + b1 * (x[lo] - xref)
    row[SEG_F_HI] = b0 + b1 * (x[hi_r] - xref)


@njit(cache=True, error_model="numpy")
def _poly_at(row: np.ndarray, X: float) -> float:
    u = X - row[SEG_XREF]
    return row[SEG_C0] + row[SEG_C1] * u + row[SEG_C2] * u * u


@njit(cache=True, error_model="numpy")
def _poly_int(row: np.ndarray, A: float, B: float) -> float:
    ua = A - row[SEG_XREF]
    ub = B - row[SEG_XREF]
    return (row[SEG_C0] * (ub - ua) + row[SEG_C1] * (ub * ub - ua * ua) / 2.0
            + row[SEG_C2] * (ub**3 - ua**3) / 3.0)  # fmt: skip


@njit(cache=True, error_model="numpy")
def _locate_slip(x: np.ndarray, F: np.ndarray, pre: np.ndarray, post: np.ndarray,
                 sigma: float, out: np.ndarray) -> None:  # fmt: skip
    """Sub-pixel slip position by matching the force integral between two segments."""
    e = int(pre[SEG_END])
    s = int(post[SEG_START])
    A = 0.5 * (x[e] + x[e + 1])
    B = 0.5 * (x[s - 1] + x[s])
    S = 0.0
    for k in range(e + 1, s):
        left = 0.5 * (x[k - 1] + x[k])
        right = 0.5 * (x[k] + x[k + 1])
        S += F[k] * (right - left)
    target = S - _poly_int(post, A, B)
    lo, hi = A, B
    for _ in range(40):  # bisection: int_A^X (pre - post) is monotone while pre > post
        mid = 0.5 * (lo + hi)
        if _poly_int(pre, A, mid) - _poly_int(post, A, mid) < target:
            lo = mid
        else:
            hi = mid
    Xs = 0.5 * (lo + hi)
    out[SLIP_X] = Xs
    out[SLIP_F] = _poly_at(pre, Xs)
    out[SLIP_F_AFTER] = _poly_at(post, Xs)
    # peak of the pre-slip branch: its value at the slip, or the vertex if it lies before
    # At low T the branch bends over just before the slip (vertical tangent at the
    # T = 0 instability), which no quadratic follows: if the last full pixel before the
    # slip lies clearly below the fit, trust the data there instead of extrapolating.
    x_end = Xs
    g = e + 1
    if g < s and 0.5 * (x[g] + x[g + 1]) <= Xs:
        gl = 0.5 * (x[g - 1] + x[g])
        gr = 0.5 * (x[g] + x[g + 1])
        pred = _poly_int(pre, gl, gr) / (gr - gl)
        rise = pred - _poly_at(pre, x[e])
        if F[g] < pred - max(3.0 * sigma, BEND_FRACTION * rise):
            out[SLIP_F] = max(F[g], _poly_at(pre, x[e]))
            x_end = x[e]
    # peak of the pre-slip branch: its value at the end, or the vertex if it lies before
    peak = out[SLIP_F]
    c2 = pre[SEG_C2]
    if c2 < 0:
        xv = pre[SEG_XREF] - pre[SEG_C1] / (2.0 * c2)
        if x[int(pre[SEG_START])] < xv < x_end:
            peak = max(peak, _poly_at(pre, xv))
    out[SLIP_PEAK] = peak


@njit(cache=True, error_model="numpy")
def _tail_sse(y: np.ndarray, lo: int, hi: int, rho: float, P: np.ndarray) -> float:
    """Residual sum of squares of ``y[lo..hi]`` fitted by a line plus ``A rho^(i-lo)``.

    ``P`` holds the segment's sums from :func:`_line_sums`; the exponential's own sums
    are accumulated here, over the samples where it is not negligible.
    """
    m = hi - lo + 1
    g = 1.0
    s_g = s_gt = s_gg = s_gy = 0.0
    for j in range(m):
        t = j / (m - 1.0)
        s_g += g
        s_gt += g * t
        s_gg += g * g
        s_gy += g * (y[lo + j] - P[5])
        g *= rho
        if g < 1e-9:
            break
    # normal equations of (1, t, g) by Cramer's rule (symmetric 3 x 3)
    a00, a01, a02, a11, a12, a22 = P[0], P[1], s_g, P[2], s_gt, s_gg
    b0, b1, b2 = P[3], P[4], s_gy
    c00 = a11 * a22 - a12 * a12
    c01 = a02 * a12 - a01 * a22
    c02 = a01 * a12 - a02 * a11
    det = a00 * c00 + a01 * c01 + a02 * c02
    if not (det > 1e-12 * a00 * a11 * a22):
        return np.nan
    c11 = a00 * a22 - a02 * a02
    c12 = a01 * a02 - a00 * a12
    c22 = a00 * a11 - a01 * a01
    th0 = (c00 * b0 + c01 * b1 + c02 * b2) / det
    th1 = (c01 * b0 + c11 * b1 + c12 * b2) / det
    th2 = (c02 * b0 + c12 * b1 + c22 * b2) / det
    return P[6] - (th0 * b0 + th1 * b1 + th2 * b2)


@njit(cache=True, error_model="numpy")
def _line_sums(y: np.ndarray, lo: int, hi: int) -> np.ndarray:
    """Sums ``1, t, t^2, y, t y``, the mean of ``y`` and ``sum y^2`` over a segment
    (``t`` from 0 to 1, ``y`` less its mean: well conditioned at any force scale)."""
    m = hi - lo + 1
    P = np.zeros(7)
    ym = 0.0
    for j in range(m):
        ym += y[lo + j]
    ym /= m
    for j in range(m):
        t = j / (m - 1.0)
        yy = y[lo + j] - ym
        P[0] += 1.0
        P[1] += t
        P[2] += t * t
        P[3] += yy
        P[4] += t * yy
        P[6] += yy * yy
    P[5] = ym
    return P


@njit(cache=True, error_model="numpy")
def response_time(F: np.ndarray, events: np.ndarray, tail: float) -> float:
    """Time constant (samples) of a first-order detector response, from the slip tails.

    A detector of finite bandwidth turns an instantaneous drop into an exponential
    approach to the next stick: from the slip on, the recorded force is the (filtered)
    stick branch plus ``A rho^i``, ``rho = exp(-1/tau)``. The lower half of every stick
    after a slip (its top may soften) is fitted by a line plus that term (its own
    ``A``; one ``rho`` for the trace) and ``tau`` is the grid value (0, then 0.3
    samples up to half the typical fitted part and 1.5 ``tail``, 1.15 apart) with the
    least total squared residual, refined by a parabola in ``log tau``. 0 when the
    tails show no exponential approach.

    ``tail`` is the typical time (samples) from a slip's steepest point to its end as
    detected on the recorded trace: an exponential approach of time ``tau`` keeps the
    drop going for about ``tau`` past that point, so slips that end sooner bound
    ``tau`` (the fit alone could take a curved stick branch for a slow tail).
    """
    n = F.size
    ne = events.shape[0]
    if ne < 2:
        return 0.0
    los = np.empty(ne, dtype=np.int64)
    his = np.empty(ne, dtype=np.int64)
    lens = np.empty(ne)
    nseg = 0
    for k in range(ne):
        lo = int(events[k, 2]) + 1
        hi = int(events[k + 1, 2]) - 1 if k + 1 < ne else n - 1
        hi = lo + (hi - lo) // 2  # the stick's lower half: its top may soften
        if hi - lo + 1 >= 4:
            los[nseg] = lo
            his[nseg] = hi
            lens[nseg] = hi - lo + 1
            nseg += 1
    if nseg < 2:
        return 0.0
    Ps = np.empty((nseg, 7))
    for k in range(nseg):
        Ps[k] = _line_sums(F, los[k], his[k])
    tmax = min(np.median(lens[:nseg]) / 2.0, TAIL_BOUND * tail)
    taus = np.zeros(96)
    nt = 1
    t = 0.3
    while t <= tmax and nt < 96:
        taus[nt] = t
        nt += 1
        t *= 1.15
    per = np.empty((nseg, nt))
    for q in range(nt):
        rho = np.exp(-1.0 / taus[q]) if taus[q] > 0 else 0.0
        for k in range(nseg):
            per[k, q] = _tail_sse(F, los[k], his[k], rho, Ps[k])
    # sticks that fit badly at every tau (a missed slip, a defect) are left out
    var = np.empty(nseg)
    for k in range(nseg):
        var[k] = np.min(per[k]) / max(lens[k] - 3.0, 1.0)
    cut = 4.0 * np.median(var)
    sse = np.zeros(nt)
    for k in range(nseg):
        if var[k] <= cut:
            sse += per[k]
    best = 0
    for q in range(1, nt):
        if sse[q] < sse[best]:
            best = q
    if best == 0:
        return 0.0
    if 1 < best < nt - 1:  # parabola through three points in log tau
        x0, x1, x2 = np.log(taus[best - 1]), np.log(taus[best]), np.log(taus[best + 1])
        y0, y1, y2 = sse[best - 1], sse[best], sse[best + 1]
        den = (x0 - x1) * (x0 - x2) * (x1 - x2)
        a = (x2 * (y1 - y0) + x1 * (y0 - y2) + x0 * (y2 - y1)) / den
        b = (x2 * x2 * (y0 - y1) + x1 * x1 * (y2 - y0) + x0 * x0 * (y1 - y2)) / den
        if a > 0:
            return np.exp(min(max(-b / (2.0 * a), x0), x2))
    return taus[best]


@njit(cache=True, error_model="numpy")
def _box(F: np.ndarray, h: int) -> np.ndarray:
    """Centred moving mean over ``2 h + 1`` samples (shorter at the ends): keeps lines
    and the position of slips, smears a slip symmetrically."""
    n = F.size
    C = _cumsum0(F)
    G = np.empty(n)
    for i in range(n):
        lo = max(0, i - h)
        hi = min(n - 1, i + h)
        G[i] = (C[hi + 1] - C[lo]) / (hi - lo + 1)
    return G


@njit(cache=True, error_model="numpy")
def deconvolve(F: np.ndarray, tau: float) -> np.ndarray:
    """Undo a first-order response of time constant ``tau`` (samples):
    ``F_in[i] = (F[i] - (1 - alpha) F[i-1]) / alpha``, ``alpha = 1 - exp(-1/tau)``."""
    alpha = 1.0 - np.exp(-1.0 / tau)
    G = F.copy()
    for i in range(1, F.size):
        G[i] = (F[i] - (1.0 - alpha) * F[i - 1]) / alpha
    return G


@njit(cache=True, error_model="numpy")
def analyse_segments(x: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray, int, float]:
    """Detect slips and fit the stick segments between them.

    Returns
    -------
    segs : ndarray (n_slips + 1, N_SEG_COLS)
        Per stick segment: fit range, rising-part slope and its end values, quadratic
        coefficients, peak; NaN where the segment is too short.
    slips : ndarray (n_slips, N_SLIP_COLS)
        Per slip: position, force just before and after, peak of the preceding stick,
        index of the slip centre. NaN where a neighbouring segment could not be fitted.
    w : int
        Detection scale in samples (0: no scale where the trace stands above its noise).
    sigma : float
        Noise per sample.
    """
    n = F.size
    events, w, sigma, _ = detect_slips(x, F)
    # a detector's finite bandwidth smears slips into the following stick: undo it
    tail = np.median(events[:, 5]) if events.shape[0] > 0 else 0.0
    tau = response_time(F, events, tail)
    if tau > TAU_MIN:
        # slips missed on the smeared trace show up once it is sharpened: estimate again
        ev2, _, _, _ = detect_slips(x, deconvolve(F, tau))
        tau2 = response_time(F, ev2, tail)
        if tau2 > TAU_MIN and ev2.shape[0] >= events.shape[0]:
            tau = tau2
        F = deconvolve(F, tau)
        if tau >= SMOOTH_TAU:  # its amplified noise, averaged over the response time
            F = _box(F, int(tau / 2.0 + 0.5))
        events, w, _, _ = detect_slips(x, F)
    ne = events.shape[0]
    segs = np.full((ne + 1, N_SEG_COLS), np.nan)
    slips = np.full((ne, N_SLIP_COLS), np.nan)
    # excluded samples around each slip: the run of D_w widened by its window
    start = 0
    for k in range(ne + 1):
        if k < ne:
            end = int(events[k, 0]) - (int(events[k, 4]) - 1)
        else:
            end = n - 1
        # one guard sample at each end, against partly averaged pixels
        lo = start + 1 if k > 0 else start
        hi = end - 1 if k < ne else end
        _fit_segment(x, F, lo, hi, sigma, segs[k])
        if k < ne:
            start = int(events[k, 1]) + int(events[k, 4])
    for k in range(ne):
        slips[k, SLIP_CENTRE] = events[k, 2]
        pre, post = segs[k], segs[k + 1]
        if np.isnan(pre[SEG_C0]) or np.isnan(post[SEG_C0]):
            continue
        if int(post[SEG_START]) <= int(pre[SEG_END]):
            continue
        _locate_slip(x, F, pre, post, sigma, slips[k])
    return segs, slips, w, sigma


@dataclass
class SlipAnalysis:
    """Slips and stick segments of one trace (for diagnostics and plots).

    Attributes
    ----------
    segments : ndarray (n_slips + 1, 11)
        Stick-segment table (see the ``SEG_*`` column constants of this module).
    slips : ndarray (n_slips, 5)
        Slip table (see the ``SLIP_*`` column constants).
    window : int
        Detection window in samples.
    noise_nN : float
        Noise per sample.
    """

    segments: np.ndarray
    slips: np.ndarray
    window: int
    noise_nN: float

    @property
    def n_slips(self) -> int:
        return int(self.slips.shape[0])

    def segment_curve(self, k: int, x_nm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Fitted quadratic of stick segment ``k`` over its fit range."""
        row = self.segments[k]
        if np.isnan(row[SEG_C0]):
            return np.empty(0), np.empty(0)
        xs = x_nm[int(row[SEG_START]) : int(row[SEG_END]) + 1]
        u = xs - row[SEG_XREF]
        return xs, row[SEG_C0] + row[SEG_C1] * u + row[SEG_C2] * u * u


def analyse_trace(x_nm: np.ndarray, force_nN: np.ndarray) -> SlipAnalysis:
    """Slip detection and stick-segment fits of one trace (see module docstring)."""
    x = np.ascontiguousarray(x_nm, dtype=float)
    F = np.ascontiguousarray(force_nN, dtype=float)
    segs, slips, w, sigma = analyse_segments(x, F)
    return SlipAnalysis(segments=segs, slips=slips, window=int(w), noise_nN=float(sigma))
