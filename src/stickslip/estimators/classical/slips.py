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
RISE_FACTOR = 3.0  # ... and in units of the median |D_w| (typical stick rise)
OUTLIER_SIGMAS = 4.0
BEND_FRACTION = 0.15  # guard-pixel deficit, in units of the fitted rise, that flags a bend

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
    # 3-point median: removes single-sample spikes, whose return looks like a slip
    G = F.copy()
    for i in range(1, F.size - 1):
        a, b, c = F[i - 1], F[i], F[i + 1]
        G[i] = max(min(a, b), min(max(a, b), c))
    return G


@njit(cache=True, error_model="numpy")
def _window_diff(G: np.ndarray, w: int) -> np.ndarray:
    """``D[i] = mean(G[i+1..i+w]) - mean(G[i-w+1..i])``; NaN where undefined."""
    n = G.size
    C = np.zeros(n + 1)
    for i in range(n):
        C[i + 1] = C[i] + G[i]
    D = np.full(n, np.nan)
    for i in range(w - 1, n - w):
        D[i] = ((C[i + w + 1] - C[i + 1]) - (C[i + 1] - C[i - w + 1])) / w
    return D


@njit(cache=True, error_model="numpy")
def _events(D: np.ndarray, thr: float, out: np.ndarray) -> int:
    """Runs of ``D < -thr/2`` reaching ``-thr``; rows (first, last, argmin, depth)."""
    n = D.size
    k = 0
    i = 0
    while i < n:
        if not (D[i] < -0.5 * thr):
            i += 1
            continue
        j = i
        imin = i
        while j + 1 < n and D[j + 1] < -0.5 * thr:
            j += 1
            if D[j] < D[imin]:
                imin = j
        if D[imin] < -thr:
            out[k, 0] = i
            out[k, 1] = j
            out[k, 2] = imin
            out[k, 3] = -D[imin]
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
def detect_slips(x: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, int, float, float]:
    """Find slip events.

    Returns
    -------
    events : ndarray (n_events, 4)
        Rows ``(first, last, centre, depth)``: first/last index of the run of ``D_w``
        below threshold, its argmin (slip between samples ``centre`` and ``centre+1``)
        and the drop there.
    w : int
        Window (samples) at which slips were detected.
    sigma : float
        Noise per sample.
    span : float
        5-95 % range of the detrended force.
    """
    n = F.size
    G = _despike(F)
    sigma = noise_sigma(F)
    span = _force_range(x, G)
    buf = np.empty((n, 4))
    w = 1
    wmax = max(1, n // 32)
    while w <= wmax:
        D = _window_diff(G, w)
        Dv = D[w - 1 : n - w]
        floor = RISE_FACTOR * np.median(np.abs(Dv)) if Dv.size > 0 else 0.0
        thr = max(NOISE_SIGMAS * sigma * np.sqrt(2.0 / w), floor)
        k = _events(D, thr, buf)
        if k > 0 and np.median(buf[:k, 3]) >= 0.5 * span:
            return buf[:k].copy(), w, sigma, span
        w *= 2
    return np.empty((0, 4)), 1, sigma, span


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
        Detection window in samples.
    sigma : float
        Noise per sample.
    """
    n = F.size
    events, w, sigma, _ = detect_slips(x, F)
    ne = events.shape[0]
    segs = np.full((ne + 1, N_SEG_COLS), np.nan)
    slips = np.full((ne, N_SLIP_COLS), np.nan)
    # excluded samples around each slip: the run of D_w widened by the window
    start = 0
    for k in range(ne + 1):
        if k < ne:
            end = int(events[k, 0]) - (w - 1)
        else:
            end = n - 1
        # one guard sample at each end, against partly averaged pixels
        lo = start + 1 if k > 0 else start
        hi = end - 1 if k < ne else end
        _fit_segment(x, F, lo, hi, sigma, segs[k])
        if k < ne:
            start = int(events[k, 1]) + w
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
