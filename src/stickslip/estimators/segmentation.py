"""Stick-slip segmentation: one recording as a piecewise-linear sawtooth on a slow baseline.

The model
    ``F_i = B(x_i) + S_i + e_i``: a sawtooth ``S`` whose sticks rise linearly and whose
    slips are falls (sudden, or lasting some samples), a slowly varying baseline ``B``
    (topography, drift), and noise ``e`` with occasional spikes.

The fit
    1. **Segmentation.** The line is cut into straight segments by penalised least
       squares: the cut points minimise ``sum_j RSS_j / sigma^2 + beta (segments)``,
       found exactly by PELT (Killick, Fearnhead and Eckley 2012) with O(1) segment
       costs from prefix sums. ``sigma`` is the line's own noise: the smaller of the
       robust (MAD) scatters of its second and first differences, then re-estimated
       from the fit's residuals until it settles (correlated noise shows more in the
       residuals; slips at a few samples each inflate the differences), and never
       below a digitised line's quantisation noise (its step over sqrt(12));
       ``beta = 3 ln n``, the BIC price of a segment's three parameters (start,
       level, slope). Segments of at most two samples have no
       residual, so they carry no evidence of a line: where the neighbours on either
       side meet without a gap, such a segment is a spike and drops out.
    2. **Sticks and slips.** The fitted polyline (its segment ends and the jumps
       between segments) is read as rises and falls with a hysteresis of ``sqrt(beta)
       sigma``, the step whose squared size the penalty prices, so that the kinks of a
       curved stick, or noise, make no slip. A stick is a rise from a valley
       to the next peak, a slip the fall from a peak to the next valley.
    3. **The regime.** Stick-slip means sticks that rise slowly and slips that fall
       fast. Per cycle, ``R_down`` is the mean fall rate of the slip over the mean rise
       rate of the stick before it, and ``R_up`` the mean rise rate over the mean fall
       rate; a slip inside one sample interval is averaged over two, so a fall (rise)
       counts one interval less than it spans, and where the detector's response
       trails after a slip its steepest piece counts. The medians over the cycles are
       weighted by the drops. A sawtooth has ``R_down`` about the
       samples per slip and ``R_up`` about 1 or less; a sine has both about 1; a
       reversed sawtooth only a large ``R_up``. Stick-slip needs the median ``R_down >=
       2.5`` and ``R_up < 2.5`` (:data:`STICK_RATIO`), between a sine's 1 and the 3 of
       a sawtooth of five samples per slip, so that an oscillating slider that never
       sticks, or PT smooth sliding, is not read as sticks. Neither large: rise and
       fall alike (smooth sliding, oscillation); ``R_up`` large: the force jumps up
       (not stick-slip).
    4. **The baseline.** Stationary stick-slip has the same mean force in every cycle;
       a trend of the per-cycle means is the baseline. It is a polynomial in ``x``
       whose degree (0 to 5) minimises the BIC of the cycle means, and its slope is
       taken off the sticks (a baseline rising by one drop per cycle would add the
       whole stick slope again).
    5. **Long lines.** The segmentation runs on block means of ``b`` samples, with
       ``b`` chosen from the line itself: the finest blocks at which a window of
       :data:`WINDOW` blocks shows several cycles, most of whose falls stand clear of
       the noise (twice the hysteresis), then coarsened to about
       :data:`BLOCKS_PER_CYCLE` blocks per cycle. PELT runs on overlapping windows of
       :data:`WINDOW` blocks, so its cost stays linear in the line's length. A block
       mean hides a spike in a level, so a line cut into blocks loses its one-sample
       spikes first (:func:`despike`).

Nothing here carries a scale in samples, nm or seconds: the noise sets the penalty,
the cycles set the resolution, and the ratios of the regime test are pure numbers.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from stickslip.robust import mad_sigma, median, white_sigma

#: Blocks per PELT window (the cost of a window is at most WINDOW^2 segment costs).
WINDOW = 2048
#: Cycles a window must show for its block size to resolve the sawtooth.
MIN_WINDOW_CYCLES = 8
#: Blocks per cycle the segmentation of a long line aims at.
BLOCKS_PER_CYCLE = 32
#: Above this median ratio of the mean fall (rise) rate to the mean rise (fall) rate a
#: line's slips (upward jumps) are fast: a sine has about 1 both ways.
STICK_RATIO = 2.5
#: Highest degree of the baseline polynomial.
MAX_BASELINE_DEGREE = 5
#: Passes of the noise level from the fit's own residuals (step 1).
MAX_NOISE_ITERATIONS = 4
#: A sample that stands off its neighbours' mean by more than this many of that
#: difference's standard deviations (and by more than they differ) is a spike.
SPIKE_SIGMAS = 4.0
#: Segment price in units of ln(n): start, level and slope (BIC).
PARAMS_PER_SEGMENT = 3.0

# columns of the cycle table returned by `find_cycles`
(CY_LO, CY_HI, CY_SLOPE_LO, CY_SLOPE_HI, CY_PEAK, CY_VALLEY, CY_DROP, CY_R_DOWN,
 CY_R_UP, CY_RATE, CY_TOP) = range(11)  # fmt: skip
N_CY_COLS = 11
#: A change of level along a series of per-cycle values counts where its likelihood
#: ratio exceeds this many ln(n). White series of 20-300 values pass 15 ln(n) far less
#: than 1 % of the time; lab-like lines (gain drift, telegraph steps, detector effects:
#: the effect families of ``benchmarks/domain.py``, seed 1) reach at most 4 times 5 ln(n)
#: while a tip change of 1.3-2x that shows in the drops or the slopes scores hundreds.
CHANGE_PENALTY = 15.0
#: ... and where the two levels differ by at least this much (in the log of a per-cycle
#: quantity: 10 %, far below the 1.3x of a tip change worth reporting)
MIN_LEVEL_CHANGE = 0.1
#: Highest degree of the slow trend a change of level must beat (by the BIC): drift
#: and gain bend the cycles' peaks smoothly along a line, a tip change steps them.
TREND_DEGREE = 3


@njit(cache=True, error_model="numpy")
def _prefix(y: np.ndarray) -> np.ndarray:
    """Prefix sums of ``y``, ``i y`` and ``y^2`` (rows 0-2, length ``n + 1``)."""
    n = y.size
    P = np.zeros((3, n + 1))
    for i in range(n):
        P[0, i + 1] = P[0, i] + y[i]
        P[1, i + 1] = P[1, i] + i * y[i]
        P[2, i + 1] = P[2, i] + y[i] * y[i]
    return P


@njit(cache=True, error_model="numpy", inline="always")
def _line(P: np.ndarray, s: int, t: int) -> tuple[float, float, float]:
    """Least-squares line through samples ``s..t-1``: (RSS, slope, value at the middle)."""
    L = t - s
    sy = P[0, t] - P[0, s]
    if L < 3:
        if L == 2:
            syy = P[2, t] - P[2, s]
            siy = P[1, t] - P[1, s]
            c = s + 0.5
            return 0.0, 2.0 * (siy - c * sy), 0.5 * sy
        return 0.0, 0.0, sy
    siy = P[1, t] - P[1, s]
    syy = P[2, t] - P[2, s]
    c = 0.5 * (s + t - 1)
    sxy = siy - c * sy
    sxx = L * (L * L - 1.0) / 12.0
    slope = sxy / sxx
    rss = syy - sy * sy / L - sxy * slope
    return max(rss, 0.0), slope, sy / L


@njit(cache=True, error_model="numpy", inline="always")
def _rss(P: np.ndarray, s: int, t: int) -> float:
    """:func:`_line`'s RSS alone (the same arithmetic): PELT's inner loop needs no more."""
    L = t - s
    if L < 3:
        return 0.0
    sy = P[0, t] - P[0, s]
    sxy = (P[1, t] - P[1, s]) - 0.5 * (s + t - 1) * sy
    rss = (P[2, t] - P[2, s]) - sy * sy / L - sxy * (sxy / (L * (L * L - 1.0) / 12.0))
    return max(rss, 0.0)


@njit(cache=True, error_model="numpy")
def _pelt(P: np.ndarray, lo: int, hi: int, beta: float, starts: np.ndarray) -> int:
    """Exact penalised segmentation of ``lo..hi-1`` (PELT); segment starts into ``starts``."""
    n = hi - lo
    cost = np.empty(n + 1)
    last = np.empty(n + 1, dtype=np.int64)
    cands = np.empty(n + 1, dtype=np.int64)
    vals = np.empty(n + 1)
    cost[0] = -beta
    cands[0] = 0
    nc = 1
    for t in range(1, n + 1):
        best = np.inf
        arg = 0
        for j in range(nc):
            s = cands[j]
            v = cost[s] + _rss(P, lo + s, lo + t) + beta
            vals[j] = v
            if v < best:
                best = v
                arg = s
        cost[t] = best
        last[t] = arg
        k = 0
        for j in range(nc):  # prune the starts that can never win again
            if vals[j] - beta <= best:
                cands[k] = cands[j]
                k += 1
        cands[k] = t
        nc = k + 1
    m = 0
    t = n
    while t > 0:
        starts[m] = lo + last[t]
        m += 1
        t = last[t]
    starts[:m] = starts[:m][::-1].copy()
    return m


@njit(cache=True, error_model="numpy")
def _segment(y: np.ndarray, beta: float) -> np.ndarray:
    """Segment starts of ``y`` (sorted, first 0), PELT on overlapping windows."""
    n = y.size
    P = _prefix(y)
    out = np.empty(n + 1, dtype=np.int64)
    buf = np.empty(WINDOW + 1, dtype=np.int64)
    m = 0
    lo = 0
    while True:
        hi = min(n, lo + WINDOW)
        k = _pelt(P, lo, hi, beta, buf)
        if hi == n:
            for j in range(k):
                out[m] = buf[j]
                m += 1
            break
        # keep the cuts of the window's first three quarters; the next window starts
        # at the last of them, so no cut depends on where a window ended
        keep_to = lo + (3 * WINDOW) // 4
        nxt = lo
        for j in range(k):
            if buf[j] <= keep_to:
                out[m] = buf[j]
                m += 1
                nxt = buf[j]
        if nxt == lo:  # one segment longer than the window: cut it (the polyline merges it)
            nxt = keep_to
        else:
            m -= 1  # the next window starts at this cut and puts it back
        lo = nxt
    return out[:m]


@njit(cache=True, error_model="numpy")
def _block_means(F: np.ndarray, b: int) -> np.ndarray:
    m = F.size // b
    y = np.empty(m)
    for j in range(m):
        y[j] = np.mean(F[j * b : (j + 1) * b])
    return y


@njit(cache=True, error_model="numpy")
def _polyline(y: np.ndarray, starts: np.ndarray, sigma: float
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """Vertices of the fitted polyline: index, value, and the slope of the piece
    that ends there (NaN for a jump), with spikes (segments of at most two samples
    whose neighbours meet without a gap) left out."""
    n = y.size
    P = _prefix(y)
    m = starts.size
    ends = np.empty(m, dtype=np.int64)
    ends[:-1] = starts[1:]
    ends[-1] = n
    slope = np.empty(m)
    mid = np.empty(m)
    for j in range(m):
        _, slope[j], mid[j] = _line(P, starts[j], ends[j])
    gap_tol = np.sqrt(2.0 * PARAMS_PER_SEGMENT * np.log(max(n, 3))) * sigma
    keep = np.ones(m, dtype=np.bool_)
    for j in range(1, m - 1):
        if ends[j] - starts[j] > 2:
            continue
        a, c = j - 1, j + 1
        xa = 0.5 * (starts[a] + ends[a] - 1)
        xc = 0.5 * (starts[c] + ends[c] - 1)
        left = mid[a] + slope[a] * (starts[c] - xa)  # left line carried to the right's start
        right = mid[c]
        right = right + slope[c] * (starts[c] - xc)
        if abs(left - right) < gap_tol:
            keep[j] = False
    # spikes at the ends: a short first or last segment is judged by its one neighbour
    vi = np.empty(2 * m, dtype=np.int64)
    vv = np.empty(2 * m)
    vs = np.empty(2 * m)
    k = 0
    for j in range(m):
        if not keep[j]:
            continue
        c = 0.5 * (starts[j] + ends[j] - 1)
        i0, i1 = starts[j], ends[j] - 1
        vi[k] = i0
        vv[k] = mid[j] + slope[j] * (i0 - c)
        vs[k] = np.nan  # reached by a jump from the previous vertex
        k += 1
        if i1 > i0:
            vi[k] = i1
            vv[k] = mid[j] + slope[j] * (i1 - c)
            vs[k] = slope[j]
            k += 1
    return vi[:k], vv[:k], vs[:k]


@njit(cache=True, error_model="numpy")
def _turns(vv: np.ndarray, delta: float) -> tuple[np.ndarray, np.ndarray]:
    """Alternating extrema of the polyline with hysteresis ``delta``: vertex indices of
    the peaks and valleys, and +1/-1 for each (a zigzag)."""
    k = vv.size
    idx = np.empty(k, dtype=np.int64)
    kind = np.empty(k, dtype=np.int64)
    m = 0
    if k == 0:
        return idx[:0], kind[:0]
    hi_j = 0
    lo_j = 0
    state = 0  # 0: undecided, 1: rising (tracking a peak), -1: falling (tracking a valley)
    for j in range(1, k):
        v = vv[j]
        if state == 0:
            if v > vv[hi_j]:
                hi_j = j
            if v < vv[lo_j]:
                lo_j = j
            if vv[hi_j] - vv[lo_j] >= delta:
                if hi_j > lo_j:  # went up first: the valley is a turn, now rising
                    idx[m] = lo_j
                    kind[m] = -1
                    m += 1
                    state = 1
                else:
                    idx[m] = hi_j
                    kind[m] = 1
                    m += 1
                    state = -1
        elif state == 1:
            if v > vv[hi_j]:
                hi_j = j
            elif vv[hi_j] - v >= delta:
                idx[m] = hi_j
                kind[m] = 1
                m += 1
                state = -1
                lo_j = j
        else:
            if v < vv[lo_j]:
                lo_j = j
            elif v - vv[lo_j] >= delta:
                idx[m] = lo_j
                kind[m] = -1
                m += 1
                state = 1
                hi_j = j
    return idx[:m], kind[:m]


@njit(cache=True, error_model="numpy")
def _steepest(vi: np.ndarray, vv: np.ndarray, a: int, b: int, sign: float) -> float:
    """Steepest fall (``sign`` -1) or rise (+1) per sample of one piece between vertices
    ``a..b`` (a segment, or a jump between two)."""
    best = 0.0
    for j in range(a + 1, b + 1):
        d = vi[j] - vi[j - 1]
        if d > 0:
            best = max(best, sign * (vv[j] - vv[j - 1]) / d)
    return best


@njit(cache=True, error_model="numpy", inline="always")
def _slope_se(sigma: float, L: float) -> float:
    """Standard error of a least-squares slope over ``L`` equally spaced samples."""
    return sigma * np.sqrt(12.0 / (L * (L * L - 1.0))) if L > 2 else np.inf


@njit(cache=True, error_model="numpy", inline="always")
def _agrees(vi: np.ndarray, vv: np.ndarray, vs: np.ndarray, j: int, s: float, se: float,
            sigma: float) -> bool:  # fmt: skip
    """Piece ``j`` (vertices j - 1 -> j) continues a straight stick of slope ``s``."""
    if np.isnan(vs[j]):  # a jump: only one inside the noise continues the stick
        return abs(vv[j] - (vv[j - 1] + s * (vi[j] - vi[j - 1]))) <= 3.0 * sigma
    Lj = vi[j] - vi[j - 1] + 1.0
    sej = _slope_se(sigma, Lj)
    return abs(vs[j] - s) <= 3.0 * np.sqrt(se * se + sej * sej)


@njit(cache=True, error_model="numpy")
def _linear_part(vi: np.ndarray, vv: np.ndarray, vs: np.ndarray, a: int, b: int,
                 sigma: float) -> tuple[int, int]:  # fmt: skip
    """The stick's straight part between vertices a (valley) and b (peak): its longest
    rising segment, continued down and up through the neighbouring segments while their
    slopes agree with it within three standard errors (a rounded top, where the slip
    has begun, or a rebound after the last slip bends away and is left out). Returns
    sample indices (first, last)."""
    seed = -1
    for j in range(a + 1, b + 1):  # pieces (j - 1, j) with a slope, not jumps
        if not np.isnan(vs[j]) and vs[j] > 0 and vi[j] - vi[j - 1] >= 2:
            if seed < 0 or vi[j] - vi[j - 1] > vi[seed] - vi[seed - 1]:
                seed = j
    if seed < 0:
        return vi[a], vi[b]
    lo_j, hi_j = seed - 1, seed  # the straight part spans vertices lo_j..hi_j
    s = vs[seed]
    grow = True
    while grow:
        grow = False
        se = _slope_se(sigma, vi[hi_j] - vi[lo_j] + 1.0)
        if hi_j < b and _agrees(vi, vv, vs, hi_j + 1, s, se, sigma):
            hi_j += 1
            grow = True
        elif lo_j > a and _agrees(vi, vv, vs, lo_j, s, se, sigma):
            lo_j -= 1
            grow = True
        if grow and not np.isnan(vs[hi_j if hi_j > lo_j else lo_j]):
            # the slope of what is merged: the length-weighted mean of its segments
            tot = 0.0
            w = 0.0
            for j in range(lo_j + 1, hi_j + 1):
                if not np.isnan(vs[j]):
                    L = vi[j] - vi[j - 1] + 1.0
                    tot += vs[j] * L
                    w += L
            s = tot / w
    return vi[lo_j], vi[hi_j]


@njit(cache=True, error_model="numpy")
def quantum_sigma(F: np.ndarray) -> float:
    """The noise a digitised line carries at least: its ADC step over sqrt(12) (the
    smallest non-zero step between neighbours, where a quarter of them or more are
    zero: the line sits on the converter's levels); 0 otherwise."""
    n = F.size
    zeros = 0
    q = np.inf
    for i in range(n - 1):
        d = abs(F[i + 1] - F[i])
        if d == 0.0:
            zeros += 1
        elif d < q:
            q = d
    if n < 3 or 4 * zeros < n - 1 or not np.isfinite(q):
        return 0.0
    return q / np.sqrt(12.0)


@njit(cache=True, error_model="numpy")
def despike(F: np.ndarray, sigma: float) -> np.ndarray:
    """``F`` with its isolated one-sample spikes replaced by their neighbours' mean.

    A sample is a spike where it stands off the mean of its two neighbours by more
    than :data:`SPIKE_SIGMAS` times that difference's noise (``sqrt(3/2) sigma``) and by
    more than the two neighbours differ from each other. A slip has neighbours on
    either side of it that differ by the drop, and a stick's samples lie on a line
    through their neighbours, so neither is touched, whatever the scale of the line.
    """
    out = F.copy()
    cut = SPIKE_SIGMAS * np.sqrt(1.5) * sigma
    for i in range(1, F.size - 1):
        mid = 0.5 * (F[i - 1] + F[i + 1])
        dev = abs(F[i] - mid)
        if dev > cut and dev > abs(F[i + 1] - F[i - 1]):
            out[i] = mid
    return out


@njit(cache=True, error_model="numpy")
def choose_block(F: np.ndarray) -> int:
    """Samples per block for the segmentation of ``F`` (1 for lines up to a window)."""
    n = F.size
    b = 1
    q = quantum_sigma(F)
    while n // b > WINDOW:
        y = _block_means(F[: b * WINDOW], b)
        s = max(white_sigma(y), q / np.sqrt(b), 1e-300)
        z = y / s
        beta = PARAMS_PER_SEGMENT * np.log(WINDOW)
        starts = _segment(z, beta)
        _, vv, _ = _polyline(z, starts, 1.0)
        tk, kind = _turns(vv, np.sqrt(beta))
        # the sawtooth is resolved where most falls stand clear of the noise (twice the
        # hysteresis): correlated noise makes many falls just past it at fine blocks
        nfall = 0
        nclear = 0
        for j in range(tk.size - 1):
            if kind[j] == 1:
                nfall += 1
                nclear += vv[tk[j]] - vv[tk[j + 1]] >= 2.0 * np.sqrt(beta)
        if nclear >= MIN_WINDOW_CYCLES and 2 * nclear >= nfall:
            per_cycle = b * WINDOW / nclear  # samples per cycle
            return max(1, int(per_cycle // BLOCKS_PER_CYCLE))
        b *= 4
    return b


@njit(cache=True, error_model="numpy")
def _residual_sigma(y: np.ndarray, starts: np.ndarray) -> float:
    """Robust noise level of the segmentation's residuals (segments of three samples or
    more: shorter ones fit exactly and say nothing of the noise)."""
    n = y.size
    P = _prefix(y)
    res = np.empty(n)
    k = 0
    for j in range(starts.size):
        t = starts[j + 1] if j + 1 < starts.size else n
        L = t - starts[j]
        if L < 3:
            continue
        _, sl, md = _line(P, starts[j], t)
        c = 0.5 * (starts[j] + t - 1)
        corr = np.sqrt(L / (L - 2.0))  # a fitted line leaves two degrees of freedom fewer
        for i in range(starts[j], t):
            res[k] = (y[i] - (md + sl * (i - c))) * corr
            k += 1
    return mad_sigma(res[:k]) if k >= 8 else np.nan


@njit(cache=True, error_model="numpy")
def find_cycles(F: np.ndarray, white: float = -1.0) -> tuple[np.ndarray, int, float]:
    """Sticks and slips of one line (the module docstring's steps 1-3, 5).

    Parameters
    ----------
    F : ndarray (n,)
        Force samples (any unit).
    white : float
        :func:`~stickslip.robust.white_sigma` of ``F`` where the caller has it
        (negative: computed).

    Returns
    -------
    cycles : ndarray (m + 1, N_CY_COLS)
        One row per stick that ends in a slip (``m`` slips): the stick's samples
        ``CY_LO..CY_HI``, its straight part ``CY_SLOPE_LO..CY_SLOPE_HI``, the slip's
        peak and valley samples, the drop, the cycle's ``R_down`` and ``R_up``, its mean rise
        rate and its peak's level (``CY_TOP``, on the fitted polyline); then
        the line's final stick (no slip after it: ``CY_PEAK`` -1).
    block : int
        Samples per block of the segmentation.
    sigma : float
        The noise level (per block mean, in F's unit) the segmentation used.
    """
    n = F.size
    if n < 4:
        out = np.full((1, N_CY_COLS), np.nan)
        out[0, CY_LO], out[0, CY_HI], out[0, CY_PEAK] = 0, max(n - 1, 0), -1
        out[0, CY_SLOPE_LO], out[0, CY_SLOPE_HI] = 0, max(n - 1, 0)
        return out, 1, 0.0
    b = 1
    if n > WINDOW:
        # a block mean hides a spike in a level that the polyline cannot tell from a
        # step, so a line cut into blocks loses its spikes first (at one sample per
        # block the polyline drops them itself: step 1)
        w = white if white >= 0 else white_sigma(F)
        clean = despike(F, max(w, quantum_sigma(F)))
        b = choose_block(clean)
        if b > 1:
            F = clean
        else:
            white = w  # the line is kept as it is: its white noise is read once
    y = _block_means(F, b) if b > 1 else F.copy()
    nb = y.size
    # start from below: the second differences count the slips of a coarse line as
    # noise, the first differences (most of them on sticks) less so; the residuals'
    # noise then settles where the segmentation explains the line
    d1 = y[1:] - y[:-1]
    s = min(white if b == 1 and white >= 0 else white_sigma(y), mad_sigma(d1) / np.sqrt(2.0))
    # the converter's step is noise too: a digitised line's levels are no segments
    floor = quantum_sigma(F) / np.sqrt(b)
    s = max(s, floor)
    if not s > 0:  # a noiseless or digitised line: any tiny scale keeps the costs finite
        s = max(1e-9 * (np.max(np.abs(y)) - np.min(np.abs(y))), 1e-300)
    beta = PARAMS_PER_SEGMENT * np.log(max(nb, 3))
    starts = _segment(y / s, beta)
    # the model's own noise: the fit's residuals, where they disagree with the second
    # differences (correlated noise shows more; slips at a few samples each inflate
    # the second differences)
    for _ in range(MAX_NOISE_ITERATIONS):
        s_res = max(_residual_sigma(y, starts), floor)
        if not s_res > 0 or abs(s_res / s - 1.0) < 0.1:
            break
        s = s_res
        starts = _segment(y / s, beta)
    vi, vv, vs = _polyline(y, starts, s)
    tk, kind = _turns(vv, np.sqrt(beta) * s)
    # cycles: valley -> peak (stick) -> valley (slip)
    out = np.full((tk.size + 1, N_CY_COLS), np.nan)
    m = 0
    v0 = 0  # the first stick starts at the line's start
    for j in range(tk.size):
        if kind[j] != 1:
            v0 = tk[j]
            continue
        p = tk[j]
        nxt = tk[j + 1] if j + 1 < tk.size else vi.size - 1
        if nxt <= p:
            continue
        lo_v = v0
        rise = vv[p] - vv[lo_v]
        rise_len = vi[p] - vi[lo_v]
        fall = vv[p] - vv[nxt]
        fall_len = vi[nxt] - vi[p]
        sl_lo, sl_hi = _linear_part(vi, vv, vs, lo_v, p, s)
        out[m, CY_LO] = vi[lo_v]
        out[m, CY_HI] = vi[p]
        out[m, CY_SLOPE_LO] = sl_lo
        out[m, CY_SLOPE_HI] = sl_hi
        out[m, CY_PEAK] = vi[p]
        out[m, CY_VALLEY] = vi[nxt]
        out[m, CY_DROP] = fall
        out[m, CY_TOP] = vv[p]
        if rise_len > 0:
            out[m, CY_RATE] = rise / rise_len
        # mean rates; a slip inside a sample interval is averaged over two of them,
        # so a fall (rise) is one interval shorter than it looks
        # or, where the detector's response trails after a slip, the steepest piece
        if rise_len > 0 and rise > 0 and fall > 0:
            f_rate = max(fall / max(fall_len - 1, 1), _steepest(vi, vv, p, nxt, -1.0))
            r_rate = max(rise / max(rise_len - 1, 1), _steepest(vi, vv, lo_v, p, 1.0))
            out[m, CY_R_DOWN] = f_rate / (rise / rise_len)
            out[m, CY_R_UP] = r_rate / (fall / fall_len)
        m += 1
        v0 = nxt
    # the final stick, after the last slip
    out[m, CY_LO] = vi[v0]
    out[m, CY_HI] = vi[vi.size - 1]
    sl_lo, sl_hi = _linear_part(vi, vv, vs, v0, vi.size - 1, s)
    out[m, CY_SLOPE_LO] = sl_lo
    out[m, CY_SLOPE_HI] = sl_hi
    out[m, CY_PEAK] = -1
    m += 1
    out = out[:m].copy()
    if b > 1:  # block indices to samples, the blocks that hold a slip left out
        for r in range(m):
            for c in (CY_LO, CY_SLOPE_LO):
                out[r, c] = (out[r, c] + 1) * b if out[r, c] > 0 else 0
            for c in (CY_HI, CY_SLOPE_HI):
                out[r, c] = min(out[r, c] * b - 1, n - 1) if r < m - 1 else n - 1
            if out[r, CY_PEAK] >= 0:
                out[r, CY_PEAK] = out[r, CY_PEAK] * b + b // 2
                out[r, CY_VALLEY] = out[r, CY_VALLEY] * b + b // 2
    return out, b, s


@njit(cache=True, error_model="numpy")
def _weighted_median(v: np.ndarray, w: np.ndarray) -> float:
    ok = ~np.isnan(v) & (w > 0)
    v, w = v[ok], w[ok]
    if v.size == 0:
        return np.nan
    order = np.argsort(v)
    half = 0.5 * np.sum(w)
    acc = 0.0
    for j in order:
        acc += w[j]
        if acc >= half:
            return v[j]
    return v[order[-1]]


@njit(cache=True, error_model="numpy")
def cycle_ratios(cycles: np.ndarray) -> tuple[float, float]:
    """Median ``R_down`` and ``R_up`` over a line's cycles, each cycle weighted by its
    drop (a small cycle, near the noise, says less of the regime); NaN without cycles."""
    m = cycles.shape[0] - 1
    if m <= 0:
        return np.nan, np.nan
    w = cycles[:m, CY_DROP]
    return (_weighted_median(cycles[:m, CY_R_DOWN], w),
            _weighted_median(cycles[:m, CY_R_UP], w))  # fmt: skip


@njit(cache=True, error_model="numpy")
def baseline(x: np.ndarray, F: np.ndarray, cycles: np.ndarray) -> np.ndarray:
    """The slow baseline under the sawtooth (the module docstring's step 4), zero-mean
    over the line: a polynomial in ``x`` through the per-cycle mean forces, of the
    degree (0 to :data:`MAX_BASELINE_DEGREE`) that minimises their BIC."""
    n = F.size
    m = cycles.shape[0] - 1  # complete cycles: valley to valley
    B = np.zeros(n)
    if m < 4:
        return B
    xc = np.empty(m)
    fc = np.empty(m)
    k = 0
    for r in range(1, m):  # from one slip's valley to the next
        lo = int(cycles[r - 1, CY_VALLEY])
        hi = int(cycles[r, CY_VALLEY])
        if hi - lo >= 2:
            xc[k] = np.mean(x[lo:hi])
            fc[k] = np.mean(F[lo:hi])
            k += 1
    if k < 4:
        return B
    xc = xc[:k]
    fc = fc[:k]
    x0 = 0.5 * (x[0] + x[n - 1])
    hw = max(0.5 * (x[n - 1] - x[0]), 1e-300)
    u = (xc - x0) / hw
    best_bic = np.inf
    best_c = np.zeros(1)
    dmax = min(MAX_BASELINE_DEGREE, k // 4)
    for d in range(dmax + 1):
        A = np.empty((k, d + 1))
        for j in range(d + 1):
            A[:, j] = u**j
        c = np.linalg.lstsq(A, fc)[0]
        r = fc - A @ c
        rss = np.sum(r * r)
        bic = k * np.log(max(rss / k, 1e-300)) + (d + 1) * np.log(k)
        if bic < best_bic:
            best_bic = bic
            best_c = c
    if best_c.size == 1:
        return B
    uu = (x - x0) / hw
    for j in range(1, best_c.size):
        B += best_c[j] * uu**j
    return B - np.mean(B)


@njit(cache=True, error_model="numpy")
def _clip_levels(v: np.ndarray, k: int, s: float) -> np.ndarray:
    """``v`` with ``v[:k]`` and ``v[k:]`` each clipped at 4 ``s`` from its own median."""
    w = v.copy()
    for a, b in ((0, k), (k, v.size)):
        med = median(v[a:b])
        for i in range(a, b):
            w[i] = min(max(v[i], med - 4.0 * s), med + 4.0 * s)
    return w


@njit(cache=True, error_model="numpy")
def _split_ratios(w: np.ndarray, s: float) -> tuple[np.ndarray, int]:
    """The likelihood ratio of one change of level before each index of ``w`` (NaN
    where not tried: a fifth of the values on each side at least) and its argmax."""
    n = w.size
    T = np.full(n, np.nan)
    total = np.sum(w)
    left = w[0] + w[1]
    best = 0.0
    arg = -1
    lo = max(3, n // 5)  # a fifth of the cycles on each side at least: an end's few
    for k in range(3, n - 2):  # odd cycles are no regime
        left += w[k - 1]  # the sum of w[:k]
        if k < lo or k > n - lo:
            continue
        m1 = left / k
        m2 = (total - left) / (n - k)
        T[k] = (m1 - m2) ** 2 / (s * s * (1.0 / k + 1.0 / (n - k)))
        if T[k] > best:
            best = T[k]
            arg = k
    return T, arg


@njit(cache=True, error_model="numpy")
def _zero_sigma(r: np.ndarray) -> float:
    """Robust standard deviation of values whose centre is zero (differences of a
    series, residuals about fitted levels): 1.4826 times their median absolute value.
    Unlike the MAD about their own median it holds where they take two values in about
    equal numbers (the differences of a series that alternates), where that MAD is 0."""
    return 1.4826 * median(np.abs(r))


@njit(cache=True, error_model="numpy")
def _level_rss(v: np.ndarray, k: int) -> float:
    """Residual sum of squares of ``v`` about the means of ``v[:k]`` and ``v[k:]``."""
    return np.sum((v[:k] - np.mean(v[:k])) ** 2) + np.sum((v[k:] - np.mean(v[k:])) ** 2)


@njit(cache=True, error_model="numpy")
def _ramp_rss(v: np.ndarray, k: int) -> float:
    """The least residual sum of squares of ``v`` about two levels joined by a straight
    ramp of ``w >= 3`` values centred on ``k`` (both levels fitted for each ``w``)."""
    n = v.size
    best = np.inf
    for w in range(3, n):
        a = k - w / 2.0  # the ramp runs from a to a + w
        if a < 1.0 or a + w > n - 1.0:
            break
        r = np.empty(n)
        for i in range(n):
            r[i] = min(max((i + 0.5 - a) / w, 0.0), 1.0)
        # least squares for v ~ m1 (1 - r) + m2 r
        s00 = np.sum((1.0 - r) ** 2)
        s01 = np.sum((1.0 - r) * r)
        s11 = np.sum(r * r)
        b0 = np.sum((1.0 - r) * v)
        b1 = np.sum(r * v)
        det = s00 * s11 - s01 * s01
        if not det > 0:
            continue
        m1 = (b0 * s11 - b1 * s01) / det
        m2 = (s00 * b1 - s01 * b0) / det
        best = min(best, np.sum((v - m1 * (1.0 - r) - m2 * r) ** 2))
    return best


@njit(cache=True, error_model="numpy")
def _change_profile(v: np.ndarray) -> tuple[np.ndarray, float]:
    """The likelihood ratio of a single change of level before each index of a series
    (per-cycle values in order; NaN where not tried), and the series' score.

    The noise of one value is the robust scatter of the series' first differences over
    sqrt(2) (a step moves one difference only), or, where larger, the robust scatter
    about the two levels of the best split (a slow trend is smooth from value to value
    but no step); the ratio is ``(mean_1 - mean_2)^2 / (s^2 (1/k + 1/(n - k)))``. The
    score is the best split's ratio over its price ``CHANGE_PENALTY ln n``: above 1, the
    series has two levels (with at least a fifth of the values on each side, values
    clipped at 4 s from the median of their own level, a step of at least
    :data:`MIN_LEVEL_CHANGE`, and two levels that fit better, by the BIC, than a slow
    trend of degree 1 to :data:`TREND_DEGREE` and than two levels joined by a ramp over
    three values or more); 0 for fewer than eight values.
    """
    n = v.size
    T = np.full(n, np.nan)
    if n < 8:
        return T, 0.0
    d = v[1:] - v[:-1]
    s = _zero_sigma(d) / np.sqrt(2.0)
    if not s > 0:
        return T, 0.0
    # one odd cycle (a missed slip, the cycle in which the tip changed) is not a
    # regime: values are clipped at 4 s from the median of their own level. The levels
    # are the best split's, first of the values as they are, then found again after
    # each clipping until the split stays put (clipping about the line's two halves
    # instead drew every split to the middle)
    w = v
    T, arg = _split_ratios(w, s)
    k = -1
    for _ in range(8):
        if arg < 0 or arg == k:
            break
        k = arg
        w = _clip_levels(v, k, s)
        T, arg = _split_ratios(w, s)
    if arg < 0:
        return T, 0.0
    # judged against the scatter about the two levels, not only between neighbours: a
    # slow trend (a modulated barrier) is smooth from cycle to cycle but no step
    res = np.empty(n)
    m1 = median(w[:arg])
    m2 = median(w[arg:])
    for i in range(n):
        res[i] = w[i] - (m1 if i < arg else m2)
    T *= (s / max(s, _zero_sigma(res))) ** 2
    if abs(m1 - m2) < MIN_LEVEL_CHANGE:
        return T, 0.0
    # a step, not a drift: two levels and a place must explain the series better, by
    # the BIC, than a slow trend (a polynomial of degree 1 to TREND_DEGREE) through it
    rss_step = max(_level_rss(w, arg), 1e-300)
    u = (np.arange(n) - 0.5 * (n - 1)) / (0.5 * n)
    for deg in range(1, TREND_DEGREE + 1):
        A = np.empty((n, deg + 1))
        for j in range(deg + 1):
            A[:, j] = u**j
        c = np.linalg.lstsq(A, w)[0]
        rss_trend = np.sum((w - A @ c) ** 2)
        if not n * np.log(rss_trend / rss_step) > (2 - deg) * np.log(n):
            return T, 0.0
    # a step, not a slope between two levels: the values as they are must not fit
    # better, by the BIC price of one more parameter, with the levels joined by a ramp
    # of three cycles or more (a barrier modulated along the substrate) than by a step
    # (a tip change moves within one cycle: the one in which it happens)
    if _ramp_rss(v, arg) * np.exp(np.log(n) / n) < _level_rss(v, arg):
        return T, 0.0
    return T, np.nanmax(T) / (CHANGE_PENALTY * np.log(n))


@njit(cache=True, error_model="numpy")
def _change_series(cycles: np.ndarray, col: int) -> np.ndarray:
    """The per-cycle series a change of level is sought in: the log rise rates
    (``CY_RATE``) or the peaks' level in median drops (``CY_TOP``), of every cycle but
    the first (its stick starts where the line does) and the final stick; empty where
    it cannot be formed (a rate not above 0, no drop)."""
    m = cycles.shape[0] - 1
    v = cycles[1:m, col]
    if col == CY_TOP:
        drop = median(cycles[1:m, CY_DROP])
        return v / drop if drop > 0 else v[:0]
    return np.log(v) if np.all(v > 0) else v[:0]


@njit(cache=True, error_model="numpy")
def cycle_change(cycles: np.ndarray) -> tuple[int, float]:
    """Two regimes along a line: the strongest change of level in its cycles' log rise
    rates (the stick's stiffness) and peak levels (in median drops: the barrier;
    :func:`_change_profile` each), placed where the likelihood ratios of the series
    that show a change add up to most. A barrier that changes at high eta moves the
    peaks and valleys alike, not the drops (about ``K a`` there); drift, gain and a
    barrier modulated along the substrate move the peaks too, but smoothly, which the
    profile's trend and ramp tests tell from a step. The drops are left out: a line
    that mixes single and multiple slips has drops of several sizes in any order.

    Returns
    -------
    k : int
        The cycle (row of ``cycles``) whose stick starts the second regime; -1 if none.
    score : float
        The strongest series' score (above 1: two regimes).
    """
    m = cycles.shape[0] - 1
    if m < 9:
        return -1, 0.0
    total = np.zeros(m - 1)
    best = 0.0
    for col in (CY_RATE, CY_TOP):
        v = _change_series(cycles, col)
        if v.size == 0:
            continue
        T, score = _change_profile(v)
        if score > 1.0:
            for i in range(T.size):
                if T[i] > 0:
                    total[i] += T[i]
        best = max(best, score)
    if best <= 1.0 or not np.any(total > 0):
        return -1, best
    return int(np.argmax(total)) + 1, best


@njit(cache=True, error_model="numpy")
def slope_change(cycles: np.ndarray) -> float:
    """The score of a change of level part-way along a line in its sticks' log rise rates
    (:func:`_change_profile`; above 1: sticks of two slopes, two springs in one line)."""
    if cycles.shape[0] - 1 < 9:
        return 0.0
    v = _change_series(cycles, CY_RATE)
    return _change_profile(v)[1] if v.size else 0.0


@njit(cache=True, error_model="numpy")
def alternation(cycles: np.ndarray) -> float:
    """The score of slips of two sizes taking turns: the likelihood ratio of two levels of
    the log drops, one for the odd slips and one for the even, against one level, over
    its price ``CHANGE_PENALTY ln n`` (above 1: two sizes alternate, as two contacts in
    different registry make; the noise is the robust scatter of each kind about its own
    median, and the two medians must differ by :data:`MIN_LEVEL_CHANGE`); 0 for fewer
    than eight slips."""
    m = cycles.shape[0] - 1
    v = cycles[:m, CY_DROP]
    n = v.size
    if n < 8 or not np.all(v > 0):
        return 0.0
    v = np.log(v)
    even, odd = v[0::2], v[1::2]
    me, mo = median(even), median(odd)
    if abs(me - mo) < MIN_LEVEL_CHANGE:
        return 0.0
    s = np.sqrt(0.5 * (_zero_sigma(even - me) ** 2 + _zero_sigma(odd - mo) ** 2))
    if not s > 0:
        s = 1e-12
    T = (np.mean(even) - np.mean(odd)) ** 2 / (s * s * (1.0 / even.size + 1.0 / odd.size))
    return T / (CHANGE_PENALTY * np.log(n))
