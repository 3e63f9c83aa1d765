"""One answer per map: random-effects pooling of a map's lines, with a shared systematic floor.

A lab measures a map (64 to 512 scan lines in two directions, one load, one tip) and
asks for the contact's <F>, U0, K and eta. This module turns the per-line rows of a
result table into one row per *group* of lines:

- a map's direction (``file, channel, load group, direction``),
- a map's trace and retrace together (``direction = "both"``),
- and, where a change point splits the lines along the slow scan axis, each side
  (``segment = "before"`` / ``"after"``) of every group above.

Model (per target; U0, K and eta on a log scale, <F> linear in nN)
-----------------------------------------------------------------
Line ``i`` of a group gives ``y_i`` (``ln U0`` ...) with its own variance ``v_i``, read
from the row's 95 % interval (``(hi95 - lo95) / (2 * 1.96)``, in log units for the log
targets) or its ``*_std``. The random-effects model is

    y_i = mu + b + u_i + e_i,   u_i ~ N(0, tau^2),   e_i ~ N(0, v_i),   b ~ N(0, sigma_sys^2)

``tau`` is the between-line heterogeneity (the map is not one contact everywhere);
``b`` is the error every line of the map shares and that no number of lines averages
out: the same tip and stated conditions (velocity, temperature), the same lateral
calibration and lattice, and an offset of the same sign in one scan direction.
``tau^2`` is estimated against the lines' variances scaled to how much neighbouring
lines actually differ (:func:`neighbour_scale`: the intervals are calibrated over a
broad prior and say more noise than one map's lines carry), by restricted maximum
likelihood (REML; Fisher scoring started at
the DerSimonian-Laird moment estimate: R. DerSimonian & N. Laird, Control. Clin. Trials
7, 177, 1986; W. Viechtbauer, J. Educ. Behav. Stat. 30, 261, 2005), its 95 % interval by
the Q-profile method (W. Viechtbauer, Stat. Med. 26, 37, 2007). The pooled value is the
inverse-variance weighted mean ``mu = sum w_i y_i / sum w_i`` with ``w_i = 1 / (v_i +
tau^2)``; its interval has the variance

    se^2 = 1 / sum w_i  +  sigma_sys^2

so the interval of a 512-line map shrinks like ``1/sqrt(N)`` only down to the floor
``sigma_sys``. ``sigma_sys`` (per target, for one direction and for both) was calibrated
on simulated maps that carry such shared effects (``benchmarks/map_pooling.py``) and is
stored with the configuration that made it in ``stickslip/resources/map_pooling.json``
(:class:`PoolingCalibration`). Every floor has two parts. For <F>,
``sigma_sys^2 = s_nN^2 + (s_rel |<F>|)^2``: an absolute one in nN (in one scan direction
mostly the crosstalk offset, the same few tenths of a nN whatever the friction) and a
relative one (the lateral calibration, the stated conditions). For ln U0, ln K and
ln eta, ``sigma_sys^2 = s_rel^2 + (s_nN / F_max)^2``: one in log units and the same kind
of offset over the pooled barrier's largest force ``F_max = pi U0 / a``
(:func:`force_scale_nN`), since the line model reads an offset of the force's zero as
a change of the largest force. One number per target made the intervals of
low-friction (low-barrier) maps too narrow and those of high ones too wide, so that the
coverage of a set of maps depended on its parameter points.

The trace and retrace of a map are pooled each on its own, and ``both`` is their mean
(geometric mean for the log targets): an offset that does not reverse with the scan
moves the two directions' <F> in opposite directions and cancels there, as in a friction
loop.

Lines that break the pattern
----------------------------
- *Outlier lines*: a line whose estimate of <F>, U0 or K lies outside the group's
  predictive interval ``mu +- z sqrt(tau^2 + v_i + 1/sum w)`` (the variances scaled
  down to the map's own scatter where the lines agree better than their intervals say,
  :func:`flag_outliers`; ``z`` =
  :attr:`PoolingCalibration.flag_z`) is flagged with a reason and left out of the pool.
  The fit that judges them starts robust (median, MAD) and is iterated without the
  flagged lines, so a few defect lines or spike bursts cannot widen ``tau`` enough to
  hide themselves.
- *Lines that show what the rest of their map does not*: a line crossing a strong
  defect or carrying a spike burst hardly moves its estimate (the line model is robust to
  both), so the estimates cannot find it; what the line shows can. Each row's evidence
  (``evidence_slow``, ``evidence_spikes``, ``evidence_local``:
  :mod:`stickslip.estimators.evidence`, dimensionless, written by the line model;
  :data:`JUDGED_EVIDENCE`) is scored against the group's own evidence,
  ``(e_i - median) / (1.4826 MAD)`` with the median and MAD of the usable lines
  (:func:`evidence_scores`), and a line whose score exceeds
  :attr:`PoolingCalibration.evidence_z` is flagged with a reason naming what it shows
  and left out of the pool (before the estimates are judged, so it widens nothing). Every
  line with evidence is scored, also one without a usable estimate (out of domain,
  refused): it is left out of the pool in any case, and its reason says what it shows.
  ``local`` answers to a defect (a few cycles whose level differs from their
  neighbours'), which ``slow`` cannot tell from the drift and crosstalk of normal lines.
  A surface defect lies at one physical position, seen in both scan directions (in a
  retrace row, which a reader stores reversed, at the mirrored position), while each
  direction's noise is its own: a line seen in both directions is judged for the local
  anomaly by its *paired* score ``(z_trace + z_retrace) / sqrt(2)`` of its two rows'
  robust scores (:func:`paired_scores`; each direction scored against its own usable
  lines, over the whole map direction), against its own threshold
  (``evidence_z["local_both"]``), and both rows are flagged; a line seen in one
  direction (or whose other row has no local evidence) keeps the one-direction rule.
  The position of the anomaly is not compared: the evidence column carries none, and
  the tip's lag behind the support shifts a defect's response between the directions
  by about twice the lag.
  The scale is the map's own, so no scale in nN or nm enters; rows without the columns
  (other estimators, older tables) are judged by their estimates only.
- *A change along the slow scan axis* (a tip change, a domain of another material from
  some line on): a two-segment Gaussian mean-shift model on the lines' estimates in
  line order (every line with an estimate, in domain or not: the lines of another
  material may lie outside the trained domain, which leaves out of the pool but does
  not hide the change; ln U0, ln K, <F> relative to its median; winsorised at 4 robust
  standard deviations),
  the likelihood ratio ``sum_j n ln(RSS0_j / RSS1_j(k))`` maximised over the split ``k``
  (segments of at least :attr:`PoolingCalibration.min_segment` lines), compared with the
  ``change_level`` quantile of its distribution on homogeneous (independent Gaussian)
  series of the same length, computed by Monte Carlo (seeded, cached), and reported only
  where the two sides differ by at least ``min_shift`` (10 %). ``change_line`` is
  the first line of the second segment; each side is then pooled on its own.

Everything here is a pure function of the rows (mappings with the result table's column
names); the module imports nothing from the rest of the package but the evidence's
names (:mod:`stickslip.estimators.evidence`, numpy only), the unit of energy and the
default lattice (:mod:`stickslip.units`, :mod:`stickslip.conditions`, leaf modules).
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from importlib import resources
from typing import Any

import numpy as np
from scipy import optimize, stats

from stickslip.conditions import GRAPHITE_LATTICE_NM
from stickslip.estimators.evidence import EVIDENCE, EVIDENCE_COLUMNS, LOCAL, LOCAL_COLUMN
from stickslip.units import fmax_nN

#: Pooled targets and whether each is pooled on a log scale.
POOL_TARGETS: dict[str, bool] = {"F_mean_nN": False, "U0_eV": True, "K_N_m": True, "eta": True}
#: Targets whose lines are judged for outliers and change points (eta follows from U0, K).
JUDGED = ("F_mean_nN", "U0_eV", "K_N_m")
Z68 = float(stats.norm.ppf(0.84))
Z95 = float(stats.norm.ppf(0.975))
CHI2_1_MEDIAN = float(stats.chi2.ppf(0.5, 1))
#: Fewest lines whose own scatter may narrow the predictive interval (:func:`flag_outliers`)
#: or scale the variances tau is estimated against (:func:`neighbour_scale`).
MIN_BIRGE_LINES = 32
CALIBRATION_FILE = "map_pooling.json"
OUTLIER_REASON = "inconsistent with its map: outside the map's predictive interval"
#: The evidences a map's lines are judged by, and the result table's columns that carry
#: them: those the line model's calibration reads
#: (:data:`~stickslip.estimators.evidence.EVIDENCE`) and the local anomaly
#: (:func:`~stickslip.estimators.evidence.local_evidence`).
JUDGED_EVIDENCE = (*EVIDENCE, LOCAL)
JUDGED_EVIDENCE_COLUMNS = (*EVIDENCE_COLUMNS, LOCAL_COLUMN)
#: What each evidence says a line shows, in the reason of a line flagged for it.
#: The local anomaly judged in trace and retrace together (:func:`paired_scores`): a key of
#: :attr:`PoolingCalibration.evidence_z` and of :data:`EVIDENCE_TEXT`.
LOCAL_BOTH = f"{LOCAL}_both"
EVIDENCE_TEXT = {"slow": "slow, non-periodic content (a drift or a step)", "spikes": "spikes",
                 LOCAL: "a local anomaly of a few stick-slip cycles (a defect)",
                 LOCAL_BOTH: "a local anomaly of a few stick-slip cycles in both scan "
                             "directions (a defect)"}  # fmt: skip
EVIDENCE_REASON = "shows what the other lines of its map do not: "
#: Robust score above which a line is flagged for an evidence, where the calibration
#: file names none: each evidence's quantile, one for all, at which 1 % of the lines of
#: seed 4211's 384 homogeneous maps (96 parameter points) exceed at least one
#: (``benchmarks/map_pooling.py``;
#: ``local`` there counts the rows of one direction, as it judges lines seen in one).
#: The spikes' scores have a long tail (a line's noise, drawn per line, sets how far its
#: slips stand out of it).
DEFAULT_EVIDENCE_Z = {"slow": 3.61, "spikes": 8.59, LOCAL: 2.89, LOCAL_BOTH: 3.07}
#: Fewest lines with evidence whose median and MAD may judge one of them.
MIN_EVIDENCE_LINES = 8
#: Least robust scale of an evidence (ln units, dimensionless): lines that agree closer
#: than this (copies of one line) are not told apart by rounding.
EVIDENCE_SCALE_FLOOR = 0.02
#: The groups table's columns, in order.
GROUP_HEAD = ("group", "file", "channel", "direction", "load", "load_unit", "load_group",
              "segment", "lines", "n_lines", "n_left_out")  # fmt: skip
GROUP_STATS = ("", "_lo68", "_hi68", "_lo95", "_hi95", "_tau", "_tau_lo95", "_tau_hi95")
GROUP_COLUMNS = (*GROUP_HEAD, *(f"{k}{s}" for k in POOL_TARGETS for s in GROUP_STATS),
                 "change_line", "flagged_lines", "note")  # fmt: skip
DIRECTIONS = ("trace", "retrace")
BOTH = "both"


# ---------------------------------------------------------------------------- calibration


@dataclass(frozen=True)
class PoolingCalibration:
    """The calibrated constants of the pooling, and the configuration that made them.

    Attributes
    ----------
    sys_single : dict of str to float
        ``sigma_sys`` per target for one scan direction: log units (relative) for U0, K,
        eta; relative to ``|<F>|`` for <F>.
    sys_both : dict of str to float
        The same for trace and retrace pooled together.
    sys_single_nN, sys_both_nN : float
        The absolute part of <F>'s floor, nN (one direction; both): ``sigma_sys`` of <F>
        is ``hypot(sys_nN, sys_rel |<F>|)`` (0: relative only).
    sys_single_offset_nN, sys_both_offset_nN : dict of str to float
        Per log target, the part of its floor that an offset of the force's zero puts
        on it, nN (one direction; both): ``sigma_sys`` of ``ln U0`` (K, eta) is
        ``hypot(sys, offset_nN / F_max)``, ``F_max = pi U0 / a`` the pooled barrier's
        largest force (:func:`force_scale_nN`); missing targets: 0.
    flag_z : float
        Half-width of the predictive interval, in standard deviations, outside which a
        line is flagged.
    change_level : float
        Quantile of the homogeneous-map distribution of the change statistic above
        which a change point is reported.
    min_segment : int
        Fewest lines on either side of a change point.
    min_shift : float
        Smallest change reported: the two sides' means must differ by at least this in
        ln U0, ln K or <F> relative to its median (0.1: 10 %); a smaller shift on a
        large map is significant but no change of contact.
    change_table : dict
        The change threshold precomputed on a grid of group sizes
        (:func:`threshold_table`; empty: computed when a group needs it).
    evidence_z : dict of str to float
        Per evidence (:data:`JUDGED_EVIDENCE`), the robust score
        (:func:`evidence_scores`) above which a line is flagged as showing what the other
        lines of its map do not, and (:data:`LOCAL_BOTH`) the threshold of the local
        anomaly's score in both directions together (:func:`paired_scores`); chosen on the
        calibration maps so that few normal lines pass them. Missing names take
        :data:`DEFAULT_EVIDENCE_Z`.
    config : dict
        How the constants were made (benchmark, seeds, maps, date).
    """

    sys_single: dict[str, float] = field(default_factory=lambda: dict.fromkeys(POOL_TARGETS, 0.05))
    sys_both: dict[str, float] = field(default_factory=lambda: dict.fromkeys(POOL_TARGETS, 0.05))
    sys_single_nN: float = 0.0
    sys_both_nN: float = 0.0
    sys_single_offset_nN: dict[str, float] = field(default_factory=dict)
    sys_both_offset_nN: dict[str, float] = field(default_factory=dict)
    flag_z: float = 3.5
    change_level: float = 0.99
    min_segment: int = 4
    min_shift: float = 0.1
    evidence_z: dict[str, float] = field(default_factory=lambda: dict(DEFAULT_EVIDENCE_Z))
    change_table: dict[str, Any] = field(default_factory=dict)
    config: dict[str, Any] = field(default_factory=dict)

    def sys(self, key: str, direction: str) -> float:
        """``sigma_sys`` of a target for a direction (``trace``, ``retrace`` or ``both``)."""
        table = self.sys_both if direction == BOTH else self.sys_single
        return float(table.get(key, 0.0))

    def sys_nN(self, direction: str) -> float:
        """The absolute part of <F>'s floor (nN) for a direction."""
        return float(self.sys_both_nN if direction == BOTH else self.sys_single_nN)

    def sys_abs(self, key: str, direction: str) -> float:
        """The part of a target's floor in nN for a direction: <F>'s absolute part
        (:meth:`sys_nN`), or a log target's offset part (over ``F_max``)."""
        if not POOL_TARGETS[key]:
            return self.sys_nN(direction)
        table = self.sys_both_offset_nN if direction == BOTH else self.sys_single_offset_nN
        return float(table.get(key, 0.0))

    def evidence_threshold(self) -> np.ndarray:
        """:attr:`evidence_z` in the order of :data:`JUDGED_EVIDENCE`."""
        return np.array([float(self.evidence_z.get(k, DEFAULT_EVIDENCE_Z[k]))
                         for k in JUDGED_EVIDENCE])  # fmt: skip

    def paired_threshold(self) -> float:
        """The threshold of the local anomaly judged in both scan directions
        (:data:`LOCAL_BOTH` of :attr:`evidence_z`)."""
        return float(self.evidence_z.get(LOCAL_BOTH, DEFAULT_EVIDENCE_Z[LOCAL_BOTH]))

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> PoolingCalibration:
        names = {f.name for f in dataclasses.fields(cls)}
        return cls(**{k: v for k, v in d.items() if k in names})

    def save(self, path: Any) -> None:
        with open(path, "w") as fh:
            json.dump(self.to_dict(), fh, indent=1, sort_keys=True)
            fh.write("\n")


@lru_cache(maxsize=1)
def bundled_calibration() -> PoolingCalibration:
    """The calibration shipped in ``stickslip/resources/map_pooling.json`` (defaults if
    the file is missing)."""
    ref = resources.files("stickslip") / "resources" / CALIBRATION_FILE
    try:
        return PoolingCalibration.from_dict(json.loads(ref.read_text()))
    except (FileNotFoundError, OSError):
        return PoolingCalibration()


# ---------------------------------------------------------------------------- maths


@dataclass(frozen=True)
class RandomEffectsFit:
    """A random-effects fit of ``y_i`` with within-line variances ``v_i``.

    Attributes
    ----------
    mu : float
        Pooled mean (weights ``1 / (v_i + tau2)``).
    se : float
        Its statistical standard error ``sqrt(1 / sum w)`` (no systematic term).
    tau2, tau2_lo, tau2_hi : float
        Between-line variance and its 95 % Q-profile interval.
    q : float
        Cochran's Q at ``tau2 = 0``.
    k : int
        Number of lines.
    """

    mu: float
    se: float
    tau2: float
    tau2_lo: float
    tau2_hi: float
    q: float
    k: int


def _weighted(y: np.ndarray, v: np.ndarray, tau2: float) -> tuple[float, np.ndarray]:
    w = 1.0 / (v + tau2)
    return float(np.sum(w * y) / np.sum(w)), w


def dersimonian_laird(y: Sequence[float], v: Sequence[float]) -> float:
    """DerSimonian-Laird moment estimate of the between-line variance ``tau^2``.

    ``tau2 = max(0, (Q - (k - 1)) / (S1 - S2 / S1))`` with ``w = 1/v``, ``S1 = sum w``,
    ``S2 = sum w^2`` and Cochran's ``Q = sum w (y - mu_w)^2`` (DerSimonian & Laird 1986).
    """
    y, v = np.asarray(y, float), np.asarray(v, float)
    if y.size < 2:
        return 0.0
    mu, w = _weighted(y, v, 0.0)
    q = float(np.sum(w * (y - mu) ** 2))
    s1, s2 = float(w.sum()), float(np.sum(w * w))
    return max(0.0, (q - (y.size - 1)) / (s1 - s2 / s1))


def reml_tau2(y: Sequence[float], v: Sequence[float], tol: float = 1e-10,
              max_iter: int = 100) -> float:  # fmt: skip
    """REML estimate of ``tau^2``, iterated from the DerSimonian-Laird value.

    The REML fixed point (Viechtbauer 2005; the Fisher-scoring step of the restricted
    likelihood): ``tau2 = sum w^2 ((y - mu)^2 - v) / sum w^2 + 1 / sum w`` with
    ``w = 1 / (v + tau2)`` and ``mu`` their weighted mean, truncated at zero.
    """
    y, v = np.asarray(y, float), np.asarray(v, float)
    if y.size < 2:
        return 0.0
    tau2 = dersimonian_laird(y, v)
    for _ in range(max_iter):
        mu, w = _weighted(y, v, tau2)
        w2 = w * w
        new = float(np.sum(w2 * ((y - mu) ** 2 - v)) / np.sum(w2) + 1.0 / np.sum(w))
        new = max(0.0, new)
        if abs(new - tau2) <= tol * max(1.0, tau2):
            return new
        tau2 = new
    return tau2


def q_profile(y: Sequence[float], v: Sequence[float], level: float = 0.95
              ) -> tuple[float, float]:  # fmt: skip
    """Q-profile confidence interval of ``tau^2`` (Viechtbauer 2007).

    The generalised ``Q(tau2) = sum (y - mu(tau2))^2 / (v + tau2)`` falls with ``tau2``;
    the interval is where it lies between the ``(1 +- level)/2`` quantiles of chi^2 with
    ``k - 1`` degrees of freedom (an end at 0 where even ``Q(0)`` is below).
    """
    y, v = np.asarray(y, float), np.asarray(v, float)
    k = y.size
    if k < 2:
        return math.nan, math.nan

    def qgen(t2: float) -> float:
        mu, w = _weighted(y, v, t2)
        return float(np.sum(w * (y - mu) ** 2))

    hi_q = stats.chi2.ppf(1 - (1 - level) / 2, k - 1)
    lo_q = stats.chi2.ppf((1 - level) / 2, k - 1)
    top = max(10.0 * float(np.var(y)) + 10.0 * float(v.max()), 1e-12)

    def root(target: float) -> float:
        if qgen(0.0) <= target:
            return 0.0
        upper = top
        while qgen(upper) > target and upper < 1e12:
            upper *= 10.0
        return float(optimize.brentq(lambda t: qgen(t) - target, 0.0, upper, xtol=1e-14))

    return root(hi_q), root(lo_q)


def random_effects(y: Sequence[float], v: Sequence[float], method: str = "REML"
                   ) -> RandomEffectsFit:  # fmt: skip
    """Random-effects pooling of ``y`` with variances ``v`` (``method``: REML or DL)."""
    y, v = np.asarray(y, float), np.asarray(v, float)
    if y.size == 0:
        return RandomEffectsFit(math.nan, math.nan, math.nan, math.nan, math.nan, math.nan, 0)
    tau2 = reml_tau2(y, v) if method.upper() == "REML" else dersimonian_laird(y, v)
    mu, w = _weighted(y, v, tau2)
    mu0, w0 = _weighted(y, v, 0.0)
    lo, hi = q_profile(y, v)
    return RandomEffectsFit(mu=mu, se=float(1.0 / math.sqrt(w.sum())), tau2=tau2, tau2_lo=lo,
                            tau2_hi=hi, q=float(np.sum(w0 * (y - mu0) ** 2)), k=int(y.size))


def line_scale(value: np.ndarray, lo95: np.ndarray, hi95: np.ndarray, std: np.ndarray,
               log: bool) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Each line's estimate on the pooling scale and its variance there.

    ``log``: ``y = ln value``, ``sd = (ln hi95 - ln lo95) / (2 z95)`` (else ``std /
    value``); linear: ``sd = (hi95 - lo95) / (2 z95)`` (else ``std``). NaN where the
    line has no usable estimate.
    """
    value, lo95, hi95, std = (np.asarray(a, float) for a in (value, lo95, hi95, std))
    with np.errstate(invalid="ignore", divide="ignore"):
        if log:
            y = np.where(value > 0, np.log(np.where(value > 0, value, 1.0)), np.nan)
            ok = (lo95 > 0) & (hi95 > lo95)
            sd = np.where(ok, (np.log(np.where(ok, hi95, 1.0)) - np.log(np.where(ok, lo95, 1.0)))
                          / (2 * Z95), std / value)  # fmt: skip
        else:
            y = value
            sd = np.where(hi95 > lo95, (hi95 - lo95) / (2 * Z95), std)
    sd = np.where(np.isfinite(sd) & (sd > 0), sd, np.nan)
    return y, sd * sd


def _birge_ratio(r2: np.ndarray) -> float:
    """The robust Birge ratio of squared standardised deviations ``r2``:
    ``median(r2) / median(chi^2_1)``, capped at 1 (lines never scatter more than their
    variances say, here) and floored at 1e-4."""
    return float(min(1.0, max(np.median(r2) / CHI2_1_MEDIAN, 1e-4)))


def _robust_start(y: np.ndarray, v: np.ndarray) -> tuple[float, float]:
    mu = float(np.median(y))
    s = 1.4826 * float(np.median(np.abs(y - mu)))
    return mu, max(0.0, s * s - float(np.median(v)))


def flag_outliers(Y: np.ndarray, V: np.ndarray, z: float, max_iter: int = 10) -> np.ndarray:
    """Lines outside the group's predictive interval in any column.

    Parameters
    ----------
    Y, V : ndarray (n, p)
        Estimates on the pooling scale and their variances (NaN: no estimate).
    z : float
        Half-width of the predictive interval ``mu +- z sqrt(tau2 + v_i + se^2)``.

    Returns
    -------
    ndarray (n,) of bool
        True for a flagged line. Starts from a robust fit (median and MAD) and refits
        without the flagged lines until the flags settle.

    Where the lines scatter less than their own intervals say (line intervals are
    calibrated over a broad prior, the lines of one map agree more closely), the
    within-line variances are scaled down by the robust Birge ratio
    ``median(r^2) / 0.455`` (``r`` the standardised residuals; never scaled up; only
    with at least :data:`MIN_BIRGE_LINES` lines), so the predictive interval follows the
    map's own scatter.
    """
    Y, V = np.atleast_2d(Y), np.atleast_2d(V)
    n, p = Y.shape
    usable = np.all(np.isfinite(Y) & np.isfinite(V), axis=1)
    flags = np.zeros(n, bool)
    if usable.sum() < 3:
        return flags
    def birge(j: int, keep: np.ndarray, mu: float, tau2: float) -> float:
        if keep.sum() < MIN_BIRGE_LINES:  # too few lines to tell their scatter
            return 1.0
        return _birge_ratio((Y[keep, j] - mu) ** 2 / (tau2 + V[keep, j]))

    fits = []
    for j in range(p):
        mu, tau2 = _robust_start(Y[usable, j], V[usable, j])
        fits.append((mu, tau2, 0.0, birge(j, usable, mu, tau2)))
    for _ in range(max_iter):
        dev = np.zeros(n)
        for j, (mu, tau2, se2, b) in enumerate(fits):
            r = np.abs(Y[:, j] - mu) / np.sqrt(b * (tau2 + V[:, j]) + se2)
            dev = np.maximum(dev, np.where(usable, r, 0.0))
        new = usable & (dev > z)
        keep = usable & ~new
        if keep.sum() < 3 or np.array_equal(new, flags):
            flags = new if keep.sum() >= 3 else flags
            break
        flags = new
        fits = []
        for j in range(p):
            tau2 = reml_tau2(Y[keep, j], V[keep, j])
            mu, w = _weighted(Y[keep, j], V[keep, j], tau2)
            b = birge(j, keep, mu, tau2)
            fits.append((mu, tau2, b / float(w.sum()), b))
    return flags


# ---------------------------------------------------------------------------- evidence


def evidence_scores(E: np.ndarray, reference: np.ndarray | None = None) -> np.ndarray:
    """Each line's evidence against its group's own: ``(e - median) / (1.4826 MAD)``.

    Parameters
    ----------
    E : ndarray (n, p)
        The group's lines' evidence (NaN: none).
    reference : ndarray (n,) of bool, optional
        The lines whose median and MAD judge every line (the map's usable lines, so
        that lines without a usable estimate are judged by the same yardstick and do
        not move it); default all.

    Returns
    -------
    ndarray (n, p)
        Robust scores, per column from the reference lines with a finite value (the MAD
        floored at :data:`EVIDENCE_SCALE_FLOOR`); NaN where a line has no evidence or
        the column fewer than :data:`MIN_EVIDENCE_LINES` reference lines.
    """
    E = np.atleast_2d(np.asarray(E, float))
    ref = np.ones(E.shape[0], bool) if reference is None else np.asarray(reference, bool)
    out = np.full(E.shape, np.nan)
    for j in range(E.shape[1]):
        ok = np.isfinite(E[:, j])
        base = E[ok & ref, j]
        if base.size < MIN_EVIDENCE_LINES:
            continue
        med = float(np.median(base))
        # the group's own scale, so a noisier map is judged by its own spread
        s = max(1.4826 * float(np.median(np.abs(base - med))), EVIDENCE_SCALE_FLOOR)
        out[ok, j] = (E[ok, j] - med) / s
    return out


def flag_evidence(E: np.ndarray, z: Sequence[float],
                  reference: np.ndarray | None = None) -> np.ndarray:  # fmt: skip
    """Lines that show more of an evidence than their group: score above ``z`` (one per
    column of ``E``; scores by :func:`evidence_scores` against the ``reference`` lines).
    Only excess counts (a line that shows less is cleaner, not odd).

    Returns
    -------
    ndarray (n, p) of bool
    """
    S = evidence_scores(E, reference)
    with np.errstate(invalid="ignore"):
        return np.isfinite(S) & (S > np.asarray(z, float)[None, :])


def evidence_reason(shown: Sequence[bool], both: bool = False) -> str:
    """The reason of a line flagged for the evidence ``shown`` (bool per
    :data:`JUDGED_EVIDENCE`) and, with ``both``, for the local anomaly in both scan
    directions (:data:`LOCAL_BOTH`)."""
    texts = [EVIDENCE_TEXT[k] for k, on in zip(JUDGED_EVIDENCE, shown, strict=True) if on]
    return EVIDENCE_REASON + " and ".join(texts + ([EVIDENCE_TEXT[LOCAL_BOTH]] if both else []))


def paired_scores(z_a: np.ndarray, z_b: np.ndarray) -> np.ndarray:
    """The local anomaly of a line judged in both scan directions: ``(z_a + z_b) /
    sqrt(2)`` of its two rows' robust scores (:func:`evidence_scores` against each
    direction's own lines; NaN where either is).

    A defect of the surface lies at one physical position, so it shows in both
    directions' rows (a reader stores the retrace reversed, so at the mirrored position
    of the row's own x), while each direction's noise is its own: for a normal line the
    two scores are about independent and the sum has the spread of one, a defect's
    excess adds up (sqrt(2) times one direction's, where it shows alike in both). Only
    excess counts, as for one direction. Dimensionless, no scale of its own.
    """
    return (np.asarray(z_a, float) + np.asarray(z_b, float)) / math.sqrt(2.0)


# ---------------------------------------------------------------------------- change point


def _winsorise(y: np.ndarray, k: float = 4.0) -> np.ndarray:
    med = np.median(y)
    s = 1.4826 * np.median(np.abs(y - med))
    if not s > 0:
        s = float(np.std(y)) or 1.0
    return np.clip(y, med - k * s, med + k * s)


def _split_statistics(Y: np.ndarray, min_segment: int) -> np.ndarray:
    """``S(k)`` (:func:`change_statistic`) at every allowed split ``k = min_segment ..
    n - min_segment`` of each of a batch of series ``Y`` (r, n, p), at once: (r, splits)."""
    n = Y.shape[1]
    c1 = np.cumsum(Y, axis=1)
    c2 = np.cumsum(Y * Y, axis=1)
    tot1, tot2 = c1[:, -1:], c2[:, -1:]
    rss0 = np.maximum(tot2 - tot1 * tot1 / n, 1e-300)
    k = np.arange(min_segment, n - min_segment + 1)
    a1, a2 = c1[:, k - 1], c2[:, k - 1]
    kk = k[None, :, None].astype(float)
    rss1 = np.maximum((a2 - a1 * a1 / kk) + ((tot2 - a2) - (tot1 - a1) ** 2 / (n - kk)), 1e-300)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = n * np.log(rss0 / rss1)
    return np.where(np.isfinite(s), s, 0.0).sum(axis=2)


def change_statistic(Y: np.ndarray, min_segment: int) -> np.ndarray:
    """The two-segment likelihood ratio at every split (NaN where not allowed).

    ``S(k) = sum_j n ln(RSS0_j / (RSS_j(:k) + RSS_j(k:)))`` for columns ``j`` of ``Y``
    (n, p): Gaussian mean shift with a common unknown variance per column. ``S(k)`` is
    the split before row ``k``.
    """
    Y = np.atleast_2d(np.asarray(Y, float))
    if Y.shape[0] == 1 and Y.shape[1] > 1 and Y.ndim == 2:
        Y = Y.T
    n = Y.shape[0]
    out = np.full(n, np.nan)
    if n < 2 * min_segment:
        return out
    out[min_segment:n - min_segment + 1] = _split_statistics(Y[None], min_segment)[0]
    return out


@lru_cache(maxsize=256)
def change_threshold(n: int, p: int, level: float, min_segment: int, reps: int = 2000) -> float:
    """The ``level`` quantile of ``max_k S(k)`` on ``n`` independent Gaussian rows of ``p``
    columns (Monte Carlo, seed 4299, cached): the false-alarm threshold for a
    homogeneous group. Batches of series at once, drawn in the order one at a time
    would draw them (the same numbers)."""
    rng = np.random.default_rng([4299, n, p, min_segment])
    chunk = max(1, min(reps, 2_000_000 // max(n * p, 1)))
    best = np.concatenate([
        _split_statistics(rng.standard_normal((min(chunk, reps - a), n, p)),
                          min_segment).max(axis=1)
        for a in range(0, reps, chunk)])  # fmt: skip
    return float(np.quantile(best, level))


#: Group sizes at which :func:`threshold_table` holds the change threshold (between them
#: it is interpolated in ln n; the quantile grows slowly and smoothly with n).
THRESHOLD_GRID = (8, 10, 12, 14, 16, 20, 24, 28, 32, 40, 48, 56, 64, 80, 96, 112, 128, 160,
                  192, 224, 256, 320, 384, 448, 512, 640, 768, 896, 1024, 1280, 1536, 2048)


def threshold_table(level: float, min_segment: int, columns: Sequence[int] = (3, 6),
                    reps: int = 20000) -> dict[str, Any]:  # fmt: skip
    """The change threshold on :data:`THRESHOLD_GRID` for ``columns`` (one direction's
    judged targets, and both directions' side by side), to ship with the calibration:
    the Monte Carlo of a group of hundreds of lines costs more than the rest of the
    pooling, and a map's groups (each direction, both) each have their own size.

    Per column count, :func:`change_threshold` with ``reps`` series at every size, then a
    quadratic in ln n fitted to them by least squares, whose values the table holds: the
    quantile grows slowly and smoothly with n, and the fit averages out the Monte Carlo's
    noise (at 2,000 series per size the 0.99 quantile scatters by several percent from
    one size to the next)."""
    grid = np.asarray(THRESHOLD_GRID, float)
    out: dict[str, Any] = {"level": level, "min_segment": min_segment, "reps": reps,
                           "n": list(THRESHOLD_GRID)}  # fmt: skip
    for p in columns:
        raw = [change_threshold(int(n), p, level, min_segment, reps) for n in grid]
        coef = np.polyfit(np.log(grid), raw, 2)
        out[str(p)] = [round(float(v), 5) for v in np.polyval(coef, np.log(grid))]
    return out


def _tabled_threshold(table: Mapping[str, Any] | None, n: int, p: int, level: float,
                      min_segment: int) -> float:  # fmt: skip
    """The change threshold from ``table`` (:func:`threshold_table`) where it was made for
    this ``level`` and ``min_segment`` and holds ``p`` columns and the size ``n``
    (interpolated in ln n), else :func:`change_threshold`."""
    if (table and table.get("level") == level and table.get("min_segment") == min_segment
            and str(p) in table):  # fmt: skip
        grid = np.asarray(table["n"], float)
        if grid[0] <= n <= grid[-1]:
            return float(np.interp(math.log(n), np.log(grid), np.asarray(table[str(p)], float)))
    return change_threshold(n, p, level, min_segment)


@dataclass(frozen=True)
class ChangePoint:
    """A change point along the slow scan axis: ``index`` (row of the first line after
    the change; None where none was found), the statistic and its threshold."""

    index: int | None
    statistic: float
    threshold: float


def find_change(Y: np.ndarray, level: float = 0.99, min_segment: int = 4,
                min_shift: float = 0.0, table: Mapping[str, Any] | None = None) -> ChangePoint:
    """The most likely single change point of the rows of ``Y`` (n, p), in line order.

    Columns are winsorised at 4 robust standard deviations (so a burst of a few wild
    lines cannot pose as a change) and rows with a NaN dropped by the caller. A change is
    reported where ``max_k S(k)`` (:func:`change_statistic`) exceeds
    :func:`change_threshold` at ``level`` (read from ``table``, :func:`threshold_table`,
    where it holds the case) and the two sides' means differ by at least ``min_shift``
    in some column.
    """
    Y = np.asarray(Y, float)
    if Y.ndim == 1:
        Y = Y[:, None]
    n, p = Y.shape
    if n < max(2 * min_segment, 8):
        return ChangePoint(None, math.nan, math.nan)
    W = np.column_stack([_winsorise(Y[:, j]) for j in range(p)])
    s = change_statistic(W, min_segment)
    k = int(np.nanargmax(s))
    thr = _tabled_threshold(table, n, p, level, min_segment)
    shift = float(np.max(np.abs(W[:k].mean(axis=0) - W[k:].mean(axis=0))))
    found = s[k] > thr and shift >= min_shift
    return ChangePoint(k if found else None, float(s[k]), thr)


# ---------------------------------------------------------------------------- groups


def _num(value: Any) -> float:
    if value is None or isinstance(value, (bool, np.bool_, str)):
        try:
            return float(value) if isinstance(value, str) and value.strip() else math.nan
        except ValueError:
            return math.nan
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


def _out_of_domain(row: Mapping[str, Any]) -> bool:
    v = row.get("in_domain")
    if v is None or v == "" or (isinstance(v, float) and math.isnan(v)):
        return False
    if isinstance(v, str):
        return v.strip().lower() in ("0", "false", "no", "n", "f")
    return not bool(v)


def _usable(row: Mapping[str, Any]) -> bool:
    return row.get("quality") in ("ok", None, "") and not _out_of_domain(row) \
        and math.isfinite(_num(row.get("U0_eV")))  # fmt: skip


def _line(row: Mapping[str, Any]) -> int | None:
    v = _num(row.get("line"))
    return int(v) if math.isfinite(v) else None


def _blank(v: Any) -> Any:
    return None if v is None or (isinstance(v, float) and math.isnan(v)) or v == "" else v


def map_keys(rows: Sequence[Mapping[str, Any]]) -> dict[tuple, list[int]]:
    """Row indices of each map group: ``(file, channel, load_group, load)`` -> rows with a
    ``line`` and a direction of ``trace`` or ``retrace`` (maps of at least two lines)."""
    out: dict[tuple, list[int]] = {}
    for i, r in enumerate(rows):
        if _line(r) is None or r.get("direction") not in DIRECTIONS:
            continue
        key = (str(r.get("file") or ""), str(r.get("channel") or ""),
               _blank(r.get("load_group")), _blank(r.get("load")))  # fmt: skip
        out.setdefault(key, []).append(i)
    return {k: v for k, v in out.items() if len({_line(rows[i]) for i in v}) >= 2}


@dataclass
class _Lines:
    """One direction's lines of a group, on the pooling scale."""

    index: np.ndarray  # row indices into the table
    line: np.ndarray  # line numbers
    y: dict[str, np.ndarray]
    v: dict[str, np.ndarray]
    usable: np.ndarray
    e: np.ndarray  # (n, len(JUDGED_EVIDENCE)) the rows' evidence, NaN where a row has none
    #: lines with an estimate of every judged target, in domain or not (what the change
    #: point is sought in: a domain of another material may lie outside the trained one)
    estimated: np.ndarray
    #: the line's local anomaly in both directions (:func:`paired_scores`); NaN where the
    #: line is seen in one direction (or either row has no local evidence)
    paired: np.ndarray | None = None
    #: the lattice spacing the rows were estimated with (their median), nm
    lattice_nm: float = GRAPHITE_LATTICE_NM

    def take(self, sel: np.ndarray) -> _Lines:
        paired = None if self.paired is None else self.paired[sel]
        return _Lines(self.index[sel], self.line[sel], {k: a[sel] for k, a in self.y.items()},
                      {k: a[sel] for k, a in self.v.items()}, self.usable[sel],
                      self.e[sel], self.estimated[sel], paired, self.lattice_nm)  # fmt: skip


def _lines(rows: Sequence[Mapping[str, Any]], idx: Sequence[int]) -> _Lines:
    idx = sorted(idx, key=lambda i: _line(rows[i]))
    sub = [rows[i] for i in idx]
    y, v = {}, {}
    for key, log in POOL_TARGETS.items():
        cols = [np.array([_num(r.get(c)) for r in sub])
                for c in (key, f"{key}_lo95", f"{key}_hi95", f"{key}_std")]
        y[key], v[key] = line_scale(*cols, log=log)
    estimated = np.array([r.get("quality") in ("ok", None, "") for r in sub], bool)
    for key in JUDGED:
        estimated &= np.isfinite(y[key])
    usable = estimated & np.array([_usable(r) for r in sub], bool)
    for key in JUDGED:
        usable &= np.isfinite(v[key])
    e = np.array([[_num(r.get(c)) for c in JUDGED_EVIDENCE_COLUMNS] for r in sub], float)
    a = np.array([_num(r.get("lattice_nm")) for r in sub])
    a = a[np.isfinite(a) & (a > 0)]
    return _Lines(np.asarray(idx, int), np.array([_line(r) for r in sub]), y, v, usable,
                  e.reshape(len(sub), len(JUDGED_EVIDENCE_COLUMNS)), estimated,
                  lattice_nm=float(np.median(a)) if a.size else GRAPHITE_LATTICE_NM)  # fmt: skip


@dataclass(frozen=True)
class TargetPool:
    """One target pooled over a group, on the pooling scale (log for U0, K, eta)."""

    mu: float
    se_stat: float
    sys: float
    tau2: float
    tau2_lo: float
    tau2_hi: float
    n: int

    @property
    def se(self) -> float:
        return math.sqrt(self.se_stat ** 2 + self.sys ** 2)


def force_scale_nN(ln_U0: float, lattice_nm: float) -> float:
    """The largest force of a pooled barrier, ``F_max = pi U0 / a``
    (:func:`stickslip.units.fmax_nN`); infinite where the pooled ln U0 is not finite, so
    that the offset part of a floor vanishes where there is no barrier to scale it.

    The scale of a log target's offset part of the floor: an offset ``o`` of the force's
    zero moves the line model's ln U0 by about ``o / F_max``
    (``benchmarks/offset_response.py``).

    Parameters
    ----------
    ln_U0 : float
        ln of the barrier in eV (the pooling scale of U0).
    lattice_nm : float
        The lattice spacing, nm.

    Returns
    -------
    float
        ``F_max`` in nN.
    """
    return float(fmax_nN(math.exp(ln_U0), lattice_nm)) if math.isfinite(ln_U0) else math.inf


def _floor(mu: float, sys_rel: float, log: bool, sys_abs: float,
           fmax_nN: float = math.inf) -> float:  # fmt: skip
    """The systematic floor of a pooled value ``mu``: ``hypot(sys_rel, sys_abs / F_max)``
    (log units) for a log target, where an offset ``sys_abs`` (nN) of the force's zero
    moves the barrier by about its share of the largest force ``fmax_nN``;
    ``hypot(sys_abs, sys_rel |mu|)`` for a linear one."""
    if log:
        return math.hypot(sys_rel, sys_abs / fmax_nN) if sys_abs > 0.0 else sys_rel
    return math.hypot(sys_abs, sys_rel * abs(mu))


def neighbour_scale(y: np.ndarray, v: np.ndarray) -> float:
    """How much less a map's lines differ from their neighbours than their intervals say.

    Lines in their order along the slow scan axis: the robust Birge ratio of successive
    differences, ``median((y_{i+1} - y_i)^2 / (v_i + v_{i+1})) / median(chi^2_1)``,
    capped at 1 (never more than the intervals say) and floored at 1e-4; 1 with fewer
    than :data:`MIN_BIRGE_LINES` lines.

    A line's interval is calibrated over a broad prior of effects, and the lines of one
    map, sharing tip, conditions and instrument, scatter less than it says: taken at
    face value, the intervals leave no room for the between-line spread ``tau`` (a map
    whose U0 varies by +-20 % along the slow axis came out at ``tau = 0``). Neighbouring
    lines differ by their noise and by the little the contact changes from one line to
    the next, so their differences measure the noise without a model of it (von
    Neumann's successive differences; J. von Neumann, Ann. Math. Stat. 12, 367, 1941);
    a spread that varies slowly along the map cancels in them and stays in ``tau``. A
    spread from line to line with no order along the map cannot be told from noise
    this way, and is left to the intervals as before (the scale is never above 1).
    """
    y, v = np.asarray(y, float), np.asarray(v, float)
    if y.size < MIN_BIRGE_LINES:
        return 1.0
    return _birge_ratio(np.diff(y) ** 2 / (v[1:] + v[:-1]))


def pool_target(y: np.ndarray, v: np.ndarray, sys_rel: float, log: bool,
                sys_abs: float = 0.0, fmax_nN: float = math.inf) -> TargetPool:  # fmt: skip
    """Pool one target's lines (in their order along the slow scan axis): random effects
    on the variances scaled by :func:`neighbour_scale`, plus the systematic floor
    (:func:`_floor`: for a log target ``sys_rel`` in log units and ``sys_abs`` nN over
    the largest force ``fmax_nN``; for a linear one ``sys_rel`` relative to ``|mu|`` and
    ``sys_abs`` in the target's unit; added in quadrature)."""
    ok = np.isfinite(y) & np.isfinite(v)
    fit = random_effects(y[ok], neighbour_scale(y[ok], v[ok]) * v[ok])
    sys = _floor(fit.mu, sys_rel, log, sys_abs, fmax_nN)
    return TargetPool(fit.mu, fit.se, sys, fit.tau2, fit.tau2_lo, fit.tau2_hi, fit.k)


def _combine(a: TargetPool, b: TargetPool, sys: float, log: bool,
             sys_abs: float = 0.0, fmax_nN: float = math.inf) -> TargetPool:  # fmt: skip
    """Trace and retrace pooled together: their mean, the statistical parts averaged,
    the floor of both directions."""
    mu = 0.5 * (a.mu + b.mu)
    se_stat = 0.5 * math.sqrt(a.se_stat ** 2 + b.se_stat ** 2)
    s = _floor(mu, sys, log, sys_abs, fmax_nN)
    return TargetPool(mu, se_stat, s, 0.5 * (a.tau2 + b.tau2), 0.5 * (a.tau2_lo + b.tau2_lo),
                      0.5 * (a.tau2_hi + b.tau2_hi), a.n + b.n)  # fmt: skip


def _target_columns(key: str, p: TargetPool, log: bool) -> dict[str, float]:
    if p.n == 0 or not math.isfinite(p.mu):
        return {f"{key}{s}": math.nan for s in GROUP_STATS}
    back = np.exp if log else (lambda x: x)
    out = {key: float(back(p.mu))}
    for z, lv in ((Z68, "68"), (Z95, "95")):
        out[f"{key}_lo{lv}"] = float(back(p.mu - z * p.se))
        out[f"{key}_hi{lv}"] = float(back(p.mu + z * p.se))
    out[f"{key}_tau"] = math.sqrt(p.tau2)
    out[f"{key}_tau_lo95"] = math.sqrt(p.tau2_lo) if math.isfinite(p.tau2_lo) else math.nan
    out[f"{key}_tau_hi95"] = math.sqrt(p.tau2_hi) if math.isfinite(p.tau2_hi) else math.nan
    return out


def _judge(lines: _Lines, cal: PoolingCalibration) -> np.ndarray:
    """Why each line is flagged (object array of str over all lines; "" where it is not):
    lines that show what the others do not (every line with evidence, scored against
    the usable lines: a line out of domain that shows spikes says so; a line seen in
    both directions is judged for the local anomaly by its paired score,
    :func:`paired_scores`, instead of this direction's alone), then, among the other
    usable lines, lines whose estimates are outside the predictive interval."""
    why = np.full(lines.index.size, "", object)
    odd = np.zeros(lines.index.size, bool)
    if lines.usable.any():
        shown = flag_evidence(lines.e, cal.evidence_threshold(), lines.usable)
        both = np.zeros(lines.index.size, bool)
        if lines.paired is not None:
            paired = np.isfinite(lines.paired)
            shown[paired, JUDGED_EVIDENCE.index(LOCAL)] = False
            with np.errstate(invalid="ignore"):
                both = paired & (lines.paired > cal.paired_threshold())
        odd = shown.any(axis=1) | both
        for i in np.flatnonzero(odd):
            why[i] = evidence_reason(shown[i], bool(both[i]))
    # judged without them: a defect line must not widen tau for the others
    sel = np.flatnonzero(lines.usable & ~odd)
    if sel.size:
        Y = np.column_stack([lines.y[k][sel] for k in JUDGED])
        V = np.column_stack([lines.v[k][sel] for k in JUDGED])
        why[sel[flag_outliers(Y, V, cal.flag_z)]] = OUTLIER_REASON
    return why


def _change(parts: Sequence[_Lines], cal: PoolingCalibration) -> int | None:
    """The change line of one or two directions' lines (columns side by side, lines that
    have an estimate in every direction, in domain or not: where the lines after a tip
    change or inside a domain of another material leave the trained domain, their
    estimates still show the change, and only a few in-domain lines would be left to
    show it), or None."""
    common = set.intersection(*(set(p.line[p.estimated].tolist()) for p in parts))
    order = np.array(sorted(common), int)
    if order.size < 2 * cal.min_segment:
        return None
    cols = []
    for p in parts:
        pos = {ln: i for i, ln in enumerate(p.line.tolist())}
        rows = np.array([pos[ln] for ln in order])
        for k in JUDGED:
            col = p.y[k][rows]
            if not POOL_TARGETS[k]:  # <F>: relative to its median, as the log targets
                col = col / max(abs(float(np.median(col))), 1e-12)
            cols.append(col)
    cp = find_change(np.column_stack(cols), cal.change_level, cal.min_segment, cal.min_shift,
                     cal.change_table)  # fmt: skip
    return None if cp.index is None else int(order[cp.index])


@dataclass
class GroupResult:
    """What :func:`pool_groups` found.

    Attributes
    ----------
    groups : list of dict
        One row per group (columns :data:`GROUP_COLUMNS`).
    reasons : dict of int to str
        Row index of the result table -> why the line was left out of its map's pool
        (outside the predictive interval, :data:`OUTLIER_REASON`; or showing what the
        other lines of its map do not, :func:`evidence_reason`).
    """

    groups: list[dict[str, Any]] = field(default_factory=list)
    reasons: dict[int, str] = field(default_factory=dict)


def _group_row(name: str, key: tuple, direction: str, segment: str, lines: Sequence[_Lines],
               pools: Mapping[str, TargetPool], flags: Sequence[np.ndarray],
               change: int | None, unit: Any) -> dict[str, Any]:  # fmt: skip
    file, channel, load_group, load = key
    all_lines = np.concatenate([p.line for p in lines]) if lines else np.array([], int)
    used = sum(int((p.usable & ~f).sum()) for p, f in zip(lines, flags, strict=True))
    n_total = sum(p.index.size for p in lines)
    row: dict[str, Any] = {
        "group": name, "file": file or None, "channel": channel or None, "direction": direction,
        "load": load, "load_unit": unit, "load_group": load_group, "segment": segment,
        "lines": f"{int(all_lines.min())}-{int(all_lines.max())}" if all_lines.size else None,
        "n_lines": used, "n_left_out": n_total - used,
    }  # fmt: skip
    for k, log in POOL_TARGETS.items():
        row.update(_target_columns(k, pools[k], log))
    flagged = sorted({int(ln) for p, f in zip(lines, flags, strict=True) for ln in p.line[f]})
    row["change_line"] = change
    row["flagged_lines"] = " ".join(map(str, flagged)) or None
    row["note"] = None
    return row


def _pool_part(lines: _Lines, flags: np.ndarray, direction: str,
               cal: PoolingCalibration) -> dict[str, TargetPool]:  # fmt: skip
    keep = lines.usable & ~flags
    u0 = pool_target(lines.y["U0_eV"][keep], lines.v["U0_eV"][keep], 0.0, True)
    # the floors' offset parts scale with the pooled barrier's largest force
    fmax = force_scale_nN(u0.mu, lines.lattice_nm)
    out = {k: pool_target(lines.y[k][keep], lines.v[k][keep], cal.sys(k, direction), log,
                          cal.sys_abs(k, direction), fmax)
           for k, log in POOL_TARGETS.items() if k != "U0_eV"}  # fmt: skip
    out["U0_eV"] = dataclasses.replace(u0, sys=_floor(u0.mu, cal.sys("U0_eV", direction), True,
                                                      cal.sys_abs("U0_eV", direction), fmax))
    return out


def _pool_both(parts: Mapping[str, dict[str, TargetPool]], lattice_nm: float,
               cal: PoolingCalibration) -> dict[str, TargetPool]:  # fmt: skip
    fmax = force_scale_nN(0.5 * (parts["trace"]["U0_eV"].mu + parts["retrace"]["U0_eV"].mu),
                          lattice_nm)  # fmt: skip
    return {k: _combine(parts["trace"][k], parts["retrace"][k], cal.sys(k, BOTH), log,
                        cal.sys_abs(k, BOTH), fmax)
            for k, log in POOL_TARGETS.items()}  # fmt: skip


def pool_groups(rows: Sequence[Mapping[str, Any]],
                calibration: PoolingCalibration | None = None) -> GroupResult:
    """Pool every map group of a result table's rows; see the module docstring.

    Parameters
    ----------
    rows : sequence of mapping
        Result-table rows (``file, channel, direction, line``, optional ``load``,
        ``load_group``, the estimates and their ``*_lo95/_hi95`` or ``*_std``). Rows
        without a ``line`` (single traces) belong to no group. Rows without an estimate
        or out of domain are counted in ``n_left_out``.
    calibration : PoolingCalibration, optional
        Default: the bundled one (:func:`bundled_calibration`).

    Returns
    -------
    GroupResult
        Per map, in this order: each direction, then ``both`` where the map has both;
        where a change point was found, each of those is followed by its ``before`` and
        ``after`` segments.
    """
    cal = calibration or bundled_calibration()
    out = GroupResult()
    for key, idx in map_keys(rows).items():
        file, channel, load_group, load = key
        unit = next((_blank(rows[i].get("load_unit")) for i in idx), None)
        by_dir = _map_lines(rows, idx)
        stem = ":".join(str(s) for s in (file.rsplit("/", 1)[-1] or "map", channel) if s)
        if load_group is not None:
            stem += f":G{load_group}"
        kinds: list[tuple[str, list[str]]] = [(d, [d]) for d in by_dir]
        if len(by_dir) == 2:
            kinds.append((BOTH, list(DIRECTIONS)))
        for direction, dirs in kinds:
            parts = [by_dir[d] for d in dirs]
            change = _change(parts, cal)
            segments: list[tuple[str, list[np.ndarray]]] = [
                ("all", [np.ones(p.index.size, bool) for p in parts])]
            if change is not None:
                segments += [("before", [p.line < change for p in parts]),
                             ("after", [p.line >= change for p in parts])]  # fmt: skip
            for segment, sels in segments:
                sub = [p.take(s) for p, s in zip(parts, sels, strict=True)]
                whys = [_judge(p, cal) if segment != "all" or change is None
                        else _judge_segmented(p, change, cal) for p in sub]  # fmt: skip
                flags = [w != "" for w in whys]
                pools_by = {d: _pool_part(p, f, d, cal)
                            for d, p, f in zip(dirs, sub, flags, strict=True)}  # fmt: skip
                pools = (pools_by[dirs[0]] if len(dirs) == 1
                         else _pool_both(pools_by, sub[0].lattice_nm, cal))  # fmt: skip
                name = f"{stem}:{direction}" + ("" if segment == "all" else f":{segment}")
                row = _group_row(name, key, direction, segment, sub, pools, flags, change, unit)
                if segment == "all" and change is not None:
                    row["note"] = (f"change point at line {change}: the lines before and after "
                                   "differ; see the before/after rows")  # fmt: skip
                out.groups.append(row)
                if segment == "all" and direction != BOTH:
                    for p, w in zip(sub, whys, strict=True):
                        for i, why in zip(p.index, w, strict=True):
                            if why:
                                out.reasons[int(i)] = str(why)
    return out


def _judge_segmented(lines: _Lines, change: int, cal: PoolingCalibration) -> np.ndarray:
    """Flags (:func:`_judge`) judged within each side of a change point."""
    why = np.full(lines.index.size, "", object)
    for sel in (lines.line < change, lines.line >= change):
        why[sel] = _judge(lines.take(sel), cal)
    return why


def _local_scores(lines: _Lines) -> np.ndarray:
    """The local anomaly's robust score of each line of one direction (NaN where none)."""
    if not lines.usable.any():
        return np.full(lines.index.size, np.nan)
    j = JUDGED_EVIDENCE.index(LOCAL)
    return evidence_scores(lines.e[:, j:j + 1], lines.usable)[:, 0]


def _pair(a: _Lines, b: _Lines) -> None:
    """Set ``paired`` of both directions' lines: the paired local score of every line
    seen in both (each direction scored against its own usable lines, over the whole map
    direction)."""
    za, zb = _local_scores(a), _local_scores(b)
    pos_b = {int(ln): i for i, ln in enumerate(b.line.tolist())}
    a.paired, b.paired = np.full(a.index.size, np.nan), np.full(b.index.size, np.nan)
    for i, ln in enumerate(a.line.tolist()):
        k = pos_b.get(int(ln))
        if k is not None:
            a.paired[i] = b.paired[k] = paired_scores(za[i], zb[k])


def _map_lines(rows: Sequence[Mapping[str, Any]], idx: Sequence[int]) -> dict[str, _Lines]:
    """The lines of one map (rows ``idx``) per scan direction that has any, in
    :data:`DIRECTIONS` order; where it has both, each line's paired local score set
    (:func:`_pair`)."""
    by_dir = {d: _lines(rows, [i for i in idx if rows[i].get("direction") == d])
              for d in DIRECTIONS}  # fmt: skip
    by_dir = {d: p for d, p in by_dir.items() if p.index.size}
    if len(by_dir) == 2:
        _pair(by_dir["trace"], by_dir["retrace"])
    return by_dir


def paired_scores_by_row(rows: Sequence[Mapping[str, Any]]) -> dict[int, float]:
    """Each map line's paired local score (:func:`paired_scores`), as :func:`pool_groups`
    judges it: row index -> score (both rows of a line the same; lines seen in one
    direction and rows without local evidence left out, or NaN).

    What :data:`LOCAL_BOTH` of :attr:`PoolingCalibration.evidence_z` is chosen on
    (``benchmarks/map_pooling.py``).
    """
    out: dict[int, float] = {}
    for idx in map_keys(rows).values():
        by_dir = _map_lines(rows, idx)
        if len(by_dir) < 2:
            continue
        for p in by_dir.values():
            for i, z in zip(p.index, p.paired, strict=True):
                out[int(i)] = float(z)
    return out


def evidence_scores_by_row(rows: Sequence[Mapping[str, Any]]) -> dict[int, np.ndarray]:
    """Each map line's evidence scores (:func:`evidence_scores`, columns
    :data:`JUDGED_EVIDENCE`) against the usable lines of its map and direction (no
    change point split), as :func:`pool_groups` judges them: row index -> (p,).

    What :attr:`PoolingCalibration.evidence_z` is chosen on (``benchmarks/map_pooling.py``
    takes a high quantile over the lines of homogeneous maps). Rows without evidence get
    NaN scores; so do all the rows of a map direction without usable lines.
    """
    out: dict[int, np.ndarray] = {}
    for idx in map_keys(rows).values():
        for lines in _map_lines(rows, idx).values():
            if not lines.usable.any():
                continue
            S = evidence_scores(lines.e, lines.usable)
            for i, s in zip(lines.index, S, strict=True):
                out[int(i)] = s
    return out


def group_table(rows: Iterable[Mapping[str, Any]],
                calibration: PoolingCalibration | None = None) -> list[dict[str, Any]]:
    """The groups table (one dict per group, every column of :data:`GROUP_COLUMNS`)."""
    res = pool_groups(list(rows), calibration)
    return [{c: g.get(c) for c in GROUP_COLUMNS} for g in res.groups]


def groups_summary(groups: Sequence[Mapping[str, Any]], limit: int = 12) -> str:
    """A short terminal summary: one line per group (whole groups first), value and 95 %
    interval of <F>, U0, K, the relative spread tau and the change line."""
    if not groups:
        return ""
    head = (f"{'group':<34}{'lines':>6}{'out':>5}{'<F> nN [95 %]':>23}{'U0 eV [95 %]':>23}"
            f"{'K N/m [95 %]':>23}{'tau U0':>8}{'change':>8}")  # fmt: skip
    lines = ["per-map pooled answer:", head]

    def cell(g: Mapping[str, Any], k: str) -> str:
        v, lo, hi = (_num(g.get(c)) for c in (k, f"{k}_lo95", f"{k}_hi95"))
        return f"{v:.3g} [{lo:.3g}, {hi:.3g}]" if math.isfinite(v) else "-"

    shown = [g for g in groups if g.get("segment") == "all"] + \
        [g for g in groups if g.get("segment") != "all"]  # fmt: skip
    for g in shown[:limit]:
        tau = _num(g.get("U0_eV_tau"))
        ch = g.get("change_line")
        lines.append(f"{str(g['group'])[-33:]:<34}{g['n_lines']:>6}{g['n_left_out']:>5}"
                     f"{cell(g, 'F_mean_nN'):>23}{cell(g, 'U0_eV'):>23}{cell(g, 'K_N_m'):>23}"
                     f"{tau:>8.3f}{'-' if ch is None else ch:>8}")  # fmt: skip
    if len(shown) > limit:
        lines.append(f"... {len(shown) - limit} more groups in the groups table")
    return "\n".join(lines)
