"""Slip detection and stick-segment fits on one force trace (numba kernels).

A slip is a drop of the force that is fast compared with the stick phase. It is found
on the windowed difference ``D_w(i) = mean(F[i+1..i+w]) - mean(F[i-w+1..i])`` of the
despiked trace at scales ``w = 1, 2, 4, ...`` samples, so that nothing fixes how many
samples a slip or a stick takes (from a few to tens of thousands per slip). A drop
counts when it is below ``-max(5 noise_w, 3 median|D_w|)``: the noise of ``D_w`` at that
scale (white noise ``sigma sqrt(2/w)``, or what the trace's own second differences of
``w``-sample means show where the noise is correlated) and three times the typical
stick rise, so smooth sliding, whose descent is as slow as its rise, has no slips.
Slips are steps: their count holds from one scale to the next while noise events come
and go. The detection scale is the one whose count holds and is largest, among the
scales whose larger drops span half the force range; without such a scale, the finest
of those. Nothing assumes that slips are one lattice spacing apart.

Between slips lie stick segments. Each gets a robust quadratic fit (one pass of
outlier rejection at 4 sigma) and a robust straight-line fit of its rising part. The
slip position inside its pixel follows from pixel averaging: the force integral over
the pixels between two segments must equal that of the pre-slip branch up to the slip
and the post-slip branch after it. That gives the force just before (``F_slip``) and
after (``F_after``) each slip free of the pixel-averaging bias.

On a coarse line (fewer than ``FINE_CYCLE`` samples per slip found), a slip averaged
over two pixels may stay below ``D_w``'s threshold, and two sticks then merge into one.
:func:`split_events` looks inside each stick for such a slip with a step statistic that
sees the whole fall however the pixels split it (the estimator uses it to refine lines
it answers).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from stickslip.robust import mad_sigma, median, percentile, white_sigma

MIN_FIT_SAMPLES = 3  # straight line
MIN_QUAD_SAMPLES = 8  # quadratic (end values and peak)
NOISE_SIGMAS = 5.0  # detection threshold on D_w in units of its noise
RISE_FACTOR = 2.0  # ... and in units of the median |D_w| (typical stick rise)
OUTLIER_SIGMAS = 4.0
SPIKE_FACTOR = 2.0  # a spike stands out of its neighbours by this times their difference
STICK_NOISE_RATIO = 0.7  # stick-only noise below this fraction of the overall: slips inflated it
CLIP_SIGMAS = 3.5  # second differences beyond this (in MAD units) are slips, not noise
DEPTH_QUANTILE = 75.0  # depth percentile of the events that must reach half the force range
BEND_FRACTION = 0.15  # guard-pixel deficit, in units of the fitted rise, that flags a bend
BLOCKS_PER_CYCLE = 8  # the noise of D_w is measured on w-blocks only up to cycle / this
FINE_CYCLE = 128  # ... on lines of fewer samples per cycle; finer ones on every w-block
COARSE_CYCLE = 16  # lines of fewer samples per cycle may take their slips from the cycles
COARSE_DROP_SIGMAS = 5.0  # ... if the drops stand this far above the sticks' noise
COARSE_ASYMMETRY = 1.4  # ... and the steepest fall beats the stick's steepest rise so
SPLIT_HALF = 3  # samples each side of the step statistic that looks for missed slips
SPLIT_SIGMAS = 5.0  # ... a missed slip's detrended step, in units of its noise
SPLIT_RAW_SIGMAS = 3.0  # ... and its raw (not detrended) fall: a flat top has none
SPLIT_DROP_FRACTION = 0.3  # ... and at least this fraction of the found slips' step

# columns of the per-segment table returned by `analyse_segments`
SEG_START, SEG_END, SEG_SLOPE, SEG_F_LO, SEG_F_HI, SEG_NFIT = 0, 1, 2, 3, 4, 5
SEG_C0, SEG_C1, SEG_C2, SEG_XREF, SEG_PEAK = 6, 7, 8, 9, 10
SEG_TAN_SLOPE, SEG_TAN_F = 11, 12  # the quadratic's tangent at the stick's start
N_SEG_COLS = 13
# columns of the per-slip table
SLIP_X, SLIP_F, SLIP_F_AFTER, SLIP_PEAK, SLIP_CENTRE = 0, 1, 2, 3, 4
N_SLIP_COLS = 5


@njit(cache=True, error_model="numpy")
def _clipped_sigma(d2: np.ndarray) -> float:
    """Standard deviation of white noise from its second differences ``d2`` (``6 s^2``).

    The MAD breaks down where slips make a large share of ``d2`` (a few samples per
    slip): values beyond ``CLIP_SIGMAS`` and their neighbours, which share samples with
    them, are left out and the MAD taken again, twice.
    """
    if d2.size == 0:
        return 0.0
    s = mad_sigma(d2)
    keep = np.ones(d2.size, dtype=np.bool_)
    for _ in range(2):
        cut = CLIP_SIGMAS * s
        if not cut > 0:
            break
        keep[:] = True
        for i in range(d2.size):
            if abs(d2[i]) > cut:
                keep[max(i - 1, 0) : i + 2] = False
        if keep.sum() < max(8, d2.size // 4):
            break
        s_kept = mad_sigma(d2[keep])
        if not s_kept > 0:  # coarse digitisation: the kept values may all be equal
            break
        s = s_kept
    return s / np.sqrt(6.0)


@njit(cache=True, error_model="numpy")
def noise_sigma(F: np.ndarray, s_all: float = -1.0) -> float:
    """White-noise standard deviation per sample from second differences (robust).

    With a few samples per slip, most second differences touch a slip and no robust
    statistic of all of them is noise. The samples around the steepest drops (steps
    below ``-RISE_FACTOR median|dF|``, slips or not) are then left out: if what remains
    is clearly quieter (``STICK_NOISE_RATIO``), slips inflated the first figure.
    ``s_all``: :func:`white_sigma` of ``F`` where the caller has it (negative: computed).
    """
    n = F.size
    if n < 3:
        return 0.0
    if s_all < 0:
        s_all = white_sigma(F)
    d1 = F[1:] - F[:-1]
    cut = -RISE_FACTOR * median(np.abs(d1))
    if not cut < 0:  # coarse digitisation: most steps are zero, nothing stands out
        return s_all
    keep = np.ones(n - 2, dtype=np.bool_)
    for i in range(n - 1):
        if d1[i] < cut:  # d2[j] reads samples j..j+2: those touching i or i + 1
            keep[max(i - 2, 0) : min(i + 2, n - 2)] = False
    if keep.sum() < 8:
        return s_all
    d2 = F[2:] - 2.0 * F[1:-1] + F[:-2]  # only here: the early returns need none
    s_stick = _clipped_sigma(d2[keep])
    return s_stick if s_stick < STICK_NOISE_RATIO * s_all else s_all


@njit(cache=True, error_model="numpy")
def _scale_noise(C: np.ndarray, w: int) -> float:
    """Standard deviation of ``D_w`` that noise alone gives, measured at scale ``w``.

    Second differences of consecutive ``w``-sample means (blind to the stick's linear
    rise) hold white, 1/f, filtered or interpolated noise as it is at that scale; white
    noise alone gives ``sigma sqrt(2/w)``. O(n/w) work.
    """
    m = (C.size - 1) // w
    if m < 8:
        return 0.0
    b = np.empty(m)
    for j in range(m):
        b[j] = (C[(j + 1) * w] - C[j * w]) / w
    return _clipped_sigma(b[2:] - 2.0 * b[1:-1] + b[:-2]) * np.sqrt(2.0)


@njit(cache=True, error_model="numpy")
def _despike(F: np.ndarray) -> np.ndarray:
    """Replace isolated one-sample spikes (whose return looks like a slip) by the mean
    of their neighbours.

    A spike leaves its two neighbours close to each other: the sample must stand out on
    the same side of both by more than ``SPIKE_FACTOR`` times their difference. The peak
    sample of a coarse sawtooth, whose neighbours differ by a whole drop, is kept (a
    3-point median cuts every peak of a trace with a few samples per slip).
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
def _window_diff(C: np.ndarray, w: int) -> np.ndarray:
    """``D[i] = mean(G[i+1..i+w]) - mean(G[i-w+1..i])`` from ``C = _cumsum0(G)``; NaN
    where undefined."""
    n = C.size - 1
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
    return percentile(r, 95.0) - percentile(r, 5.0) if n > 1 else 0.0


@njit(cache=True, error_model="numpy")
def _cumsum0(G: np.ndarray) -> np.ndarray:
    """``C[i] = sum(G[:i])`` (length ``n + 1``): any window mean in O(1)."""
    C = np.zeros(G.size + 1)
    for i in range(G.size):
        C[i + 1] = C[i] + G[i]
    return C


@njit(cache=True, error_model="numpy")
def _scale_noise_memo(C: np.ndarray, w: int, memo: np.ndarray) -> float:
    """:func:`_scale_noise` at a power-of-two ``w``, computed once per line: ``memo[j]``
    holds it for ``w = 2**j`` (NaN until computed). Every coarser detection scale reads
    the noise at the same block size, ``w_noise``."""
    j = 0
    while (1 << j) < w:
        j += 1
    if np.isnan(memo[j]):
        memo[j] = _scale_noise(C, w)
    return memo[j]


@njit(cache=True, error_model="numpy")
def _scale_events(G: np.ndarray, C: np.ndarray, w: int, sigma: float, w_noise: int,
                  buf: np.ndarray, memo: np.ndarray) -> int:  # fmt: skip
    """Drops of ``D_w`` below ``-max(noise, RISE_FACTOR median|D_w|)`` into ``buf``.

    Correlated noise (1/f, filtered, interpolated) is larger at scale ``w`` than white
    noise: it is measured on ``w``-blocks up to ``w_noise`` samples (blocks that resolve
    a stick-slip cycle, whose second differences are mostly noise), and extrapolated as
    white beyond (blocks of a quarter cycle are all signal: measured there, the "noise"
    would be the sawtooth itself); ``w_noise = -1``: on ``w``-blocks (finely sampled
    lines); 0: white noise only. ``memo``: :func:`_scale_noise_memo`'s, one per line.
    """
    n = G.size
    D = _window_diff(C, w)
    Dv = D[w - 1 : n - w]
    floor = RISE_FACTOR * median(np.abs(Dv)) if Dv.size > 0 else 0.0
    noise_w = sigma * np.sqrt(2.0 / w)
    if w_noise >= 1:
        wm = min(w, w_noise)
        noise_w = max(noise_w, _scale_noise_memo(C, wm, memo) * np.sqrt(wm / w))
    elif w_noise < 0:  # every block size measures the noise
        noise_w = max(noise_w, _scale_noise_memo(C, w, memo))
    return _events(D, max(NOISE_SIGMAS * noise_w, floor), buf)


@njit(cache=True, error_model="numpy")
def _schmitt_on(r: np.ndarray, out: np.ndarray) -> int:
    """Falls of ``r`` from above its 75th to below its 25th percentile (a Schmitt
    trigger, blind to noise smaller than half the range of ``r``).

    Rows of ``out``: the last sample at or above the 75th percentile before the fall and
    the first at or below the 25th. Returns the number of falls.
    """
    n = r.size
    if n < 4:
        return 0
    lo = percentile(r, 25.0)
    hi = percentile(r, 75.0)
    high = r[0] >= hi
    last_high = 0
    k = 0
    for i in range(1, n):
        if r[i] >= hi:
            high = True
            last_high = i
        elif high and r[i] <= lo:
            out[k, 0] = last_high
            out[k, 1] = i
            k += 1
            high = False
    return k


@njit(cache=True, error_model="numpy")
def _schmitt_falls(x: np.ndarray, G: np.ndarray, out: np.ndarray) -> int:
    """Falls of the linearly detrended force through its quartiles (:func:`_schmitt_on`)."""
    if G.size < 4:
        return 0
    xm = np.mean(x)
    Gm = np.mean(G)
    sxx = np.sum((x - xm) ** 2)
    b = np.sum((x - xm) * (G - Gm)) / sxx if sxx > 0 else 0.0
    return _schmitt_on(G - b * (x - xm), out)


@njit(cache=True, error_model="numpy")
def _local_falls(G: np.ndarray, out: np.ndarray) -> int:
    """Falls of the force minus its running mean over ``2 COARSE_CYCLE + 1`` samples
    through its quartiles: on a line of a few samples per cycle that mean holds two
    cycles or more, so it follows a drift that a straight line does not (a drift
    larger than the sawtooth hides most cycles from :func:`_schmitt_falls`)."""
    n = G.size
    h = COARSE_CYCLE
    C = _cumsum0(G)
    r = np.empty(n)
    for i in range(n):
        a = max(0, i - h)
        b = min(n, i + h + 1)
        r[i] = G[i] - (C[b] - C[a]) / (b - a)
    return _schmitt_on(r, out)


@njit(cache=True, error_model="numpy")
def _cycles(x: np.ndarray, G: np.ndarray) -> int:
    """Stick-slip cycles of a trace: the Schmitt trigger's falls (:func:`_schmitt_falls`)."""
    return _schmitt_falls(x, G, np.empty((G.size, 2), dtype=np.int64))


@njit(cache=True, error_model="numpy")
def _coarse_events(x: np.ndarray, G: np.ndarray, local: bool = False
                   ) -> tuple[np.ndarray, float]:  # fmt: skip
    """Slips of a line with a few samples per cycle, from its Schmitt-trigger falls.

    With fewer than ``COARSE_CYCLE`` samples per cycle, every second difference touches
    a slip or the stick's bend, so no differencing measures the noise, and a slip
    split over two pixels makes two steps that need not stand out alone. Here each fall
    of the Schmitt trigger holds one slip: the run of falling steps around its steepest
    step. The noise is what straight lines through the sticks between them leave.
    The slips are accepted only if they look like slips: each drop at least
    ``COARSE_DROP_SIGMAS`` times that noise and ``RISE_FACTOR`` times the typical stick
    step (a slip split over pixels drops that much over its run), runs shorter than the
    sticks, sticks that rise, and a fall steeper (``COARSE_ASYMMETRY``) than the sticks'
    steepest rise (a sine or a square wave rises as steeply as it falls). Else no
    events (noise, a reversed sawtooth, a random walk, a sine). ``local``: the falls
    come from :func:`_local_falls` (a drift the straight detrend does not follow), and
    the line must hold fewer than ``COARSE_CYCLE`` samples per fall.

    Returns
    -------
    events : ndarray (n_events, 4)
        As :func:`detect_slips` at window 1 (``depth``: the drop over the run).
    sigma : float
        Noise per sample from the stick fits (NaN where there are no events).
    """
    n = G.size
    falls = np.empty((n, 2), dtype=np.int64)
    k = _local_falls(G, falls) if local else _schmitt_falls(x, G, falls)
    none = np.empty((0, 4))
    if k < 3 or (local and n >= COARSE_CYCLE * k):
        return none, np.nan
    ev = np.empty((k, 4))
    d = G[1:] - G[:-1]
    for j in range(k):
        a, b = falls[j, 0], falls[j, 1]
        c = a
        for i in range(a, b):
            if d[i] < d[c]:
                c = i
        first, last = c, c
        while first > a and d[first - 1] < 0:
            first -= 1
        while last < b - 1 and d[last + 1] < 0:
            last += 1
        ev[j, 0] = first
        ev[j, 1] = last
        ev[j, 2] = c
        ev[j, 3] = G[first] - G[last + 1]
    # sticks between the runs: from each slip's bottom to the next one's top
    ss = 0.0
    dof = 0
    slopes = np.empty(k - 1)
    stick_len = np.empty(k - 1)
    jump = np.empty(k - 1)
    steps = np.empty(n)
    ns = 0
    for j in range(k - 1):
        lo, hi = int(ev[j, 1]) + 1, int(ev[j + 1, 0])
        stick_len[j] = hi - lo + 1
        jump[j] = np.max(d[lo:hi]) if hi > lo else 0.0
        slopes[j] = np.nan
        if hi - lo + 1 >= 3:
            c0, c1, _ = _polyfit(x, G, lo, hi, x[lo], np.int64(1),
                                 np.ones(hi - lo + 1, np.bool_))  # fmt: skip
            slopes[j] = c1
            ss += np.sum((G[lo : hi + 1] - c0 - c1 * (x[lo : hi + 1] - x[lo])) ** 2)
            dof += hi - lo - 1
        for i in range(lo, hi):
            steps[ns] = abs(d[i])
            ns += 1
    if dof < 6 or ns == 0:
        return none, np.nan
    sigma = np.sqrt(ss / dof)
    run = ev[:, 1] - ev[:, 0] + 1
    good = slopes[~np.isnan(slopes)]
    drop = median(ev[:, 3].copy())  # contiguous: one compiled median for every caller
    steep = np.empty(k)
    for j in range(k):
        steep[j] = -d[int(ev[j, 2])]
    if (drop >= COARSE_DROP_SIGMAS * sigma
            and drop >= RISE_FACTOR * median(steps[:ns])
            and median(run) < median(stick_len)
            and median(steep) >= COARSE_ASYMMETRY * median(jump)
            and good.size >= 2 and median(good) > 0):  # fmt: skip
        return ev, sigma
    return none, np.nan


@njit(cache=True, error_model="numpy")
def _stable(a: int, b: int) -> bool:
    """Event counts at two successive scales that agree (within 10 %)."""
    return a > 0 and abs(a - b) <= max(1, int(0.1 * a + 0.5))


@njit(cache=True, error_model="numpy")
def detect_slips(x: np.ndarray, F: np.ndarray, s_all: float = -1.0
                 ) -> tuple[np.ndarray, int, float, float]:  # fmt: skip
    """Find slip events (``s_all``: :func:`white_sigma` of ``F`` if the caller has it).

    Returns
    -------
    Slips are steps: at scales from a slip's duration up to a fraction of the stick
    they keep their count, while noise events come and go. Of the scales whose larger
    events span half the force range (``DEPTH_QUANTILE``), the one whose count holds at
    the next scale and is largest wins (noise can hide small slips at the finest
    scale); without such a scale, the finest one whose events span the range.

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
    sigma = noise_sigma(F, s_all)
    span = _force_range(x, G)
    C = _cumsum0(G)
    buf = np.empty((n, 4))
    memo = np.full(64, np.nan)
    # blocks of up to 1/BLOCKS_PER_CYCLE of a cycle measure the noise (``_scale_events``)
    w_noise = 0
    # cycles: the Schmitt trigger's count, or the drops at the two finest scales above
    # white noise where drift or a modulated barrier hide cycles from it
    nc = _cycles(x, G)
    for w in range(1, 3):
        nc = max(nc, _scale_events(G, C, w, sigma, np.int64(0), buf, memo))
    cyc = n / max(nc, 1)
    if cyc >= FINE_CYCLE:
        # finely sampled: blocks at every window size stay far below a cycle, and their
        # noise keeps a smooth (eta < 1) fall, steep at the scale of a block, from
        # passing for a slip
        w_noise = -1
    elif cyc >= BLOCKS_PER_CYCLE:
        w_noise = 1
        while 2 * w_noise * BLOCKS_PER_CYCLE <= cyc:
            w_noise *= 2
    ws = np.empty(64, dtype=np.int64)
    counts = np.zeros(64, dtype=np.int64)
    deep = np.zeros(64, dtype=np.bool_)
    ns = 0
    w = np.int64(1)
    best = -1
    while w <= max(1, n // 32) and ns < 64:
        ws[ns] = w
        counts[ns] = _scale_events(G, C, w, sigma, w_noise, buf, memo)
        k = counts[ns]
        # the larger slips, not all (a multiple-slip trace mixes sizes), span the range
        deep[ns] = k > 0 and percentile(buf[:k, 3].copy(), DEPTH_QUANTILE) >= 0.5 * span
        if ns > 0 and deep[ns - 1] and _stable(counts[ns - 1], k):
            if best < 0 or counts[ns - 1] > counts[best]:
                best = ns - 1
        ns += 1
        if best >= 0 and k < counts[best]:
            break  # slips merge at coarser scales: no larger count follows
        w *= 2
    if best < 0:  # no scale where the count holds (coarse or short traces): the first deep one
        for j in range(ns):
            if deep[j]:
                best = j
                break
    k = _scale_events(G, C, ws[best], sigma, w_noise, buf, memo) if best >= 0 else 0
    if cyc < COARSE_CYCLE and 2 * k < nc:
        # a few samples per cycle and most cycles without a slip: the noise estimate
        # read the sticks' bends as noise, or slips split over pixels hid below it.
        # The raw force: a slip averaged into one pixel leaves the top's neighbours
        # close, so at a few samples per slip the despiker cuts the tops as spikes.
        ce, sc = _coarse_events(x, F, np.bool_(False))
        if ce.shape[0] > 0:
            return ce, 1, sc, span
    if k < 3:
        # no stick-slip found: a drift larger than the sawtooth may have hidden the
        # cycles of a coarse line from the straight detrend
        ce, sc = _coarse_events(x, F, np.bool_(True))
        if ce.shape[0] > 0:
            return ce, 1, sc, span
    if best < 0:
        return np.empty((0, 4)), 1, sigma, span
    return buf[:k].copy(), int(ws[best]), sigma, span


@njit(cache=True, error_model="numpy")
def _after_slip(events: np.ndarray, k: int, w: int) -> int:
    """The first sample after slip ``k``'s run of ``D_w`` and its window: where the next
    stick starts (before its guard sample). A slip smeared by the detector's bandwidth
    (a run longer than the window) relaxes after its steepest part for as long again."""
    first, last = int(events[k, 0]), int(events[k, 1])
    return last + w + max(0, last - first + 1 - w)


@njit(cache=True, error_model="numpy")
def _split_sticks(F: np.ndarray, events: np.ndarray, w: int, sigma: float) -> np.ndarray:
    """Slips that the detection missed inside the stick segments of a coarse line.

    With a few samples per slip, a slip split over two pixels makes two steps that
    need not stand out of ``D_w``'s noise, and a multiple-slip line mixes slips of one
    and two lattice spacings: the detection may keep the large ones only, and a missed
    slip merges two sticks into one, whose slope is then far too low. Inside each
    segment the step ``S(i) = mean(F[i+2..i+m+1]) - mean(F[i-m+1..i]) - s (m + 1)``
    (``m = SPLIT_HALF``; pixel ``i + 1`` may hold the slip; ``s`` the sticks' rise per
    sample, the median first difference away from the slips) has the noise
    ``sigma sqrt(2/m)`` and sees a whole slip however the pixels split it. A missed
    slip must fall by ``SPLIT_SIGMAS`` of that noise after detrending, by
    ``SPLIT_RAW_SIGMAS`` before (a stick that bends over to a flat top falls only
    after detrending) and by ``SPLIT_DROP_FRACTION`` of the found slips' median step.
    Returns the events with the new ones (rows as :func:`detect_slips`), sorted.
    """
    n = F.size
    ne = events.shape[0]
    m = SPLIT_HALF
    if ne < 2 or not sigma > 0 or n < 4 * m:
        return events
    d = F[1:] - F[:-1]
    away = np.ones(n - 1, dtype=np.bool_)
    for k in range(ne):
        away[max(int(events[k, 0]) - w, 0) : min(int(events[k, 1]) + w + 1, n - 1)] = False
    if away.sum() < 8:
        return events
    s = median(d[away])
    if not s > 0:
        return events
    C = _cumsum0(F)
    S = np.full(n, np.nan)
    for i in range(m - 1, n - m - 1):
        S[i] = (C[i + m + 2] - C[i + 2] - C[i + 1] + C[i - m + 1]) / m - s * (m + 1)
    # the found slips' step (the pixel split decides which of two positions sees it)
    hd = np.empty(ne)
    for k in range(ne):
        c = int(events[k, 2])
        hd[k] = np.nan
        for i in (c - 1, c):
            if 0 <= i < n and not np.isnan(S[i]) and not (S[i] >= hd[k]):
                hd[k] = S[i]
    hv = hd[~np.isnan(hd)]
    if hv.size < 2:
        return events
    se = sigma * np.sqrt(2.0 / m)
    thr = max(SPLIT_SIGMAS * se, -SPLIT_DROP_FRACTION * median(hv))
    extra = np.empty((n, 4))
    nx = 0
    start = 0
    # candidates of the current stick (all False between sticks: one array for the line,
    # not one per stick, which would cost samples x slips on a long coarse line)
    free = np.zeros(n, dtype=np.bool_)
    for k in range(ne + 1):
        end = int(events[k, 0]) - (w - 1) - 1 if k < ne else n - 1
        lo, hi = start + 1, end - 1  # one guard sample each side, as the stick fits
        for i in range(lo + m - 1, hi - m):
            free[i] = not np.isnan(S[i])
        while True:
            best = -1
            for i in range(lo, hi + 1):
                if free[i] and (best < 0 or S[i] < S[best]):
                    best = i
            if best < 0 or not (S[best] < -thr and S[best] + s * (m + 1) < -SPLIT_RAW_SIGMAS * se):
                break
            i = best
            extra[nx, 0] = i + 1
            extra[nx, 1] = i + 1
            extra[nx, 2] = i if d[i] < d[i + 1] else i + 1
            extra[nx, 3] = -S[i]
            nx += 1
            free[max(i - m - 1, 0) : min(i + m + 2, n)] = False
        if hi >= lo:
            free[lo : hi + 1] = False
        if k < ne:
            start = _after_slip(events, k, w)
    if nx == 0:
        return events
    out = np.empty((ne + nx, 4))
    out[:ne] = events
    out[ne:] = extra[:nx]
    return out[np.argsort(out[:, 0])]


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
def _fit_segment(x: np.ndarray, F: np.ndarray, lo: int, hi: int, sigma: float,
                 trim: int, row: np.ndarray) -> None:  # fmt: skip
    """Fill one row of the segment table (NaN slope if too short).

    The slope is fitted on the rising part without its last ``trim`` samples: before a
    slip the branch bends over (vertical tangent at the T = 0 instability), which a
    straight line does not follow. The row also holds the segment quadratic's tangent
    at the stick's start and the force there: precursor softening bends a stick from
    its bottom up but leaves its slope at the bottom (PHYSICS.md's K is the stiffness
    before softening), which no straight line over the stick sees.
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
    # the slope is fitted on the rising part only (up to the quadratic's vertex)
    hi_r = hi
    if c2 < 0:
        xv = xref - c1 / (2.0 * c2)
        while hi_r > lo and x[hi_r] > xv:
            hi_r -= 1
    if hi_r - lo + 1 < MIN_FIT_SAMPLES:
        hi_r = hi
    if hi_r - trim - lo + 1 >= MIN_FIT_SAMPLES:
        hi_r = min(hi_r, hi - trim)
    b0, b1, _ = _robust_fit(x, F, lo, hi_r, xref, np.int64(1), sigma,
                            mask[: hi_r - lo + 1].copy())  # fmt: skip
    row[SEG_SLOPE] = b1
    row[SEG_F_LO] = b0 + b1 * (x[lo] - xref)
    row[SEG_F_HI] = b0 + b1 * (x[hi_r] - xref)
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
    out[SLIP_PEAK] = peak


@njit(cache=True, error_model="numpy")
def split_events(F: np.ndarray, events: np.ndarray, w: int, sigma: float) -> np.ndarray:
    """The events with the slips the detection missed inside the sticks of a coarse line
    (fewer than ``FINE_CYCLE`` samples per slip found; :func:`_split_sticks`); the same
    rows where it finds none or the line is finely sampled."""
    if F.size < FINE_CYCLE * (events.shape[0] + 1):
        return _split_sticks(F, events, w, sigma)
    return events


@njit(cache=True, error_model="numpy")
def _rising_run(F: np.ndarray, lo: int, hi: int, lo_min: int, hi_max: int) -> tuple[int, int]:
    """``lo..hi`` grown within ``lo_min..hi_max`` while the samples beside it continue
    the stick's rise (a partly averaged pixel at a slip breaks it)."""
    while hi < hi_max and F[hi + 1] > F[hi]:
        hi += 1
    while lo > lo_min and F[lo - 1] < F[lo]:
        lo -= 1
    return lo, hi


@njit(cache=True, error_model="numpy")
def fit_segments(x: np.ndarray, F: np.ndarray, events: np.ndarray, w: int, tol: float
                 ) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """The stick fits between given slip events (:func:`analyse_segments`' tables);
    ``tol``: the fits' outlier and bend tolerance (:func:`detect_for_fits`)."""
    n = F.size
    ne = events.shape[0]
    segs = np.full((ne + 1, N_SEG_COLS), np.nan)
    slips = np.full((ne, N_SLIP_COLS), np.nan)
    coarse = n < COARSE_CYCLE * (ne + 1)
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
        if coarse and hi - lo + 1 < MIN_FIT_SAMPLES and hi >= lo:
            # a few samples per slip: the guards (and a slip split over two pixels,
            # which is not a smeared one) leave too little to fit; take back the
            # samples beside it that still rise along the stick
            raw_lo = int(events[k - 1, 1]) + w if k > 0 else 0
            lo, hi = _rising_run(F, lo, hi, raw_lo, end)
        _fit_segment(x, F, lo, hi, tol, 1 if k < ne else 0, segs[k])
        if k < ne:
            start = _after_slip(events, k, w)
    for k in range(ne):
        slips[k, SLIP_CENTRE] = events[k, 2]
        pre, post = segs[k], segs[k + 1]
        if np.isnan(pre[SEG_C0]) or np.isnan(post[SEG_C0]):
            continue
        if int(post[SEG_START]) <= int(pre[SEG_END]):
            continue
        _locate_slip(x, F, pre, post, tol, slips[k])
    return segs, slips


@njit(cache=True, error_model="numpy")
def detect_for_fits(x: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, int, float, float]:
    """:func:`detect_slips`' events, window and noise, and the stick fits' tolerance
    (:func:`fit_segments`' ``tol``): the scatter of all second differences
    (:func:`white_sigma`), sharp corners of the branch included, not the sticks' noise
    alone; computed once for the detection's noise estimate and the fits."""
    tol = white_sigma(F)
    events, w, sigma, _ = detect_slips(x, F, tol)
    return events, w, sigma, tol


@njit(cache=True, error_model="numpy")
def analyse_segments(x: np.ndarray, F: np.ndarray, split: bool = False
                     ) -> tuple[np.ndarray, np.ndarray, int, float]:  # fmt: skip
    """Detect slips and fit the stick segments between them (``split``: and split the
    sticks of a coarse line at the slips the detection missed, :func:`split_events`).

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
        Noise per sample (:func:`noise_sigma`).
    """
    events, w, sigma, tol = detect_for_fits(x, F)
    if split:
        events = split_events(F, events, w, sigma)
    segs, slips = fit_segments(x, F, events, w, tol)
    return segs, slips, w, sigma


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
