"""Stick fits and slips of one force trace, given its cycles (numba kernels).

The cycles come from the segmentation of :mod:`stickslip.estimators.segmentation`
(sticks, their straight parts, and the slips between them). Each stick gets a robust
quadratic fit (one pass of outlier rejection at 4 sigma) over the whole stick and a
robust straight-line fit of its straight part. The slip position inside its pixel
follows from pixel averaging: the force integral over the samples between two sticks
must equal that of the pre-slip branch up to the slip and the post-slip branch after
it. That gives the force just before (``F_slip``) and after (``F_after``) each slip free
of the pixel-averaging bias. Those levels, which stationary slips keep, give a second
reading of each stick's slope (:func:`level_slopes`) that checks the baseline.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

import stickslip.estimators.segmentation as sg
from stickslip.robust import mad_sigma, white_sigma

MIN_FIT_SAMPLES = 3  # straight line
MIN_QUAD_SAMPLES = 8  # quadratic (end values and peak)
OUTLIER_SIGMAS = 4.0
BEND_FRACTION = 0.15  # guard-pixel deficit, in units of the fitted rise, that flags a bend

# columns of the per-segment table returned by `analyse_segments`
SEG_START, SEG_END, SEG_SLOPE, SEG_F_LO, SEG_F_HI, SEG_NFIT = 0, 1, 2, 3, 4, 5
SEG_C0, SEG_C1, SEG_C2, SEG_XREF, SEG_PEAK = 6, 7, 8, 9, 10
SEG_TAN_SLOPE, SEG_TAN_F = 11, 12  # the quadratic's tangent at the stick's start
N_SEG_COLS = 13
# columns of the per-slip table
SLIP_X, SLIP_F, SLIP_F_AFTER, SLIP_PEAK, SLIP_CENTRE = 0, 1, 2, 3, 4
N_SLIP_COLS = 5


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
    cut = OUTLIER_SIGMAS * max(sigma, mad_sigma(res[mask[:m]]))
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
def _fit_segment(x: np.ndarray, F: np.ndarray, lo: int, hi: int, slo: int, shi: int,
                 sigma: float, trim: int, row: np.ndarray) -> None:  # fmt: skip
    """Fill one row of the segment table (NaN slope if too short).

    The quadratic spans the stick ``lo..hi``; the straight line its straight part
    ``slo..shi`` (:func:`~.segmentation.find_cycles`), without its last ``trim``
    samples where that part reaches the stick's end: before a slip the branch bends
    over (vertical tangent at the T = 0 instability), which a straight line does not
    follow. The row also holds the quadratic's tangent at the stick's start and the
    force there: precursor softening bends a stick from its bottom up but leaves its
    slope at the bottom (PHYSICS.md's K is the stiffness before softening), which no
    straight line over the stick sees.
    """
    row[:] = np.nan
    row[SEG_START] = lo
    row[SEG_END] = hi
    m = hi - lo + 1
    row[SEG_NFIT] = max(m, 0)
    if m < MIN_FIT_SAMPLES:
        return
    xref = 0.5 * (x[lo] + x[hi])
    mask = np.ones(m, dtype=np.bool_)
    # np.int64: a literal degree would compile each function once per degree
    c0, c1, c2 = _robust_fit(x, F, lo, hi, xref, np.int64(2), sigma, mask)
    row[SEG_C0], row[SEG_C1], row[SEG_C2], row[SEG_XREF] = c0, c1, c2, xref
    slo, shi = max(slo, lo), min(shi, hi)
    if shi - slo + 1 < MIN_FIT_SAMPLES:
        slo, shi = lo, hi
    if shi == hi and shi - trim - slo + 1 >= MIN_FIT_SAMPLES:
        shi -= trim
    b0, b1, _ = _robust_fit(x, F, slo, shi, xref, np.int64(1), sigma,
                            np.ones(shi - slo + 1, dtype=np.bool_))  # fmt: skip
    row[SEG_SLOPE] = b1
    row[SEG_F_LO] = b0 + b1 * (x[slo] - xref)
    row[SEG_F_HI] = b0 + b1 * (x[shi] - xref)
    if m >= MIN_QUAD_SAMPLES and c2 < 0:
        u = x[lo] - xref
        row[SEG_TAN_SLOPE] = c1 + 2.0 * c2 * u
        row[SEG_TAN_F] = c0 + c1 * u + c2 * u * u


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
    # pixel averaging hides at most one sample interval of the stick's rise before a
    # sudden slip: a peak extrapolated higher than that above the samples is a fall
    # that took its time (smooth sliding), not a slip the pixels averaged away
    top = F[e]
    for k in range(e + 1, s):
        top = max(top, F[k])
    u = x[e] - pre[SEG_XREF]
    rise = max(pre[SEG_C1] + 2.0 * pre[SEG_C2] * u, 0.0) * (x[e + 1] - x[e])
    cap = top + rise + 3.0 * sigma
    out[SLIP_F] = min(out[SLIP_F], cap)
    out[SLIP_PEAK] = min(peak, cap)


@njit(cache=True, error_model="numpy")
def fit_sticks(x: np.ndarray, F: np.ndarray, cycles: np.ndarray, tol: float
               ) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """The stick and slip tables of a line from its cycles (:func:`~.segmentation.find_cycles`);
    ``tol``: the fits' outlier and bend tolerance."""
    ns = cycles.shape[0] - 1
    segs = np.full((ns + 1, N_SEG_COLS), np.nan)
    slips = np.full((max(ns, 0), N_SLIP_COLS), np.nan)
    for k in range(ns + 1):
        c = cycles[k]
        lo, hi = int(c[sg.CY_LO]), int(c[sg.CY_HI])
        # one guard sample beside each slip: it may be partly averaged with the slip, or
        # hold the branch's bend-over just before it (:func:`_locate_slip` reads it)
        if hi - lo + 1 >= MIN_FIT_SAMPLES + 2:
            lo += 1 if k > 0 else 0
            hi -= 1 if k < ns else 0
        _fit_segment(x, F, lo, hi, int(c[sg.CY_SLOPE_LO]), int(c[sg.CY_SLOPE_HI]), tol,
                     1 if k < ns else 0, segs[k])  # fmt: skip
    for k in range(ns):
        slips[k, SLIP_CENTRE] = 0.5 * (cycles[k, sg.CY_PEAK] + cycles[k, sg.CY_VALLEY])
        pre, post = segs[k], segs[k + 1]
        if np.isnan(pre[SEG_C0]) or np.isnan(post[SEG_C0]):
            continue
        if int(post[SEG_START]) <= int(pre[SEG_END]):
            continue
        _locate_slip(x, F, pre, post, tol, slips[k])
    return segs, slips


@njit(cache=True, error_model="numpy")
def level_slopes(segs: np.ndarray, slips: np.ndarray) -> np.ndarray:
    """Each stick's slope less the trend of the slip levels on either side of it.

    Stationary stick-slip slips from and to the same levels cycle after cycle, so
    where the force before and after the slip at one end of a stick differ from those
    at its other end, the difference is baseline that the line's baseline left in
    (:func:`~.segmentation.baseline` follows the cycle means, which few cycles do not
    pin down); its slope over the stick comes off the stick's slope. NaN for the
    first and last sticks (one slip beside them) and where a fit is missing.
    """
    ns = slips.shape[0]
    out = np.full(ns + 1, np.nan)
    for k in range(1, ns):
        a, b = slips[k - 1], slips[k]
        dX = b[SLIP_X] - a[SLIP_X]
        if not dX > 0:  # NaN: a slip without its fits
            continue
        trend = 0.5 * ((b[SLIP_F] - a[SLIP_F]) + (b[SLIP_F_AFTER] - a[SLIP_F_AFTER])) / dX
        out[k] = segs[k, SEG_SLOPE] - trend
    return out


@njit(cache=True, error_model="numpy")
def fit_line(x: np.ndarray, F: np.ndarray) -> tuple[
        np.ndarray, np.ndarray, np.ndarray, np.ndarray, int, float, float]:  # fmt: skip
    """Segment a line, take its baseline off and fit its sticks: the line less its
    baseline, the stick and slip tables, the cycles, the block size, the segmentation's
    noise, and the fits' tolerance (:func:`white_sigma` of the line)."""
    tol = white_sigma(F)
    cycles, block, sigma = sg.find_cycles(F, tol)
    G = F - sg.baseline(x, F, cycles)  # zero-mean: <F> is kept
    segs, slips = fit_sticks(x, G, cycles, tol)
    return G, segs, slips, cycles, block, sigma, tol


@njit(cache=True, error_model="numpy")
def analyse_segments(x: np.ndarray, F: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, float]:  # fmt: skip
    """Segment a line, take its baseline off and fit its sticks.

    Returns
    -------
    segs : ndarray (n_slips + 1, N_SEG_COLS)
        Per stick: fit range, straight-part slope and its end values, quadratic
        coefficients; NaN where the stick is too short.
    slips : ndarray (n_slips, N_SLIP_COLS)
        Per slip: position, force just before and after, peak of the preceding stick,
        index of the slip centre. NaN where a neighbouring stick could not be fitted.
    cycles : ndarray (n_slips + 1, segmentation.N_CY_COLS)
        The segmentation's cycle table (:func:`~.segmentation.find_cycles`).
    block : int
        Samples per block of the segmentation.
    sigma : float
        Noise per block mean that the segmentation used.
    """
    _, segs, slips, cycles, block, sigma, _ = fit_line(x, F)
    return segs, slips, cycles, block, sigma


@dataclass
class SlipAnalysis:
    """Slips and stick segments of one trace (for diagnostics and plots).

    Attributes
    ----------
    segments : ndarray (n_slips + 1, 13)
        Stick-segment table (see the ``SEG_*`` column constants of this module).
    slips : ndarray (n_slips, 5)
        Slip table (see the ``SLIP_*`` column constants).
    window : int
        Samples per block of the segmentation (1 up to long lines).
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
    segs, slips, _, block, sigma = analyse_segments(x, F)
    return SlipAnalysis(segments=segs, slips=slips, window=int(block), noise_nN=float(sigma))
