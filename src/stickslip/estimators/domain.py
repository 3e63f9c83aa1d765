"""Is a trace in the domain the estimates are valid for? A verdict on every row.

Every estimator's :meth:`~stickslip.estimators.base.TraceEstimator.predict` ends with
:func:`assess`, which adds three columns to each row:

``in_domain``
    True when the trace looks like Prandtl-Tomlinson stick-slip that the estimator
    was built for, False otherwise (and for rows without an estimate).
``domain_score``
    The largest of the checks below, each a statistic divided by its limit, so that
    each check fails above 1: ``domain_score <= 1`` is in domain, 2 is twice as far
    past the nearest limit. Empty for rows without an estimate.
``change_nm``
    Where the line changes part-way (a tip that changed: the check "change" below),
    else empty.
``domain_reason``
    Empty in domain; else the failed checks in plain words, worst first, separated
    by ``"; "`` (``"no estimate: <quality>"`` for rows without an estimate).

The checks. The first five read the trace itself (:func:`trace_checks`, a compiled
kernel: the classical estimator's segmentation of the line into sticks and slips,
:mod:`stickslip.estimators.segmentation`; chunks of lines on numba's threads)
and the row's estimate, so they hold for every estimator:

1. slips: at least :data:`MIN_SLIPS` cycles whose fall is fast against the stick's
   rise (``R_down >= STICK_RATIO`` of the segmentation) -- ``"no stick-slip: slips
   not found"`` (``"flat line: ..."`` when the force does not vary beyond the noise);
2. direction: cycles whose rise is a sudden jump (``R_up >= STICK_RATIO``) at most
   :data:`MAX_RISE_FRACTION` of the slips. Stick-slip rises slowly and drops fast; a
   sawtooth that does the opposite is ``"sawtooth reversed"`` (a retrace read without
   its sign flip, a trace read backwards), and jumps both ways (a square wave,
   telegraph noise) are ``"jumps up as well as down"``;
3. spacing: the lower quartile of the distances between consecutive slips at least
   :data:`MIN_SPACING` lattice spacings of the stated lattice. Slips are one (single
   slip) or several (multiple slip) lattice spacings apart; closer ones mean the stated
   lattice is wrong or the drops are not slips -- ``"slips closer than one lattice
   spacing"``, or, where the slips' drops are of unequal sizes (robust spread above
   :data:`UNEQUAL_DROPS` of their median), ``"several unequal slips per lattice period:
   more than one contact"``;
4. change: the line is one regime: no change of level, part-way along it, in its
   sticks' log rise rates or its peaks' level
   (:func:`~stickslip.estimators.segmentation.cycle_change`: a likelihood ratio over
   its price, at least a fifth of the cycles on each side, a 10 % step, and a step
   that beats by the BIC any slow trend of degree 1-3 and any ramp over three cycles
   or more) --
   ``"the line changes part-way (at x = ... nm): two regimes"``;
5. eta: the estimate's eta inside the trained window :data:`ETA_WINDOW`, judged on
   the estimate's own uncertainty (the window is missed when the whole 95 % interval,
   else ``eta +- 2 eta_std``, else the value, lies outside it) -- ``"eta below the
   trained window"`` (smooth sliding, or a barely bistable contact) or ``"... above"``;
   and, for learned estimators (``eta_edge`` of :func:`assess`), the estimate itself at
   least :data:`ETA_EDGE`, a little inside the window's lower edge -- ``"eta at the
   edge of the trained window"``. Near eta = 1 stick-slip
   fades into smooth sliding: the slips shrink to nothing, and a model trained on eta
   >= 1.2 maps a smooth (eta < 1) line onto the edge of its window (the bundled line
   model gives eta 1.15-1.45 for most of them), where it also puts weak stick-slip, so
   an estimate there cannot say which of the two the line is (the classical
   estimator inverts the slips and can report eta < 1.2, so it is held to the window);
6. for learned estimators whose eta estimate is below :data:`ETA_CONFIRM`, the line's
   own slips: the classical estimator (slip detection, stick fits, PT inversion at T =
   0, the lower eta) must answer it. A model trained with the effect families
   (low-pass, precursor softening) puts smooth lines at eta 1.4-2 too, beyond any edge
   that keeps weak stick-slip in domain; the inversion tells them apart (it finds no
   slips to fit, or a peak and slope no PT stick-slip has). The estimator puts the
   classical refusal in the row's ``stick_slip_check`` (absent when not checked or
   answered) -- ``"eta near the trained window's edge and the slips do not invert to
   stick-slip"``;
7. for estimators that give one: ``domain_embedding`` (a column of the row), the
   distance of the line from the estimator's training lines in units of its limit
   (the whole-line CNN: Mahalanobis distance of its pooled features from those of
   simulated training-like lines, :class:`EmbeddingReference`) -- ``"line unlike the
   training lines"``;
8. for estimators that give one: ``domain_contacts``, the odds that the line comes
   from a contact of several asperities that no single PT describes, over the odds at
   the probe's limit (the whole-line CNN: a logistic regression on the same pooled
   features, fitted on simulated contact and single-point lines that carry the same
   instrument effects, :class:`ContactProbe`) -- ``"the line's shape is no
   single-point contact's ...: more than one contact"``. Such a contact's line at room
   temperature is often a plain sawtooth (thermal activation skips the small slips of
   its T = 0 waveform), so the spacing check does not see it, while its effective PT
   is far from what the line's sawtooth would say.

Out of domain, the numbers stay, but the intervals are widened (:func:`widen_rows`):
every half-width ``*_lo68/_hi68/_lo95/_hi95`` about the estimate and every ``*_std``
grows by a factor (in log space for U0, K and eta, whose intervals are log-normal),
because the calibration that made them was fitted on lines of the domain and says
nothing about others. The factor is the one the 95 % intervals needed to cover 95 %
of the truths of the out-of-domain simulated lines that have a truth, rounded up
(``benchmarks/domain.py`` prints it; chosen on the seed-1 sets): :data:`WIDEN_FACTOR`
for smooth sliding (U0 needed 2.2x, K 1.8x), and for the spacing check, whose rows
read a misstated lattice, :data:`CHECK_WIDEN_FACTORS` (U0 needed 4.6x on a 0.6x
lattice, K 2.1x). A row failing several checks takes the largest.
The plain reason says why; ``infer --check`` (the posterior predictive check) stays
the deeper, slower test of whether the PT model describes a trace at all.
"""

from __future__ import annotations

import functools
import os
from collections.abc import Mapping, MutableMapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numba import njit
from threadpoolctl import ThreadpoolController

import stickslip.estimators.segmentation as sg
from stickslip.compiled import chunk_bounds, made_up_line, run_chunks
from stickslip.estimators.calibration import Z68, lognormal_std
from stickslip.estimators.table import BOUNDS, OK, TARGETS, TWO_REGIMES, VOLT_NAMES, is_missing
from stickslip.robust import mad_sigma, median, percentile, select_tails, white_sigma

#: The trained window of eta (the training range of every learned model, PHYSICS.md).
ETA_WINDOW = (1.2, 40.0)
#: Estimates of eta below this are too close to the window's lower edge to rule out
#: smooth sliding (tuned on the seed-1 sets of ``benchmarks/domain.py``).
ETA_EDGE = 1.45
#: Learned estimates of eta below this are kept in domain only if the line's own slips
#: invert to stick-slip (the row's ``stick_slip_check``; tuned on the seed-1 sets: for
#: the model bundled since 2026-11-25, 2.3 leaves smooth sliding in domain as often as
#: 2.5 did, 0.225, and checks a fifth fewer lines).
ETA_CONFIRM = 2.3
MIN_SLIPS = 2
MAX_RISE_FRACTION = 0.25
MIN_SPACING = 0.8  # lattice spacings
WIDEN_FACTOR = 3.0
#: Checks whose rows need more than :data:`WIDEN_FACTOR`: slips closer than the stated
#: lattice mean the lattice is misstated, which biases U0 by the lattice ratio (on the
#: seed-1 lines on a 0.6x lattice the 95 % intervals of U0 needed 4.6x to cover 95 % of
#: the truths; ``benchmarks/domain.py`` prints it). A row takes its failed checks' largest.
CHECK_WIDEN_FACTORS = {"spacing": 5.0}
MAX_SCORE = 1e3  # domain_score is capped here (an eta of 0 would give infinity)
#: Checks in the order a tie is reported.
CHECKS = ("slips", "direction", "spacing", "change", "eta_low", "eta_high", "stick_slip",
          "contacts", "embedding")  # fmt: skip
#: Estimates whose intervals :func:`widen_rows` widens: in nN units, and in V units for
#: traces read without a calibration (:data:`~stickslip.estimators.table.VOLT_NAMES`).
WIDENED = (*TARGETS, *(VOLT_NAMES[k] for k in TARGETS if k in VOLT_NAMES))
LINEAR_TARGETS = ("F_mean_nN", VOLT_NAMES["F_mean_nN"])  # the others are log-normal

# fields of the kernel's output
N_DROPS, N_RISES, SPACING_MEDIAN, SPACING_Q25, NOISE, SPAN, CHANGE, CHANGE_X, DROP_SPREAD = (
    range(9))  # fmt: skip
N_FIELDS = 9
#: Drops whose robust spread exceeds this fraction of their median are of unequal sizes
#: (the spacing check then names more than one contact rather than a wrong lattice).
UNEQUAL_DROPS = 0.3


@njit(cache=True, error_model="numpy")
def _check_one(x: np.ndarray, F: np.ndarray, out: np.ndarray) -> None:
    n = F.size
    out[:] = np.nan
    out[NOISE] = white_sigma(F)  # also the segmentation's start
    out[SPAN] = 0.0
    if n < 4:
        out[N_DROPS] = 0
        out[N_RISES] = 0
        return
    # the 2 % and 98 % order statistics of the force less its straight trend
    xm, Fm = np.mean(x), np.mean(F)
    sxx, sxy = 0.0, 0.0
    for i in range(n):
        u = x[i] - xm
        sxx += u * u
        sxy += u * (F[i] - Fm)
    slope = sxy / sxx if sxx > 0 else 0.0
    hi, lo = int(0.98 * (n - 1)), int(0.02 * (n - 1))
    if hi > lo:
        bottom, top = select_tails(F - slope * (x - xm), lo, hi)
        out[SPAN] = top - bottom
    # the classical estimator's segmentation: a cycle's fall is a slip where it is fast
    # against the stick's rise, its rise a sudden jump up where that is fast instead
    cycles, _, _ = sg.find_cycles(F, out[NOISE])
    m = cycles.shape[0] - 1
    pos = np.empty(max(m, 0))
    nd = 0
    nr = 0
    for k in range(m):
        if cycles[k, sg.CY_R_DOWN] >= sg.STICK_RATIO:
            pos[nd] = x[int(0.5 * (cycles[k, sg.CY_PEAK] + cycles[k, sg.CY_VALLEY]))]
            nd += 1
        if cycles[k, sg.CY_R_UP] >= sg.STICK_RATIO:
            nr += 1
    out[N_DROPS] = nd
    out[N_RISES] = nr
    if nd >= 2:
        gaps = pos[1:nd] - pos[: nd - 1]
        out[SPACING_MEDIAN] = median(gaps)
        out[SPACING_Q25] = percentile(gaps, 25.0)
    # two regimes along the line (a tip that changes): a change of level in the
    # cycles' rise rates or peaks
    out[CHANGE] = 0.0
    if m >= 8:
        drops = cycles[:m, sg.CY_DROP]
        out[DROP_SPREAD] = mad_sigma(drops) / max(median(drops), 1e-300)
        k, score = sg.cycle_change(cycles)
        out[CHANGE] = score
        if k > 0:
            out[CHANGE_X] = x[int(cycles[k, sg.CY_LO])]


@njit(cache=True, nogil=True, error_model="numpy")
def _check_batch(xs: np.ndarray, Fs: np.ndarray, offsets: np.ndarray, out: np.ndarray) -> None:
    # serial and without the GIL: trace_checks runs one chunk per thread (a numba
    # parallel loop over _check_one takes minutes to compile)
    for i in range(offsets.size - 1):
        lo, hi = offsets[i], offsets[i + 1]
        _check_one(xs[lo:hi], Fs[lo:hi], out[i])


#: Lines per thread below which :func:`trace_checks` stays on one thread.
MIN_LINES_PER_THREAD = 256
#: The compiled kernels behind :func:`trace_checks` (:func:`stickslip.compiled.cached`).
KERNELS = (_check_batch,)


@dataclass
class TraceChecks:
    """What :func:`trace_checks` reads off each trace (arrays of length N).

    Attributes
    ----------
    n_drops, n_rises : ndarray of int
        Cycles with a fast fall (slips) and with a sudden rise.
    spacing_median_nm, spacing_q25_nm : ndarray
        Median and lower quartile of the distances between consecutive drops (NaN with
        fewer than two drops).
    noise_nN : ndarray
        White-noise standard deviation per sample (from second differences).
    span_nN : ndarray
        2-98 % range of the linearly detrended force.
    change_score : ndarray
        The strongest change of level along the line's cycles, over its price
        (:func:`~stickslip.estimators.segmentation.cycle_change`; above 1: two regimes).
    change_nm : ndarray
        Where that change is: the start of the first stick of the second regime (NaN
        without eight cycles).
    drop_spread : ndarray
        Robust spread of the slips' drops over their median.
    """

    n_drops: np.ndarray
    n_rises: np.ndarray
    spacing_median_nm: np.ndarray
    spacing_q25_nm: np.ndarray
    noise_nN: np.ndarray
    span_nN: np.ndarray
    change_score: np.ndarray
    change_nm: np.ndarray
    drop_spread: np.ndarray


def trace_checks(x_nm: Sequence[np.ndarray], force_nN: Sequence[np.ndarray],
                 threads: int | None = None) -> TraceChecks:  # fmt: skip
    """Slips, rises and slip spacing of each trace (see the module docstring).

    ``threads``: chunks of lines checked at once, each on its own thread (default:
    numba's thread count, ``NUMBA_NUM_THREADS``; one per
    :data:`MIN_LINES_PER_THREAD` lines at most).
    """
    sizes = np.array([np.asarray(f).size for f in force_nN], np.int64)
    n = sizes.size
    if n == 0:
        e = np.empty(0)
        return TraceChecks(e.astype(int), e.astype(int), e, e, e, e, e, e, e)
    offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    xs = np.concatenate([np.asarray(x, float) for x in x_nm])
    Fs = np.concatenate([np.asarray(f, float) for f in force_nN])
    out = np.empty((n, N_FIELDS))
    cuts = chunk_bounds(n, MIN_LINES_PER_THREAD, threads)
    run_chunks(_check_batch, [(xs, Fs, offsets[a:b + 1], out[a:b])
                              for a, b in zip(cuts[:-1], cuts[1:], strict=True)])  # fmt: skip
    return TraceChecks(out[:, N_DROPS].astype(int), out[:, N_RISES].astype(int),
                       out[:, SPACING_MEDIAN], out[:, SPACING_Q25], out[:, NOISE],
                       out[:, SPAN], out[:, CHANGE], out[:, CHANGE_X],
                       out[:, DROP_SPREAD])  # fmt: skip


_NAN = float("nan")


def warm() -> None:
    """Compile :func:`trace_checks`'s kernel into numba's on-disk cache: one made-up
    sawtooth line (a step of :func:`stickslip.compiled.compile_ahead`)."""
    x, F = made_up_line()
    trace_checks([x], [F], threads=1)


def _value(v: Any) -> float:
    """A row's entry as a float: NaN for missing, non-numeric and boolean entries."""
    if type(v) is float:  # the usual case, first: this runs for every row and column
        return v
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.integer, np.floating)):
        return _NAN
    return _NAN if is_missing(v) else float(v)


def _number(row: Mapping[str, Any], key: str) -> float:
    return _value(row.get(key))


def _column(rows: Sequence[Mapping[str, Any]], key: str) -> np.ndarray:
    """One column of the rows as floats (:func:`_value`)."""
    vals = [r.get(key) for r in rows]
    kinds = set(map(type, vals))
    # the usual cases without a call per row (numpy reads None as NaN)
    if kinds <= {float, type(None)}:
        return np.array(vals, float)
    return np.array([_value(v) for v in vals], float)


def eta_bounds_columns(rows: Sequence[Mapping[str, Any]]) -> tuple[np.ndarray, np.ndarray]:
    """The range of eta each row's estimate allows: its 95 % interval, else
    ``eta +- 2 eta_std`` (an ``eta_std`` may be a spread over slips or windows), else the
    value itself. Arrays (lo, hi) of length N."""
    eta = _column(rows, "eta")
    lo, hi = _column(rows, "eta_lo95"), _column(rows, "eta_hi95")
    sd = _column(rows, "eta_std")
    has_iv = np.isfinite(lo) & np.isfinite(hi)
    has_sd = ~has_iv & np.isfinite(sd)
    lo = np.where(has_iv, lo, np.where(has_sd, eta - 2.0 * sd, eta))
    hi = np.where(has_iv, hi, np.where(has_sd, eta + 2.0 * sd, eta))
    return lo, hi


def eta_bounds(row: Mapping[str, Any]) -> tuple[float, float]:
    """:func:`eta_bounds_columns` of one row."""
    lo, hi = eta_bounds_columns([row])
    return float(lo[0]), float(hi[0])


def check_ratios(checks: TraceChecks, lattice_nm: np.ndarray,
                 rows: Sequence[Mapping[str, Any]],
                 eta_edge: float = ETA_WINDOW[0]) -> dict[str, np.ndarray]:  # fmt: skip
    """Each check (:data:`CHECKS`) of every trace as statistic / limit: fails above 1.

    ``rows[i]`` is trace ``i``'s estimate and ``lattice_nm[i]`` its lattice. Returns an
    array of length N per check, NaN where the check cannot be made (no eta, fewer than
    two slips for the spacing, no sudden rise, no embedding); ``eta_edge`` is the least
    estimate of eta kept in domain.
    """
    lattice_nm = np.asarray(lattice_nm, float)
    nd = checks.n_drops.astype(float)
    nr = checks.n_rises.astype(float)
    nan = np.full(nd.size, np.nan)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = {"slips": MIN_SLIPS / np.maximum(nd, 0.5)}
        out["direction"] = np.where(nr > 0, nr / np.maximum(nd, 0.5) / MAX_RISE_FRACTION, nan)
        q25 = checks.spacing_q25_nm
        ok = np.isfinite(q25) & (q25 > 0) & (lattice_nm > 0)
        out["spacing"] = np.where(ok, MIN_SPACING * lattice_nm / q25, nan)
        out["change"] = np.where(checks.change_score > 0, checks.change_score, nan)
        eta = _column(rows, "eta")
        lo, hi = eta_bounds_columns(rows)
        low = np.where(np.isfinite(hi), np.where(hi > 0, ETA_WINDOW[0] / hi, np.inf), nan)
        if eta_edge > ETA_WINDOW[0]:
            edge = np.where(eta > 0, eta_edge / eta, np.inf)
            low = np.where(np.isfinite(eta), np.fmax(np.where(np.isnan(low), 0.0, low), edge), low)
        out["eta_low"] = low
        out["eta_high"] = np.where(np.isfinite(lo), lo / ETA_WINDOW[1], nan)
        flagged = np.array([bool(r.get("stick_slip_check")) for r in rows], bool)
        confirm = np.where(eta > 0, ETA_CONFIRM / eta, np.inf)
        out["stick_slip"] = np.where(flagged & np.isfinite(eta), confirm, nan)
        probe = _column(rows, "domain_contacts")
        out["contacts"] = np.where(np.isfinite(probe), probe, nan)
        emb = _column(rows, "domain_embedding")
        out["embedding"] = np.where(np.isfinite(emb), emb, nan)
    return out


def reason(check: str, checks: TraceChecks, i: int, lattice_nm: float,
           row: Mapping[str, Any], eta_edge: float = ETA_WINDOW[0]) -> str:  # fmt: skip
    """The plain reason a check of trace ``i`` failed."""
    nd, nr = int(checks.n_drops[i]), int(checks.n_rises[i])
    if check == "slips":
        text = ("no stick-slip: slips not found" if nd == 0 else
                f"no stick-slip: {nd} slip found, at least {MIN_SLIPS} needed")  # fmt: skip
        if checks.span_nN[i] < 10.0 * checks.noise_nN[i] + 1e-9:
            text += " (the force does not vary beyond its noise)"
        return text
    if check == "direction":
        if nr >= 2 * max(nd, 1):
            return "sawtooth reversed: sudden rises and slow falls"
        return "jumps up as well as down: not a stick-slip sawtooth"
    if check == "spacing":
        med = checks.spacing_median_nm[i] / lattice_nm
        if checks.drop_spread[i] > UNEQUAL_DROPS:
            return (f"several unequal slips per lattice period (median {med:.2f} a apart): "
                    "more than one contact")  # fmt: skip
        return (f"slips closer than one lattice spacing (median {med:.2f} a, stated "
                f"a = {lattice_nm:g} nm)")  # fmt: skip
    if check == "change":
        return (f"the line changes part-way (at x = {checks.change_nm[i]:.2f} nm): "
                "two regimes")  # fmt: skip
    eta = _number(row, "eta")
    if check == "eta_low":
        hi = eta_bounds(row)[1]
        if np.isfinite(hi) and hi < ETA_WINDOW[0]:
            return f"eta below the trained window ({eta:.3g} < {ETA_WINDOW[0]:g})"
        return (f"eta at the edge of the trained window ({eta:.3g} < {eta_edge:g}): "
                "smooth sliding not ruled out")  # fmt: skip
    if check == "eta_high":
        return f"eta above the trained window ({eta:.3g} > {ETA_WINDOW[1]:g})"
    if check == "stick_slip":
        return (f"eta near the trained window's edge ({eta:.3g} < {ETA_CONFIRM:g}) and the "
                f"slips do not invert to stick-slip (classical: {row['stick_slip_check']})")
    if check == "contacts":
        odds = _number(row, "domain_contacts")
        return (f"the line's shape is no single-point contact's (contact probe {odds:.3g}x "
                "the limit): more than one contact")  # fmt: skip
    emb = _number(row, "domain_embedding")
    return f"line unlike the training lines (embedding distance {emb:.3g}x the limit)"


def widen_row(row: MutableMapping[str, Any], factor: float = WIDEN_FACTOR) -> None:
    """Widen a row's intervals and stds about its estimates by ``factor`` (in place).

    ``F_mean_nN`` (or ``F_mean_V``): every bound moves ``factor`` times as far from the
    estimate, and the std grows by ``factor``. ``U0_eV, K_N_m, eta`` (and their volt
    versions; log-normal intervals): the same in log space, ``lo -> m (lo / m) ** factor``;
    the std is then that of the log-normal with the widened 68 % interval, as the line
    model defines it (without a 68 % interval, the std grows by ``factor``).
    """
    widen_rows([row], factor)


def _put(rows: Sequence[MutableMapping[str, Any]], key: str, values: np.ndarray,
         where: np.ndarray) -> None:  # fmt: skip
    vals = values.tolist()  # Python floats
    if where.all():
        for row, v in zip(rows, vals, strict=True):
            row[key] = v
        return
    for j in np.flatnonzero(where).tolist():
        rows[j][key] = vals[j]


def widen_rows(rows: Sequence[MutableMapping[str, Any]], factor: float = WIDEN_FACTOR) -> None:
    """:func:`widen_row` on every row, one column at a time (out-of-domain rows can be
    most of a table: a user's whole file at a wrong lattice)."""
    if not rows:
        return
    model_sd = _column(rows, "F_model_std_nN")  # the pairs' std (estimators.pairs)
    _put(rows, "F_model_std_nN", factor * model_sd, np.isfinite(model_sd))
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        for k in WIDENED:
            m = _column(rows, k)
            has = np.isfinite(m)
            if not has.any():
                continue
            log = (k not in LINEAR_TARGETS) & (m > 0)
            bounds = {}
            for b in BOUNDS:
                v = _column(rows, f"{k}_{b}")
                ok = has & np.isfinite(v)
                new = np.where(log, m * (v / m) ** factor, m + factor * (v - m))
                # a log-normal bound at or below 0 cannot be widened in log space
                put = ok & ~(log & ~(v > 0))
                _put(rows, f"{k}_{b}", new, put)
                bounds[b] = np.where(put, new, v)  # what the row now holds
            sd = _column(rows, f"{k}_std")
            ok = has & np.isfinite(sd)
            lo, hi = bounds["lo68"], bounds["hi68"]
            from68 = log & np.isfinite(lo) & np.isfinite(hi) & (lo > 0)
            e = np.log(hi / lo) / (2.0 * Z68)
            lognormal = lognormal_std(m, e)
            _put(rows, f"{k}_std", np.where(from68, lognormal, factor * sd), ok)


def _locate_refused_changes(rows: Sequence[MutableMapping[str, Any]],
                            x_nm: Sequence[np.ndarray],
                            force_nN: Sequence[np.ndarray]) -> None:  # fmt: skip
    """Rows refused as two regimes (the classical estimator's sticks change slope) get
    ``change_nm`` and the place in their reason, where the change check finds it."""
    idx = [i for i, r in enumerate(rows) if r.get("quality") == TWO_REGIMES]
    if not idx:
        return
    checks = trace_checks([x_nm[i] for i in idx], [force_nN[i] for i in idx])
    for j, i in enumerate(idx):
        if checks.change_score[j] > 1.0:
            rows[i]["change_nm"] = float(checks.change_nm[j])
            rows[i]["domain_reason"] = (f"no estimate: {TWO_REGIMES} (the line changes "
                                        f"part-way at x = {checks.change_nm[j]:.2f} nm)")


def assess(rows: Sequence[MutableMapping[str, Any]], x_nm: Sequence[np.ndarray],
           force_nN: Sequence[np.ndarray], lattice_nm: Sequence[float],
           widen: bool = True, eta_edge: float = ETA_WINDOW[0]) -> None:  # fmt: skip
    """Add ``in_domain``, ``domain_score``, ``domain_reason`` to every row (in place) and,
    with ``widen``, widen the intervals of the rows out of domain (:func:`widen_rows`).

    ``rows[i]`` is the row of the trace ``(x_nm[i], force_nN[i])`` read at lattice
    ``lattice_nm[i]``; rows without an estimate (``quality`` other than ``ok``) are out
    of domain with the reason ``"no estimate: <quality>"``. ``eta_edge``: the least
    estimate of eta in domain (:data:`ETA_EDGE` for learned models, which cannot report
    an eta below their window).
    """
    todo = [i for i, r in enumerate(rows) if r.get("quality") == OK]
    for r in rows:
        if r.get("quality") != OK:
            r.update(in_domain=False, domain_score=None,
                     domain_reason=f"no estimate: {r.get('quality')}")  # fmt: skip
    _locate_refused_changes(rows, x_nm, force_nN)
    if not todo:
        return
    checks = trace_checks([x_nm[i] for i in todo], [force_nN[i] for i in todo])
    done = [rows[i] for i in todo]
    lattice = [float(lattice_nm[i]) for i in todo]
    ratios = check_ratios(checks, np.array(lattice), done, eta_edge)
    table = np.column_stack([ratios[k] for k in CHECKS])  # (N, checks), NaN: not made
    with np.errstate(invalid="ignore"):
        failing = table > 1.0
    score = np.minimum(np.where(np.isnan(table), -np.inf, table).max(axis=1), MAX_SCORE)
    # failed checks worst first (a stable sort: a tie goes in the order of CHECKS)
    order = np.argsort(np.where(failing, -table, np.inf), axis=1, kind="stable").tolist()
    n_failed = failing.sum(axis=1).tolist()
    changed = failing[:, CHECKS.index("change")]
    for j, (row, nf, sc) in enumerate(zip(done, n_failed, score.tolist(), strict=True)):
        row["in_domain"] = nf == 0
        row["domain_score"] = sc
        row["change_nm"] = float(checks.change_nm[j]) if changed[j] else None
        row["domain_reason"] = "; ".join(reason(CHECKS[c], checks, j, lattice[j], row, eta_edge)
                                         for c in order[j][:nf]) or None  # fmt: skip
    if widen:
        out = failing.any(axis=1)
        factor = np.full(len(done), WIDEN_FACTOR)
        for check, f in CHECK_WIDEN_FACTORS.items():
            hit = failing[:, CHECKS.index(check)]
            factor[hit] = np.maximum(factor[hit], f)
        for f in np.unique(factor[out]):  # a few groups: widen_rows works column-wise
            widen_rows([done[j] for j in np.flatnonzero(out & (factor == f))], float(f))


@functools.cache
def _blas_controller() -> ThreadpoolController:
    """The process's thread-pool controller, made on first use (it lists the BLAS
    libraries loaded by then: numpy's, and torch's once a model has run)."""
    return ThreadpoolController()


#: Held-out weighted log loss picks the probe's L2 penalty among these (per feature,
#: on standardised features).
PROBE_PENALTIES = (1e-4, 1e-3, 1e-2, 1e-1)


def _log_loss(z: np.ndarray, y: np.ndarray, w: np.ndarray) -> float:
    """Weighted mean log loss of log-odds ``z`` for labels ``y`` (0 or 1)."""
    return float(np.sum(w * np.logaddexp(0.0, -(2.0 * y - 1.0) * z)) / w.sum())


def _logistic_fit(X: np.ndarray, y: np.ndarray, w: np.ndarray, penalty: float
                  ) -> tuple[np.ndarray, float]:  # fmt: skip
    """Weights and bias of an L2-penalised logistic regression (weighted mean log loss
    plus ``penalty/2 |weights|^2``), by L-BFGS with the exact gradient."""
    from scipy.optimize import minimize  # scipy's optimisers load in 0.3 s: only here

    w = w / w.sum()
    sign = 2.0 * y - 1.0

    def loss(theta: np.ndarray) -> tuple[float, np.ndarray]:
        s = X @ theta[:-1] + theta[-1]
        value = _log_loss(s, y, w) + 0.5 * penalty * theta[:-1] @ theta[:-1]
        g = -w * sign * np.exp(-np.logaddexp(0.0, sign * s))  # d loss / d s
        return value, np.concatenate([X.T @ g + penalty * theta[:-1], [g.sum()]])

    res = minimize(loss, np.zeros(X.shape[1] + 1), jac=True, method="L-BFGS-B")
    return res.x[:-1], float(res.x[-1])


def _joined(features: np.ndarray) -> np.ndarray:
    """Every member's features of N lines (M, N, D) side by side: (N, M D)."""
    feats = np.asarray(features, float)
    return feats.transpose(1, 0, 2).reshape(feats.shape[1], -1)


@dataclass
class ContactProbe:
    """The log-odds that a line comes from a contact of several asperities that no
    single Prandtl-Tomlinson slider describes, read linearly off a learned model's
    pooled features: an L2-penalised logistic regression on every member's features,
    standardised and side by side.

    It is fitted on simulated lines with known answers (``benchmarks/domain.py
    --write-reference``): multi-asperity contact lines whose T = 0 waveform no single PT
    describes against training-like single-point lines and described contact lines,
    every kind carrying the same instrument effects, so that the probe reads the
    contact, not the instrument. A line is flagged where its log-odds exceed
    :attr:`limit`, the ``level`` quantile of held-out single-point lines.

    Attributes
    ----------
    mean, scale : ndarray (M D,)
        The standardisation of the joined features.
    weights : ndarray (M D,)
    bias : float
    limit : float
        Log-odds above which a line is flagged.
    level : float
    penalty : float
        The L2 penalty the fit chose.
    """

    mean: np.ndarray
    scale: np.ndarray
    weights: np.ndarray
    bias: float
    limit: float
    level: float
    penalty: float

    @classmethod
    def fit(cls, features: np.ndarray, labels: np.ndarray, weights: np.ndarray,
            validation: np.ndarray, penalties: Sequence[float] = PROBE_PENALTIES
            ) -> ContactProbe:  # fmt: skip
        """Fit on lines' features (M, N, D), ``labels`` (N,; 1: several contacts) and
        ``weights`` (N,), leaving out the ``validation`` lines (N,; bool): the penalty is
        the one of least weighted log loss on them, and they stay held out for
        :meth:`set_limit` (:attr:`limit` is left at 0, even odds)."""
        X = _joined(features)
        y = np.asarray(labels, float)
        w = np.asarray(weights, float)
        val = np.asarray(validation, bool)
        mean = X[~val].mean(axis=0)
        scale = X[~val].std(axis=0) + 1e-9
        Z = (X - mean) / scale
        fits = {p: _logistic_fit(Z[~val], y[~val], w[~val], p) for p in penalties}
        best = min(penalties, key=lambda p: _log_loss(Z[val] @ fits[p][0] + fits[p][1],
                                                      y[val], w[val]))  # fmt: skip
        return cls(mean, scale, *fits[best], 0.0, 0.5, float(best))

    def log_odds(self, features: np.ndarray) -> np.ndarray:
        """The log-odds of N lines' features (M, N, D)."""
        return ((_joined(features) - self.mean) / self.scale) @ self.weights + self.bias

    def set_limit(self, features: np.ndarray, level: float) -> None:
        """Set :attr:`limit` to the ``level`` quantile of these (single-point) lines'
        log-odds: about ``1 - level`` of lines like them are flagged."""
        self.limit = float(np.quantile(self.log_odds(features), level))
        self.level = float(level)

    def ratio(self, features: np.ndarray) -> np.ndarray:
        """The odds over the odds at :attr:`limit` (above 1: flagged), capped at e^50."""
        return np.exp(np.minimum(self.log_odds(features) - self.limit, 50.0))

    def arrays(self) -> dict[str, np.ndarray]:
        """The probe as arrays (``probe_*``), for :meth:`EmbeddingReference.save`."""
        return {"probe_mean": self.mean.astype(np.float32),
                "probe_scale": self.scale.astype(np.float32),
                "probe_weights": self.weights.astype(np.float32),
                "probe_bias": np.float64(self.bias), "probe_limit": np.float64(self.limit),
                "probe_level": np.float64(self.level),
                "probe_penalty": np.float64(self.penalty)}  # fmt: skip

    @classmethod
    def from_arrays(cls, z: Mapping[str, np.ndarray]) -> ContactProbe | None:
        """The probe saved by :meth:`arrays` (None where the file has none)."""
        if "probe_weights" not in z:
            return None
        return cls(z["probe_mean"].astype(float), z["probe_scale"].astype(float),
                   z["probe_weights"].astype(float), float(z["probe_bias"]),
                   float(z["probe_limit"]), float(z["probe_level"]), float(z["probe_penalty"]))


@dataclass
class EmbeddingReference:
    """Where a learned model's pooled features lie on its training-like lines.

    A Mahalanobis distance from the reference lines' features, in their principal
    components: ``d^2 = sum_j p_j^2 / var_j + r^2 / var_res``, ``p = components @ (f -
    mean)`` and ``r`` the norm of what the components do not span. The variances are
    shrunk towards their mean (``var_j = lambda_j + s mean(lambda)``, ``var_res = s
    mean(lambda)``) so that directions in which the reference lines hardly vary count
    without dominating. The distance reported is ``sqrt(d^2 / D)`` (``D`` features; about
    1 for a typical reference line), averaged over an ensemble's members, and divided
    by ``limit``: its ``level`` quantile over the reference lines, so that about ``1 -
    level`` of lines like them fall beyond 1.

    Attributes
    ----------
    mean : ndarray (M, D)
        Per member: the reference features' mean.
    components : ndarray (M, k, D)
        Principal directions (k <= D).
    variance : ndarray (M, k)
        Shrunk variance along each.
    residual_variance : ndarray (M,)
        Variance assumed outside the components.
    limit : float
        Unscaled distance at the ``level`` quantile of the reference lines.
    level : float
    fingerprint : str
        Identifies the model the features come from (its weights): a reference made
        for another model is not used.
    probe : ContactProbe or None
        The contact probe read off the same features (the verdict's "contacts" check).
    """

    mean: np.ndarray
    components: np.ndarray
    variance: np.ndarray
    residual_variance: np.ndarray
    limit: float
    level: float
    fingerprint: str
    probe: ContactProbe | None = None
    #: per member, ``L`` with ``L L^T`` the precision the distance reads (made on first use)
    _whitener: np.ndarray | None = field(default=None, init=False, repr=False, compare=False)

    @classmethod
    def fit(cls, features: np.ndarray, fingerprint: str, shrinkage: float = 0.01,
            level: float = 0.995) -> EmbeddingReference:  # fmt: skip
        """From the features (M, N, D) of N reference lines for each of M members."""
        feats = np.asarray(features, float)
        M, N, D = feats.shape
        k = min(N - 1, D)
        mean = feats.mean(axis=1)
        comps = np.empty((M, k, D))
        var = np.empty((M, k))
        res = np.empty(M)
        for m in range(M):
            X = feats[m] - mean[m]
            _, s, vt = np.linalg.svd(X, full_matrices=False)
            lam = s[:k] ** 2 / (N - 1)
            floor = shrinkage * max(float(lam.sum()) / D, 1e-30)
            comps[m], var[m], res[m] = vt[:k], lam + floor, floor
        ref = cls(mean, comps, var, res, 1.0, level, fingerprint)
        ref.set_limit(feats, level)
        return ref

    def set_limit(self, features: np.ndarray, level: float) -> None:
        """Set :attr:`limit` to the ``level`` quantile of the distances of these lines'
        features (M, N, D): held-out reference lines give an honest limit."""
        self.limit = float(np.quantile(self.raw_distance(features), level))
        self.level = float(level)

    def whitener(self) -> np.ndarray:
        """Per member a (D, D) matrix ``L`` with ``d^2 = |(f - mean) L|^2``, float32.

        ``L`` is the Cholesky factor of the precision ``C^T diag(1/var - 1/var_res) C +
        I / var_res`` (``C`` the components, orthonormal rows), which is the class's
        ``d^2``: one matrix product per member instead of a projection and a residual
        (whose difference of squares also loses digits).
        """
        if self._whitener is None:
            M, k, D = self.components.shape
            L = np.empty((M, D, D), np.float32)
            for m in range(M):
                C, r = self.components[m], self.residual_variance[m]
                W = (C.T * (1.0 / self.variance[m] - 1.0 / r)) @ C + np.eye(D) / r
                L[m] = np.linalg.cholesky(0.5 * (W + W.T))
            self._whitener = L
        return self._whitener

    def raw_distance(self, features: np.ndarray) -> np.ndarray:
        """Distance (mean over members) of N lines' features (M, N, D), not scaled.

        Computed in float32 (the features' precision; relative error ~1e-6)."""
        feats = np.asarray(features, np.float32)
        L = self.whitener()
        mean = self.mean.astype(np.float32)
        d2 = np.empty(feats.shape[:2])
        # on one BLAS thread: after a threaded product OpenBLAS's threads spin for a
        # while, and the verdict's compiled checks that follow on numba's threads ran
        # up to 1.7x slower beside them (about 20 ms per 5,000 lines)
        with _blas_controller().limit(limits=1, user_api="blas"):
            for m in range(feats.shape[0]):  # one member at a time: (N, D) @ (D, D)
                Y = (feats[m] - mean[m]) @ L[m]
                d2[m] = np.einsum("nd,nd->n", Y, Y)
        return np.sqrt(d2 / feats.shape[-1]).mean(axis=0)

    def distance(self, features: np.ndarray) -> np.ndarray:
        """Distance of N lines in units of :attr:`limit` (above 1: out of domain)."""
        return self.raw_distance(features) / self.limit

    def save(self, path: str | os.PathLike) -> Path:
        """Write as a compressed ``.npz`` (float32 arrays)."""
        path = Path(path)
        np.savez_compressed(
            path, mean=self.mean.astype(np.float32),
            components=self.components.astype(np.float32),
            variance=self.variance.astype(np.float32),
            residual_variance=self.residual_variance.astype(np.float32),
            limit=np.float64(self.limit), level=np.float64(self.level),
            fingerprint=np.str_(self.fingerprint),
            **(self.probe.arrays() if self.probe is not None else {}),
        )  # fmt: skip
        return path

    @classmethod
    def load(cls, path: str | os.PathLike) -> EmbeddingReference:
        with np.load(path) as z:
            return cls(z["mean"].astype(float), z["components"].astype(float),
                       z["variance"].astype(float), z["residual_variance"].astype(float),
                       float(z["limit"]), float(z["level"]), str(z["fingerprint"]),
                       ContactProbe.from_arrays(z))  # fmt: skip
