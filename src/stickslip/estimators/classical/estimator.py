"""Classical stick-slip estimator: slips, stick slopes, peak force, PT inversion.

The experimentalists' automated algorithm, made robust and physics-consistent:

1. the line's cycles by one segmentation (:mod:`stickslip.estimators.segmentation`:
   a piecewise-linear sawtooth on a slow baseline, fitted by penalised least squares),
   which also gives the regime (fast falls after slow rises, or not) and the baseline,
   taken off before the sticks are fitted;
2. per stick a robust straight-line fit of its straight part (``k_exp`` is the median
   over sticks) and per slip the peak force, free of pixel averaging
   (:mod:`stickslip.estimators.classical.slips`);
3. ``F_max`` and ``K`` from the mean peak and the slopes, inverting the PT relations
   along the whole rising branch with the thermal-activation correction of
   :mod:`stickslip.estimators.classical.pt_inversion`; ``U0 = a F_max/pi``,
   ``eta = 2 pi F_max/(a K)``;
4. slip sizes in lattice spacings from the tip jump ``drop/K`` plus the tip's advance
   during a stick, the regime, and the spread over slips (``*_std``: 1.4826 MAD of the
   per-slip values; for ``F_mean`` the spread of the per-cycle mean force).

Quality flags (``quality``): ``ok``; ``too few slips``; ``smooth sliding`` (the force
cycles, but falls no faster than it rises: smooth sliding, or a slider that oscillates
without sticking); ``not stick-slip`` (the force jumps up, as well as or instead of
down); ``too noisy`` (nothing stands out of the noise, or the noise is a large fraction
of the drops); ``inconsistent slopes`` (no positive K fits the slopes and the peak, or the slopes of
fewer than two sticks do);
``sticks disagree`` (the sticks' own K's scatter by more than :data:`MAX_K_SPREAD` of
the line's K: no one spring fits them; or the slip levels show a baseline left in the
sticks, :data:`LEVEL_AGREEMENT`); ``two regimes`` (the sticks' slope changes part-way:
a tip that changed); ``alternating slips`` (slips of two sizes take turns: more than
one contact). Every flag but ``ok`` comes without K.

Both directions of a map line (a trace/retrace pair,
:func:`~stickslip.estimators.pairs.find_pairs`) are read less the offset of the force's
zero that they share (:func:`~stickslip.estimators.pairs.offset_free_pairs`: a tilt,
curvature or crosstalk that does not reverse with the scan), which the inversion would
read as another F_max; their ``F_mean_nN`` stays the row's own mean, so that the pair's
``offset_pair_nN`` still says how large the offset was. A lone line keeps its offset:
one line cannot tell it from friction.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from numba import njit

import stickslip.estimators.classical.slips as sl
import stickslip.estimators.segmentation as sg
from stickslip.compiled import chunk_bounds, made_up_line, run_chunks
from stickslip.conditions import GRAPHITE, GRAPHITE_LATTICE_NM, Conditions, Reference
from stickslip.estimators.base import TraceEstimator, in_volts
from stickslip.estimators.classical.pt_inversion import invert, k_from_segment, median_k
from stickslip.estimators.pairs import offset_free_pairs
from stickslip.estimators.table import TWO_REGIMES as TWO_REGIMES_QUALITY
from stickslip.robust import mad_sigma, median, percentile
from stickslip.units import EV_TO_NN_NM

PAPER_MASS_KG = 1e-12
PAPER_DAMPING_PER_S = 1e7
MIN_SLIPS = 3
NOISE_TO_DROP_MAX = 0.25  # noise per sample / median drop above which a trace is too noisy
# Precursor softening (a stick that bends from its bottom up) lowers the straight-line
# slopes; the sticks' tangents at their start do not see it. A line takes K from the
# tangents where they give a clearly stiffer K than the lines (softening: by
# TANGENT_GAIN, beyond TANGENT_SIGMAS standard errors of the tangents) and its eta is
# high enough that the PT branch is nearly straight at its start; at low eta the branch
# bends from the start, which a quadratic's tangent does not follow (K then 14 % high).
TANGENT_MIN_ETA = 3.0
TANGENT_GAIN = 1.05
TANGENT_SIGMAS = 3.0
# A stick reports a tangent only where its quadratic bends over (c2 < 0). On short
# noisy sticks (20 samples per lattice spacing) the curvature's sign is noise, and the
# sticks that report are those whose noise steepened their start (K 1.26-1.42x at
# eta 13): the tangents count only where more than this fraction of the sticks long
# enough for a quadratic bend over (a majority, chosen a priori, not tuned).
TANGENT_MAJORITY = 0.5
# A line whose sticks' own K's scatter (1.4826 MAD) by more than this fraction of its K
# has no one spring: drift, gain, telegraph steps or missed slips bend the sticks apart,
# and the median K of such lines was off by up to 2x. Chosen on the tuning sets
# (benchmarks/classical_lab.py --tune): the smallest value that refuses at most 5 % more
# of any set there.
MAX_K_SPREAD = 0.8
# Two readings of the spring: the sticks' slopes, and the same slopes less the trend of
# the slip levels beside each stick (:func:`slips.level_slopes`: stationary slips keep
# their levels, so a trend is baseline the line's baseline left in). Where their medians
# differ by more than this fraction of k_exp and by more than their standard errors, the
# baseline is not resolved at the scale of a cycle (a few cycles under a baseline that
# wanders by several drops read k at 1.3-8x the spring) and K is refused. A pure number:
# the mark beyond which an answer misleads (the stress corpus's 20 %). A line with fewer
# than two sticks between fitted slips cannot be checked and is refused too.
LEVEL_AGREEMENT = 0.2

# output fields of the kernel
(F_MEAN, F_MEAN_STD, U0, U0_STD, K_, K_STD, ETA, ETA_STD, K_EXP, K_EXP_STD, F_PEAK,
 F_PEAK_STD, N_SLIPS, FRAC_MULTIPLE, NOISE, WINDOW, STATUS, R_DOWN,
 R_UP) = range(19)  # fmt: skip
N_FIELDS = 19

QUALITY = {
    0: "ok",
    1: "too few slips",
    2: "smooth sliding",
    3: "too noisy",
    4: "inconsistent slopes",
    5: "sticks disagree",
    6: "not stick-slip",
    7: TWO_REGIMES_QUALITY,
    8: "alternating slips",
}
#: The flag of a line whose slips are stick-slip but whose sticks fit no one spring: a
#: refusal of K, not a sign that the line is not stick-slip.
STICKS_DISAGREE = 5
#: The flag of a line whose force jumps up (as well as, or instead of, down).
NOT_STICK_SLIP = 6
#: The flag of a line whose sticks change slope part-way (two springs: a tip that
#: changed; :func:`~stickslip.estimators.segmentation.slope_change`).
TWO_REGIMES = 7
#: The flag of a line whose slips take turns at two sizes (two contacts in different
#: registry; :func:`~stickslip.estimators.segmentation.alternation`).
ALTERNATING = 8
#: The flags of lines that are stick-slip but have no one spring: K refused.
K_REFUSED = (STICKS_DISAGREE, TWO_REGIMES, ALTERNATING)
REGIMES = ("single slip", "multiple slip", "stick-slip", "smooth", "not stick-slip")


@njit(cache=True, error_model="numpy")
def _spread(v: np.ndarray) -> float:
    vals = v[~np.isnan(v)]
    return mad_sigma(vals) if vals.size > 1 else np.nan


@njit(cache=True, error_model="numpy")
def _median_se(v: np.ndarray) -> float:
    """Standard error of the median of ``v`` (NaN left out): its robust spread times
    1.25 (about sqrt(pi/2), the median's efficiency at normal scatter) over sqrt(n)."""
    n = np.sum(~np.isnan(v))
    return 1.25 * _spread(v) / np.sqrt(n) if n > 1 else np.nan


# inlined into its one caller: numba optimises a kernel's LLVM module again with every
# compiled callee linked in, so a separately compiled wrapper cost 2.6 s of the first run
@njit(cache=True, error_model="numpy", inline="always")
def _estimate_one(x: np.ndarray, F: np.ndarray, a: float, T: float, v: float,
                  mass_kg: float, gamma: float, out: np.ndarray) -> None:  # fmt: skip
    # the sticks are fitted on the line less its baseline (zero-mean: <F> is kept)
    G, segs, slp, cycles, block, s_fit, tol = sl.fit_line(x, F)
    _estimate_core(x, F, G, segs, slp, cycles, block, s_fit, tol, a, T, v, mass_kg, gamma, out)


@njit(cache=True, error_model="numpy")
def _estimate_core(x: np.ndarray, F: np.ndarray, G: np.ndarray, segs: np.ndarray,
                   slp: np.ndarray, cycles: np.ndarray, block: int, s_fit: float, tol: float,
                   a: float, T: float, v: float, mass_kg: float, gamma: float,
                   out: np.ndarray) -> None:  # fmt: skip
    """One line's fields from its cycles (:func:`segmentation.find_cycles`) and its stick
    and slip tables (:func:`slips.fit_sticks`, on ``G``, the line less its baseline)."""
    out[:] = np.nan
    out[F_MEAN] = np.mean(F)
    ns = slp.shape[0]
    out[N_SLIPS] = ns
    # noise per sample: the segmentation's own where it ran on samples, else the
    # second differences' (a long line with few slips per sample)
    out[NOISE] = s_fit if block == 1 else tol
    out[WINDOW] = block
    out[FRAC_MULTIPLE] = 0.0
    if ns == 0:
        span = percentile(G, 95.0) - percentile(G, 5.0)
        out[STATUS] = 3 if span < 10.0 * out[NOISE] else 2
        return
    r_down, r_up = sg.cycle_ratios(cycles)
    out[R_DOWN] = r_down
    out[R_UP] = r_up
    if r_up >= sg.STICK_RATIO:
        out[STATUS] = NOT_STICK_SLIP  # the force jumps up (as well as, or not, down)
        return
    if not r_down >= sg.STICK_RATIO:
        out[STATUS] = 2  # rise and fall alike: no sticking
        return
    # spread of the mean force over stick-slip cycles
    if ns >= 2:
        cyc = np.empty(ns - 1)
        for k in range(1, ns):
            c0 = int(cycles[k - 1, sg.CY_VALLEY])
            c1 = int(cycles[k, sg.CY_VALLEY])
            cyc[k - 1] = np.mean(G[c0:c1]) if c1 > c0 else np.nan
        out[F_MEAN_STD] = _spread(cyc)
    if ns < MIN_SLIPS:
        out[STATUS] = 1
        return
    # a refusal carries no numbers: slopes between slips that noise may have made up
    if s_fit > NOISE_TO_DROP_MAX * median(cycles[:ns, sg.CY_DROP]):
        out[STATUS] = 3
        return
    # no one spring: sticks of two slopes (a tip that changed part-way), or slips of two
    # sizes taking turns (two contacts); the median of either mixture is no K
    if sg.slope_change(cycles) > 1.0:
        out[STATUS] = TWO_REGIMES
        return
    if sg.alternation(cycles) > 1.0:
        out[STATUS] = ALTERNATING
        return
    good = ~np.isnan(slp[:, sl.SLIP_F])
    drops = slp[:, sl.SLIP_F] - slp[:, sl.SLIP_F_AFTER]
    kseg = segs[:, sl.SEG_SLOPE]
    segok = kseg > 0
    if good.sum() < MIN_SLIPS - 1 or segok.sum() < 2:
        out[STATUS] = 1  # too few slips between sticks long enough to fit
        return
    out[K_EXP] = median(kseg[segok])
    out[K_EXP_STD] = _spread(kseg[segok])
    # mean peak, outliers (missed or spurious slips) trimmed at 4 sigma
    peaks = slp[good, sl.SLIP_PEAK]
    med = median(peaks)
    sp = mad_sigma(peaks)
    keep = np.abs(peaks - med) <= 4.0 * sp + 1e-12
    F_peak = np.mean(peaks[keep])
    out[F_PEAK] = F_peak
    out[F_PEAK_STD] = _spread(peaks)
    F_after = median(slp[good, sl.SLIP_F_AFTER])
    kv = kseg[segok]
    Kseg = np.empty(kv.size)
    Fmax, K = invert(F_peak, F_after, kv, segs[segok, sl.SEG_F_LO], segs[segok, sl.SEG_F_HI],
                     a, T, v, mass_kg, gamma, Kseg)  # fmt: skip
    if np.isnan(K) or np.isnan(Fmax):
        out[STATUS] = 4
        return
    eta = 2.0 * np.pi * Fmax / (a * K)
    tok = segs[:, sl.SEG_TAN_SLOPE] > 0
    nquad = np.sum(segs[:, sl.SEG_NFIT] >= sl.MIN_QUAD_SAMPLES)
    # only where the segmentation saw each stick as one straight rise: where it found
    # the bend, the straight part below it already holds the slope before softening
    whole = 0
    for k in range(ns + 1):
        whole += (cycles[k, sg.CY_SLOPE_LO] == cycles[k, sg.CY_LO]
                  and cycles[k, sg.CY_SLOPE_HI] == cycles[k, sg.CY_HI])  # fmt: skip
    if (eta >= TANGENT_MIN_ETA and tok.sum() >= 2 and tok.sum() > TANGENT_MAJORITY * nquad
            and whole > TANGENT_MAJORITY * (ns + 1)):  # fmt: skip
        kt = segs[tok, sl.SEG_TAN_SLOPE]
        Ft = segs[tok, sl.SEG_TAN_F]
        # the median in slope space: K = 1/(1/k - c) is skewed, so a median of noisy
        # per-stick K's reads high even without softening
        kt_med = median(kt)
        Ft_med = median(Ft)
        Fmax_t, K_t = invert(F_peak, F_after, np.array([kt_med]), np.array([Ft_med]),
                             np.array([Ft_med]), a, T, v, mass_kg, gamma, np.empty(1))  # fmt: skip
        # switch only if K stays clearly stiffer at the tangents' median minus
        # TANGENT_SIGMAS standard errors (an end tangent is noisier than a line)
        se = _median_se(kt)
        K_lo = k_from_segment(kt_med - TANGENT_SIGMAS * se, Ft_med, Ft_med, Fmax_t, a)
        if K_lo > TANGENT_GAIN * K and not np.isnan(K_t):
            Fmax, K = Fmax_t, K_t
            Kseg = np.empty(kt.size)  # each stick's K at the tangents' F_max, for K_STD
            median_k(kt, Ft, Ft, Fmax, a, Kseg)
            eta = 2.0 * np.pi * Fmax / (a * K)
    if eta < 1.0:  # no PT stick-slip has this peak and slope: the drops are not slips
        out[STATUS] = 2
        return
    # the slip levels' check of the baseline (LEVEL_AGREEMENT)
    kl = sl.level_slopes(segs, slp)
    kl = kl[~np.isnan(kl)]
    se = _median_se(kseg)
    if kl.size < 2 or not se <= LEVEL_AGREEMENT * out[K_EXP]:
        out[STATUS] = STICKS_DISAGREE
        return
    gap = median(kl) - out[K_EXP]
    if abs(gap) > LEVEL_AGREEMENT * out[K_EXP] and abs(gap) > np.hypot(se, _median_se(kl)):
        out[STATUS] = STICKS_DISAGREE  # the slip levels trend: a baseline left in
        return
    k_spread = _spread(Kseg)
    if np.isnan(k_spread):  # one stick at most whose slope fits the peak: no spread, no K
        out[STATUS] = 4
        return
    if k_spread > MAX_K_SPREAD * K:
        out[STATUS] = STICKS_DISAGREE
        return
    scale = Fmax / F_peak  # thermal correction, applied to every slip's peak
    out[U0] = a * Fmax / np.pi / EV_TO_NN_NM
    out[K_] = K
    out[ETA] = eta
    out[U0_STD] = _spread(a * peaks * scale / np.pi / EV_TO_NN_NM)
    out[K_STD] = k_spread
    # per-segment eta: each stick's own K with the mean F_max
    out[ETA_STD] = _spread(2.0 * np.pi * Fmax / (a * Kseg))
    # slip sizes: tip jump drop/K plus the tip's advance during a stick, in units of a
    adv = np.full(ns, np.nan)
    for k in range(1, ns):
        if good[k] and good[k - 1]:
            dX = slp[k, sl.SLIP_X] - slp[k - 1, sl.SLIP_X]
            adv[k] = dX - (slp[k, sl.SLIP_F] - slp[k - 1, sl.SLIP_F_AFTER]) / K
    av = adv[~np.isnan(adv)]
    d_stick = median(av) if av.size > 0 else 0.0
    nmult = 0
    ngood = 0
    for k in range(ns):
        if good[k]:
            ngood += 1
            if np.rint((drops[k] / K + d_stick) / a) >= 2:
                nmult += 1
    out[FRAC_MULTIPLE] = nmult / max(ngood, 1)
    out[STATUS] = 0


@njit(cache=True, nogil=True, error_model="numpy")
def _estimate_batch(xs: np.ndarray, Fs: np.ndarray, offsets: np.ndarray, a: np.ndarray,
                    T: np.ndarray, v: np.ndarray, mass_kg: float, gamma: float,
                    out: np.ndarray) -> None:  # fmt: skip
    # serial and without the GIL: estimate_array runs one chunk of lines per thread
    # (stickslip.compiled; a parallel loop here took 11 s more to compile)
    for i in range(offsets.size - 1):
        lo, hi = offsets[i], offsets[i + 1]
        _estimate_one(xs[lo:hi], Fs[lo:hi], a[i], T[i], v[i], mass_kg, gamma, out[i])


#: Lines per thread below which :func:`estimate_array` stays on one thread (a line
#: costs about 0.1 ms).
MIN_LINES_PER_THREAD = 16
#: The compiled kernels behind :func:`estimate_array` (:func:`stickslip.compiled.cached`).
KERNELS = (_estimate_batch,)


@dataclass
class ClassicalEstimate:
    """Classical (slip-detection + PT inversion) estimate for one trace.

    Forces in nN, stiffnesses in N/m, U0 in eV. ``*_std`` are spreads over slips
    (1.4826 MAD of the per-slip or per-segment values), not standard errors. Values
    are NaN where ``quality`` is not ``ok`` (``F_mean`` and ``n_slips`` are always set).
    """

    trace: str
    F_mean_nN: float
    U0_eV: float
    K_N_m: float
    eta: float
    k_exp_N_m: float
    F_peak_nN: float
    n_slips: int
    regime: str
    quality: str
    F_mean_nN_std: float = np.nan
    U0_eV_std: float = np.nan
    K_N_m_std: float = np.nan
    eta_std: float = np.nan
    k_exp_N_m_std: float = np.nan
    F_peak_nN_std: float = np.nan
    multiple_slip_fraction: float = np.nan
    noise_nN: float = np.nan
    meta: dict[str, Any] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def _regime(row: np.ndarray) -> str:
    """The regime the line's cycles show: ``single slip`` or ``multiple slip`` (answered),
    ``stick-slip`` (slips, but K refused), ``smooth`` (no sticking: rise and fall alike,
    smooth sliding or an oscillating slider), ``not stick-slip`` (jumps up, or no
    cycles standing out of the noise), or ``""`` (too few cycles to tell)."""
    status = int(row[STATUS])
    if status == 2:
        return "smooth"
    if status in (NOT_STICK_SLIP, 3, 4):  # 4: no spring and peak fit the falls
        return "not stick-slip"
    if status == 1:
        return ""
    if status != 0:
        return "stick-slip"
    # multiple slip when most slips jump two or more lattice spacings
    return "multiple slip" if row[FRAC_MULTIPLE] > 0.5 else "single slip"


def _to_estimate(name: str, row: np.ndarray, meta: dict[str, Any]) -> ClassicalEstimate:
    return ClassicalEstimate(
        trace=name,
        F_mean_nN=float(row[F_MEAN]),
        U0_eV=float(row[U0]),
        K_N_m=float(row[K_]),
        eta=float(row[ETA]),
        k_exp_N_m=float(row[K_EXP]),
        F_peak_nN=float(row[F_PEAK]),
        n_slips=int(row[N_SLIPS]),
        regime=_regime(row),
        quality=QUALITY[int(row[STATUS])],
        F_mean_nN_std=float(row[F_MEAN_STD]),
        U0_eV_std=float(row[U0_STD]),
        K_N_m_std=float(row[K_STD]),
        eta_std=float(row[ETA_STD]),
        k_exp_N_m_std=float(row[K_EXP_STD]),
        F_peak_nN_std=float(row[F_PEAK_STD]),
        multiple_slip_fraction=float(row[FRAC_MULTIPLE]),
        noise_nN=float(row[NOISE]),
        meta=dict(meta),
    )


def estimate_array(
    x_nm: np.ndarray | Sequence[np.ndarray],
    force_nN: np.ndarray | Sequence[np.ndarray],
    lattice_nm: float | np.ndarray = GRAPHITE_LATTICE_NM,
    temperature_K: float | np.ndarray = 296.0,
    velocity_nm_per_s: float | np.ndarray = 60.0,
    mass_kg: float = PAPER_MASS_KG,
    damping_per_s: float = PAPER_DAMPING_PER_S,
    threads: int | None = None,
) -> np.ndarray:
    """Vectorised core: the raw field table (one row per trace) of many traces.

    Parameters
    ----------
    x_nm : ndarray (N, P) or (P,) or sequence of 1-D arrays
        Support positions; a single row is shared by all traces.
    force_nN : ndarray (N, P) or sequence of 1-D arrays
        Lateral forces.
    lattice_nm, temperature_K, velocity_nm_per_s : float or ndarray (N,)
        Lattice spacing, temperature and scan velocity used by the inversion.
    mass_kg, damping_per_s : float
        Mass and damping of the thermal-activation prefactor (paper preset).
    threads : int, optional
        Chunks of lines estimated at once, each on its own thread (default: numba's
        thread count, ``NUMBA_NUM_THREADS``; :data:`MIN_LINES_PER_THREAD` lines each
        at least).

    Returns
    -------
    ndarray (N, N_FIELDS)
        Columns given by the module's field constants (``F_MEAN`` ... ``STATUS``).
    """
    Fs = [np.ascontiguousarray(f, dtype=float) for f in force_nN]
    if isinstance(x_nm, np.ndarray) and x_nm.ndim == 1:
        xs = [np.asarray(x_nm, float)] * len(Fs)
    else:
        xs = [np.asarray(x, float) for x in x_nm]
    n = len(Fs)
    if len(xs) != n or any(x.shape != f.shape for x, f in zip(xs, Fs, strict=True)):
        raise ValueError("x_nm and force_nN must have matching shapes")
    offsets = np.zeros(n + 1, dtype=np.int64)
    offsets[1:] = np.cumsum([f.size for f in Fs])
    xcat = np.concatenate(xs) if n else np.empty(0)
    Fcat = np.concatenate(Fs) if n else np.empty(0)

    def per(v: float | np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(np.broadcast_to(np.asarray(v, float), (n,)))

    a, T, v = per(lattice_nm), per(temperature_K), per(velocity_nm_per_s)
    out = np.empty((n, N_FIELDS))
    cuts = chunk_bounds(n, MIN_LINES_PER_THREAD, threads)
    run_chunks(_estimate_batch, [
        (xcat, Fcat, offsets[i:j + 1], a[i:j], T[i:j], v[i:j], float(mass_kg),
         float(damping_per_s), out[i:j])
        for i, j in zip(cuts[:-1], cuts[1:], strict=True)])  # fmt: skip
    return out


def warm() -> None:
    """Compile :func:`estimate_array`'s kernel into numba's on-disk cache: one made-up
    sawtooth line (a step of :func:`stickslip.compiled.compile_ahead`)."""
    x, F = made_up_line()
    estimate_array(x, [F], threads=1)


def estimate_trace(
    x_nm: np.ndarray,
    force_nN: np.ndarray,
    lattice_nm: float = GRAPHITE_LATTICE_NM,
    temperature_K: float = 296.0,
    velocity_nm_per_s: float = 60.0,
    name: str = "",
    **kwargs: float,
) -> ClassicalEstimate:
    """Classical estimate of one trace (see the module docstring).

    Parameters
    ----------
    x_nm, force_nN : ndarray (P,)
        Support position (nm, increasing) and lateral force (nN).
    lattice_nm, temperature_K, velocity_nm_per_s : float
        Used by the PT inversion and its thermal correction.
    name : str
        Trace name carried into the result.
    **kwargs
        ``mass_kg``, ``damping_per_s`` of :func:`estimate_array`.
    """
    row = estimate_array([x_nm], [force_nN], lattice_nm, temperature_K, velocity_nm_per_s,
                         **kwargs)[0]  # fmt: skip
    return _to_estimate(name, row, {})


def estimate_traces(
    traces: Sequence[Any],
    lattice_nm: float = GRAPHITE_LATTICE_NM,
    temperature_K: float = 296.0,
    velocity_nm_per_s: float = 60.0,
    **kwargs: float,
) -> list[ClassicalEstimate]:
    """Classical estimates of :class:`~stickslip.traces.trace.Trace` objects (one each).

    Traces are processed in one parallel batch; ``trace.meta`` is carried over.
    """
    if not traces:
        return []
    table = estimate_array([t.x_nm for t in traces], [t.force_nN for t in traces], lattice_nm,
                           temperature_K, velocity_nm_per_s, **kwargs)  # fmt: skip
    return [_to_estimate(t.name, row, t.meta) for t, row in zip(traces, table, strict=True)]


CLASSICAL_COLUMNS = ("regime", "k_exp_N_m", "F_peak_nN", "n_slips", "k_exp_N_m_std",
                     "F_peak_nN_std", "noise_nN")  # fmt: skip


class ClassicalEstimator(TraceEstimator):
    """The classical estimator behind the one interface (:class:`~..base.Estimator`).

    Its reference conditions are the paper preset's (graphite, 60 nm/s, 296 K): the
    inversion needs a lattice spacing, and the thermal correction a temperature and a
    velocity, for every trace. ``quality`` is ``ok`` or the flag that explains missing
    or doubtful values (``smooth sliding``, ``too few slips``, ``too noisy``,
    ``inconsistent slopes``, ``sticks disagree``); flagged rows keep whatever could be
    measured.
    """

    name = "classical"
    kind = "classical"
    intervals = False
    accepts_volts = True  # slopes and peaks scale with the force unit: estimates in V units

    def __init__(self, mass_kg: float = PAPER_MASS_KG, damping_per_s: float = PAPER_DAMPING_PER_S,
                 reference: Reference = GRAPHITE, pair_offsets: bool = True) -> None:  # fmt: skip
        self.mass_kg = mass_kg
        self.damping_per_s = damping_per_s
        self.reference = reference
        #: read trace/retrace pairs less the offset they share (module docstring)
        self.pair_offsets = pair_offsets

    def describe(self) -> str:
        return "classical slip-detection estimator with the finite-temperature PT inversion"

    def estimate(self, traces: Sequence[Any], conditions: Sequence[Conditions]
                 ) -> tuple[list[dict[str, Any] | str], list[str]]:  # fmt: skip
        # the thermal correction compares energies with kT: not possible in volts
        volts = np.array([in_volts(t) for t in traces], dtype=bool)
        read, n_pairs = (offset_free_pairs(traces, [c.lattice_nm for c in conditions])
                         if self.pair_offsets else (list(traces), 0))  # fmt: skip
        table = estimate_array(
            [t.x_nm for t in read], [t.force_nN for t in read],
            np.array([c.lattice_nm for c in conditions]),
            np.where(volts, 0.0, [c.temperature_K for c in conditions]),
            np.array([c.velocity_nm_per_s for c in conditions]),
            mass_kg=self.mass_kg, damping_per_s=self.damping_per_s,
        )  # fmt: skip
        out: list[dict[str, Any] | str] = []
        for t, r, row in zip(traces, read, table, strict=True):
            d = _to_estimate(t.name, row, {}).as_dict()
            res = {k: d[k] for k in ("F_mean_nN", "U0_eV", "K_N_m", "eta", "quality")}
            res.update({f"{k}_std": d[f"{k}_std"] for k in ("F_mean_nN", "U0_eV", "K_N_m", "eta")})
            res.update({k: d[k] for k in CLASSICAL_COLUMNS})
            if r is not t:  # read less its pair's offset: <F> stays the row's own
                res["F_mean_nN"] = float(np.mean(t.force_nN))
            out.append(res)
        notes = []
        if n_pairs:
            notes.append(f"classical: {n_pairs} trace/retrace pair(s) read less the offset "
                         "both directions share (the mean over one lattice period of their "
                         "half-difference)")  # fmt: skip
        if volts.any():
            notes.append(f"{int(volts.sum())} trace(s) in volts (no --calibration): <F>, U0 "
                         "and K in V, V nm and V/nm, without the thermal correction of the "
                         "peak force")  # fmt: skip
        return out, notes
