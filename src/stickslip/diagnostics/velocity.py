"""Friction against scan velocity: the thermally activated Prandtl-Tomlinson law.

The law (Sang, Dube and Grant, PRL 87, 174301, 2001; Riedo et al., PRL 91, 084502, 2003)::

    F(v) = F_c - (beta k_B T ln(v_c / v))^(2/3)    for v < v_c,      F(v) = F_c above v_c

- ``F_c`` (nN): the athermal friction, the force at which the barrier vanishes. In the PT
  model it is the peak of the stick branch, ``F_max = pi U0 / a``.
- ``beta`` (nN^(1/2)/nm): the barrier shape near the instability, ``dE = (F_c - F)^(3/2) /
  beta``. For the sinusoid in the large-eta (tilted washboard) limit
  ``beta = 3 pi sqrt(F_c) / (2 sqrt(2) a)``; at finite eta the barrier at a given distance
  from ``F_c`` is higher and the fitted ``beta`` smaller (16.1 instead of 19.4 at eta = 17,
  measured below; compare Dong et al., J. Phys.: Condens. Matter 24, 265001, 2012).
  The fit's parameter is ``B = (beta k_B T)^(2/3)`` (nN), the force scale of the thermal
  drop; ``beta`` follows from it at the given T.
- ``v_c`` (nm/s): the critical velocity above which thermal activation no longer acts.
  With the loading rate ``k v`` (``k`` the measured stick slope), Riedo's relation gives
  the attempt rate ``f0 = 3 k v_c sqrt(F_c - F) / (2 beta k_B T)``, here with ``F`` the
  series' mean peak force: an order of magnitude (it comes from the most probable slip
  force, and the PT attempt rate itself changes along the stick).

What is fitted: the mean peak (slip) force of each line, ``F_peak`` of the classical
estimator, averaged per velocity (the law describes the slip force). The mean friction
``<F>`` is fitted with the same law as a secondary result under one approximation: a
velocity-independent slip drop and a straight stick, so that ``<F> = F_peak - drop/2``
shifts the curve but keeps its shape; its ``F_c`` is then ``pi U0/a - drop/2``, not
``F_max``.

Fitting: for a fixed ``v_c`` the law is linear in ``(F_c, B)``, so ``ln v_c`` is profiled
on a grid (refined by a bounded minimisation) and ``(F_c, B)`` solved by weighted least
squares at each point: the global optimum, whatever the start. ``v_c`` is searched from
the fastest velocity upwards: the law's plateau above ``v_c`` is not fitted (in the PT
simulator inertia, not a plateau, follows the thermal regime; and a kink inside the data
lets one low point at the top pose as the plateau, with a falsely tight ``F_c``).
Uncertainties are one standard deviation from the covariance ``s^2 (J^T W J)^-1`` with
``W = 1/sem^2`` per velocity and ``s^2 = max(1, chi2/dof)``; ``F_c`` and ``v_c`` also get
profile intervals (``chi2 - chi2_min <= s^2``), honest where the covariance is not: with a
velocity range far below ``v_c`` the data bound neither from above, and the intervals say
so (``inf``). On synthetic series from the law (13 velocities, 10 to 10^4 nm/s) the 68 %
intervals cover 70-80 % (``v_c`` three times above the data); with ``v_c`` just above the
fastest velocity the ``v_c`` interval covers 57 % (the search boundary).

How many decades a laboratory needs, measured on the simulated series of the tests
(PT paper preset, U0 = 1 eV, K = 3 N/m, eta = 17, 296 K, 32 lines of 2 nm per velocity,
a quarter decade apart; ``tests/diagnostics/test_velocity.py``): fitted from 10 nm/s up,
one decade (10-100 nm/s) and two decades (10-1000 nm/s) leave ``v_c``, ``F_c`` and the
attempt rate unbounded above; three decades (10-10^4 nm/s), which reach the knee where
the peak force comes within 4 % of ``F_max``, give ``v_c = 1.7e4`` nm/s (68 %: 1.35e4 to
2.7e4), ``f0 = 6.9e5`` 1/s (4.7e5 to 1.1e6) and ``F_c = 2.074`` nN (2.040 to 2.129; the
true ``F_max`` is 2.046). What pins the attempt rate is reaching the knee, not the count
of decades: here ``v_c`` is about 10^4 nm/s, three decades above typical lab speeds.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from stickslip.units import EV_TO_NN_NM, KB_NN_NM_PER_K

MIN_VELOCITIES = 4  # three parameters and one degree of freedom
LN_VC_SPAN = 30.0  # search ln v_c up to this far above the fastest velocity (13 decades)
N_GRID = 601


def thermal_law(velocity_nm_per_s: np.ndarray | float, F_c_nN: float, B_nN: float,
                v_c_nm_per_s: float) -> np.ndarray:  # fmt: skip
    """``F_c - B ln(v_c/v)^(2/3)`` below ``v_c``, ``F_c`` above it (nN)."""
    v = np.asarray(velocity_nm_per_s, dtype=float)
    arg = np.maximum(np.log(v_c_nm_per_s) - np.log(v), 0.0)
    return F_c_nN - B_nN * np.cbrt(arg) ** 2


def washboard_beta(F_c_nN: float, lattice_nm: float) -> float:
    """Large-eta barrier shape ``beta = 3 pi sqrt(F_c) / (2 sqrt(2) a)`` in nN^(1/2)/nm."""
    return 3.0 * math.pi * math.sqrt(max(F_c_nN, 0.0)) / (2.0 * math.sqrt(2.0) * lattice_nm)


@dataclass
class VelocityFit:
    """The thermally activated PT law fitted to a force against velocity.

    Attributes
    ----------
    quantity : str
        What was fitted (``F_peak_nN`` or ``F_mean_nN``).
    F_c_nN, F_c_std : float
        Athermal force and its standard deviation.
    B_nN, B_std : float
        ``(beta k_B T)^(2/3)``, the force scale of the thermal drop.
    ln_v_c, ln_v_c_std : float
        Natural log of the critical velocity (nm/s) and its standard deviation.
    v_c_lo, v_c_hi : float
        Profile 68 % interval of ``v_c`` (nm/s); ``inf`` where the data do not bound it.
    F_c_lo, F_c_hi : float
        Profile 68 % interval of ``F_c`` (nN), over every ``v_c`` the data allow; ``inf``
        above where they do not bound ``v_c``. Wider than ``F_c +- F_c_std`` where the
        covariance is too optimistic (a series that ends at the knee of the law).
    cov : ndarray (3, 3)
        Covariance of ``(F_c, B, ln v_c)``.
    chi2_red : float
        chi^2 per degree of freedom with the per-velocity errors (NaN without errors).
    rms_nN : float
        Root-mean-square residual.
    dof : int
        Velocities minus three.
    temperature_K : float
        Temperature used to turn ``B`` into ``beta``.
    notes : list of str
        What the user should know (a parameter at a limit).
    """

    quantity: str
    F_c_nN: float
    F_c_std: float
    B_nN: float
    B_std: float
    ln_v_c: float
    ln_v_c_std: float
    v_c_lo: float
    v_c_hi: float
    F_c_lo: float
    F_c_hi: float
    cov: np.ndarray
    chi2_red: float
    rms_nN: float
    dof: int
    temperature_K: float
    notes: list[str] = field(default_factory=list)

    @property
    def v_c_nm_per_s(self) -> float:
        """Critical velocity in nm/s."""
        return math.exp(self.ln_v_c)

    @property
    def beta(self) -> float:
        """Barrier shape ``beta = B^(3/2) / (k_B T)`` in nN^(1/2)/nm."""
        return self.B_nN**1.5 / (KB_NN_NM_PER_K * self.temperature_K)

    @property
    def beta_std(self) -> float:
        return 1.5 * self.beta * self.B_std / self.B_nN if self.B_nN > 0 else math.nan

    def predict(self, velocity_nm_per_s: np.ndarray | float) -> np.ndarray:
        """The fitted law at the given velocities (nN)."""
        return thermal_law(velocity_nm_per_s, self.F_c_nN, self.B_nN, self.v_c_nm_per_s)

    def U0_eV(self, lattice_nm: float) -> tuple[float, float]:
        """Barrier ``a F_c / pi`` (eV) and its standard deviation, from ``F_c`` as F_max."""
        k = lattice_nm / math.pi / EV_TO_NN_NM
        return k * self.F_c_nN, k * self.F_c_std

    def attempt_rate(self, k_N_m: float, F_nN: float, n_draws: int = 4000,
                     seed: int = 0) -> tuple[float, float, float]:  # fmt: skip
        """Attempt rate ``f0 = 3 k v_c sqrt(F_c - F) / (2 beta k_B T)`` in 1/s.

        Parameters
        ----------
        k_N_m : float
            Loading stiffness (the measured stick slope ``k_exp``).
        F_nN : float
            Force at which the square root is taken (the series' mean peak force).
        n_draws, seed : int
            Draws from the parameter covariance for the interval.

        Returns
        -------
        (f0, lo, hi) : float
            Best value and a 68 % interval: the 16th to 84th percentiles over draws from
            the parameter covariance, widened to ``f0`` scaled by the profile interval of
            ``v_c`` (``inf`` where the data do not bound ``v_c``). NaN where ``F_c <= F``.
        """
        kT = KB_NN_NM_PER_K * self.temperature_K

        def f0(Fc: np.ndarray, B: np.ndarray, lnvc: np.ndarray) -> np.ndarray:
            beta = np.maximum(B, 1e-300) ** 1.5 / kT
            gap = np.where(Fc > F_nN, Fc - F_nN, np.nan)
            with np.errstate(over="ignore", invalid="ignore"):
                return 3.0 * k_N_m * np.exp(lnvc) * np.sqrt(gap) / (2.0 * beta * kT)

        best = float(f0(np.array(self.F_c_nN), np.array(self.B_nN), np.array(self.ln_v_c)))
        lo, hi = best * self.v_c_lo / self.v_c_nm_per_s, best * self.v_c_hi / self.v_c_nm_per_s
        if not (math.isfinite(best) and np.all(np.isfinite(self.cov))):
            return best, math.nan, math.nan
        rng = np.random.default_rng(seed)
        mean = [self.F_c_nN, self.B_nN, self.ln_v_c]
        d = rng.multivariate_normal(mean, self.cov, size=n_draws, method="eigh")
        vals = f0(d[:, 0], d[:, 1], d[:, 2])
        vals = vals[np.isfinite(vals) & (d[:, 1] > 0)]
        if vals.size < n_draws // 2:
            return best, lo, hi
        p16, p84 = np.percentile(vals, [16, 84])
        return best, float(min(p16, lo)), float(max(p84, hi))

    def summary(self) -> str:
        """One line: parameters with uncertainties and the goodness of fit."""
        hi = "inf" if math.isinf(self.v_c_hi) else f"{self.v_c_hi:.3g}"
        fhi = "inf" if math.isinf(self.F_c_hi) else f"{self.F_c_hi:.4g}"
        gof = f"rms {self.rms_nN:.3g} nN"
        if math.isfinite(self.chi2_red):
            gof = f"chi2/dof {self.chi2_red:.3g} (dof {self.dof}), " + gof
        line = (f"{self.quantity}: F_c = {self.F_c_nN:.4g} +- {self.F_c_std:.2g} nN "
                f"(68 %: {self.F_c_lo:.4g} to {fhi}), "
                f"beta = {self.beta:.4g} +- {self.beta_std:.2g} nN^0.5/nm "
                f"(B = {self.B_nN:.3g} +- {self.B_std:.2g} nN), v_c = {self.v_c_nm_per_s:.3g} "
                f"nm/s (68 %: {self.v_c_lo:.3g} to {hi}); {gof}")  # fmt: skip
        return line + "".join(f"; {n}" for n in self.notes)


def _profile(lnv: np.ndarray, F: np.ndarray, w: np.ndarray,
             ln_vc: np.ndarray) -> tuple[np.ndarray, ...]:  # fmt: skip
    """Weighted least squares of (F_c, B) at each fixed ``ln v_c``: F_c, B, chi2, var(F_c).

    The law is linear in ``(F_c, B)`` for a given ``v_c``: a 2 x 2 normal system per grid
    point, solved in closed form. ``var(F_c)`` is the unscaled ``[(X^T W X)^-1]_00``: at
    that ``v_c`` chi2 grows by ``(F_c - best)^2 / var`` away from the best ``F_c``.
    Degenerate points (every velocity above ``v_c``) get chi2 = inf.
    """
    t = np.atleast_1d(np.asarray(ln_vc, dtype=float))[:, None]
    g = np.cbrt(np.maximum(t - lnv[None, :], 0.0)) ** 2
    s0, s1, s2 = w.sum(), (w * g).sum(axis=1), (w * g * g).sum(axis=1)
    b0, b1 = (w * F).sum(), (w * g * F).sum(axis=1)
    det = s0 * s2 - s1 * s1
    ok = det > 1e-12 * s0 * np.maximum(s2, 1e-300)
    det = np.where(ok, det, 1.0)
    Fc = (s2 * b0 - s1 * b1) / det
    B = (s1 * b0 - s0 * b1) / det
    chi2 = (w * (F[None, :] - Fc[:, None] + B[:, None] * g) ** 2).sum(axis=1)
    return Fc, B, np.where(ok, chi2, np.inf), np.where(ok, s2 / det, np.nan)


def fit_thermal_law(
    velocity_nm_per_s: Sequence[float],
    force_nN: Sequence[float],
    sem_nN: Sequence[float] | None = None,
    temperature_K: float = 296.0,
    quantity: str = "F_peak_nN",
) -> VelocityFit:
    """Fit ``F(v) = F_c - (beta k_B T ln(v_c/v))^(2/3)`` (see the module docstring).

    Parameters
    ----------
    velocity_nm_per_s, force_nN : array_like (n,)
        One point per velocity (a mean over lines); NaN entries are left out.
    sem_nN : array_like (n,), optional
        Standard error of each mean; without it all points weigh the same and the
        uncertainties come from the residual scatter.
    temperature_K : float
        Temperature of the series (turns ``B`` into ``beta``).
    quantity : str
        Name of what is fitted, carried into the result.

    Returns
    -------
    VelocityFit

    Raises
    ------
    ValueError
        With fewer than four distinct velocities, or non-positive velocities.
    """
    from scipy.optimize import minimize_scalar

    v = np.asarray(velocity_nm_per_s, dtype=float)
    F = np.asarray(force_nN, dtype=float)
    if v.shape != F.shape or v.ndim != 1:
        raise ValueError("velocity and force must be 1-D arrays of equal length")
    keep = np.isfinite(v) & np.isfinite(F)
    weighted = sem_nN is not None
    s = np.ones_like(F) if sem_nN is None else np.asarray(sem_nN, dtype=float)
    if weighted:
        keep &= np.isfinite(s) & (s > 0)
    v, F, s = v[keep], F[keep], s[keep]
    if np.any(v <= 0):
        raise ValueError("velocities must be > 0 nm/s")
    if np.unique(v).size < MIN_VELOCITIES:
        raise ValueError(f"need at least {MIN_VELOCITIES} distinct velocities "
                         f"({np.unique(v).size} given)")  # fmt: skip
    w = 1.0 / s**2
    lnv = np.log(v)
    lo, hi = float(lnv.max()), float(lnv.max()) + LN_VC_SPAN
    grid = np.linspace(lo, hi, N_GRID)
    Fc_grid, _, chi, var_grid = _profile(lnv, F, w, grid)
    k = int(np.argmin(chi))
    a, b = grid[max(k - 1, 0)], grid[min(k + 1, N_GRID - 1)]
    best = float(minimize_scalar(lambda t: float(_profile(lnv, F, w, t)[2][0]), bounds=(a, b),
                                 method="bounded", options={"xatol": 1e-9}).x)  # fmt: skip
    Fc, B, chi2 = (float(x[0]) for x in _profile(lnv, F, w, best)[:3])
    notes = []
    if B < 0:
        notes.append("the force falls with velocity: not thermally activated stick-slip")
    n = v.size
    dof = n - 3
    scale = max(1.0, chi2 / dof) if weighted else chi2 / dof
    arg = np.maximum(best - lnv, 0.0)
    dlnvc = np.where(arg > 0, -B * (2.0 / 3.0) / np.cbrt(np.where(arg > 0, arg, 1.0)), 0.0)
    J = np.column_stack([np.ones_like(lnv), -np.cbrt(arg) ** 2, dlnvc])
    try:
        cov = np.linalg.inv(J.T @ (w[:, None] * J)) * scale
    except np.linalg.LinAlgError:
        cov = np.full((3, 3), np.nan)
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    # profile intervals: chi2 within s^2 of its minimum, minimised over the other parameters
    at_edge = hi - 2 * (grid[1] - grid[0])
    inside = chi <= chi2 + scale
    vc_lo = math.exp(min(float(grid[inside].min()), best)) if inside.any() else math.nan
    vc_hi = math.exp(max(float(grid[inside].max()), best)) if inside.any() else math.nan
    Fc_lo = Fc_hi = float(Fc)
    allowed = inside & np.isfinite(var_grid)  # the F_c range allowed at each such v_c
    if allowed.any():
        half = np.sqrt(np.maximum(chi2 + scale - chi[allowed], 0.0) * var_grid[allowed])
        Fc_lo = min(Fc_lo, float(np.min(Fc_grid[allowed] - half)))
        Fc_hi = max(Fc_hi, float(np.max(Fc_grid[allowed] + half)))
    if inside.any() and grid[inside].max() >= at_edge:
        vc_hi = Fc_hi = math.inf
        notes.insert(0, "the data do not bound v_c (nor F_c) from above: a wider velocity range, "
                     "up to where the force levels off, is needed")
    resid = F - thermal_law(v, Fc, B, math.exp(best))
    return VelocityFit(
        quantity=quantity, F_c_nN=float(Fc), F_c_std=float(std[0]), B_nN=float(B),
        B_std=float(std[1]), ln_v_c=best, ln_v_c_std=float(std[2]), v_c_lo=vc_lo,
        v_c_hi=vc_hi, F_c_lo=Fc_lo, F_c_hi=Fc_hi, cov=cov,
        chi2_red=chi2 / dof if weighted else math.nan,
        rms_nN=float(np.sqrt(np.mean(resid**2))), dof=dof, temperature_K=temperature_K,
        notes=notes,
    )  # fmt: skip


@dataclass
class VelocityGroups:
    """Per-velocity means of per-line values.

    Attributes
    ----------
    velocity_nm_per_s : ndarray (g,)
        Distinct velocities, increasing.
    n_lines : ndarray of int (g,)
        Lines with a value at each velocity.
    mean, sem : ndarray (g,)
        Mean over lines and its standard error (line-to-line scatter over sqrt(n); for
        a single line the per-line error given, else NaN).
    """

    velocity_nm_per_s: np.ndarray
    n_lines: np.ndarray
    mean: np.ndarray
    sem: np.ndarray


def group_by_velocity(velocity_nm_per_s: Sequence[float], values: Sequence[float],
                      line_sem: Sequence[float] | None = None,
                      rel_tol: float = 1e-3) -> VelocityGroups:  # fmt: skip
    """Mean and standard error of per-line values at each velocity.

    Velocities within ``rel_tol`` of each other are one group. NaN values are left out.
    """
    v = np.asarray(velocity_nm_per_s, dtype=float)
    x = np.asarray(values, dtype=float)
    e = np.full_like(x, np.nan) if line_sem is None else np.asarray(line_sem, dtype=float)
    ok = np.isfinite(v) & np.isfinite(x) & (v > 0)
    v, x, e = v[ok], x[ok], e[ok]
    order = np.argsort(v)
    v, x, e = v[order], x[order], e[order]
    starts = [0] + [i for i in range(1, v.size) if v[i] > v[i - 1] * (1 + rel_tol)]
    bounds = list(zip(starts, [*starts[1:], v.size], strict=True))
    vel, n, mean, sem = [], [], [], []
    for i, j in bounds:
        vel.append(float(np.mean(v[i:j])))
        n.append(j - i)
        mean.append(float(np.mean(x[i:j])))
        if j - i > 1:
            sem.append(float(np.std(x[i:j], ddof=1) / math.sqrt(j - i)))
        else:
            sem.append(float(e[i]))
    return VelocityGroups(np.array(vel), np.array(n, dtype=int), np.array(mean),
                          np.array(sem))  # fmt: skip


# ---------------------------------------------------------------- the simulator check


def simulated_series(
    U0_eV: float,
    K_N_m: float,
    velocities_nm_per_s: Sequence[float],
    *,
    lattice_nm: float = 0.246,
    temperature_K: float = 296.0,
    lines: int = 32,
    length_nm: float = 2.0,
    pixels: int = 96,
    seed: int = 0,
    damping_per_s: float | None = None,
) -> dict[str, np.ndarray]:
    """Simulate ``lines`` lines at each velocity and label them with the classical estimator.

    A short recorded line (default 2 nm as 96 pixels, the paper's pixel size) keeps slow
    velocities affordable: a line costs ``(warm-up + length) / (v dt)`` steps, 1.1e8 at
    3 nm/s. Lines run 32 to a block, so up to 32 lines per velocity cost the same.
    ``damping_per_s``: the contact's damping rate (None: the paper preset's); the labels
    assume the preset's, as a user who does not know it would.

    Returns
    -------
    dict
        ``velocity_nm_per_s``, ``F_peak_nN``, ``F_peak_nN_std``, ``n_slips``,
        ``F_mean_nN``, ``U0_eV``, ``K_N_m``, ``k_exp_N_m``: one entry per line.
    """
    from stickslip.estimators.classical.estimator import (
        F_MEAN,
        F_PEAK,
        F_PEAK_STD,
        K_,
        K_EXP,
        N_SLIPS,
        U0,
        estimate_array,
    )
    from stickslip.simulators.config import PhysicalSettings
    from stickslip.simulators.simulate import simulate

    vs = np.repeat(np.asarray(velocities_nm_per_s, dtype=float), lines)
    dynamics = {} if damping_per_s is None else {"damping_per_s": float(damping_per_s)}
    settings = PhysicalSettings(length_nm=length_nm, pixels=pixels, lattice_nm=lattice_nm,
                                temperature_K=temperature_K, **dynamics)  # fmt: skip
    res = simulate(np.full(vs.size, U0_eV), np.full(vs.size, K_N_m), settings, seed=seed,
                   velocity_nm_per_s=vs)  # fmt: skip
    est = estimate_array(res.x_nm, res.force_nN, lattice_nm, temperature_K, vs)
    cols = {"F_peak_nN": F_PEAK, "F_peak_nN_std": F_PEAK_STD, "n_slips": N_SLIPS,
            "F_mean_nN": F_MEAN, "U0_eV": U0, "K_N_m": K_, "k_exp_N_m": K_EXP}  # fmt: skip
    out = {k: est[:, i].copy() for k, i in cols.items()}
    out["velocity_nm_per_s"] = vs
    out["force_nN"] = res.force_nN
    out["x_nm"] = res.x_nm
    return out


def line_sem(F_peak_std: np.ndarray, n_slips: np.ndarray) -> np.ndarray:
    """Per-line standard error of the mean peak: spread over slips / sqrt(slips)."""
    return np.asarray(F_peak_std, float) / np.sqrt(np.maximum(np.asarray(n_slips, float), 1.0))


def check_rows(groups: VelocityGroups, sim: VelocityGroups) -> tuple[np.ndarray, float]:
    """z-scores of the measured means against the simulated ones, and their RMS.

    ``z = (measured - simulated) / sqrt(sem_measured^2 + sem_simulated^2)`` at each
    velocity of ``groups`` (matched to ``sim`` by nearest velocity).
    """
    idx = np.array([int(np.argmin(np.abs(np.log(sim.velocity_nm_per_s / v))))
                    for v in groups.velocity_nm_per_s])  # fmt: skip
    den = np.sqrt(np.nan_to_num(groups.sem) ** 2 + np.nan_to_num(sim.sem[idx]) ** 2)
    z = np.where(den > 0, (groups.mean - sim.mean[idx]) / np.where(den > 0, den, 1.0), np.nan)
    zf = z[np.isfinite(z)]
    return z, float(np.sqrt(np.mean(zf**2))) if zf.size else math.nan


def fit_rows(fit: VelocityFit, lattice_nm: float, extra: dict[str, Any] | None = None
             ) -> list[dict[str, Any]]:  # fmt: skip
    """Table rows of a fit: one per parameter (quantity, parameter, value, std, unit ...)."""
    common = {"chi2_red": fit.chi2_red, "rms_nN": fit.rms_nN,
              "dof": fit.dof, "note": "; ".join(fit.notes) or None, **(extra or {})}  # fmt: skip
    U0, U0s = fit.U0_eV(lattice_nm)
    q = {"quantity": fit.quantity}
    return [q | r for r in [
        {"parameter": "F_c", "value": fit.F_c_nN, "std": fit.F_c_std, "lo68": fit.F_c_lo,
         "hi68": fit.F_c_hi, "unit": "nN", **common},
        {"parameter": "beta", "value": fit.beta, "std": fit.beta_std, "unit": "nN^0.5/nm",
         **common},
        {"parameter": "B", "value": fit.B_nN, "std": fit.B_std, "unit": "nN", **common},
        {"parameter": "v_c", "value": fit.v_c_nm_per_s, "std": None, "lo68": fit.v_c_lo,
         "hi68": fit.v_c_hi, "unit": "nm/s", **common},
        {"parameter": "ln_v_c", "value": fit.ln_v_c, "std": fit.ln_v_c_std, "unit": "ln(nm/s)",
         **common},
        {"parameter": "U0 = a F_c/pi", "value": U0, "std": U0s, "unit": "eV", **common},
    ]]  # fmt: skip
