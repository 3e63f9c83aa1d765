"""Posterior predictive check: does the PT model at the estimate reproduce the trace?

Each trace is re-simulated several times at its estimated (U0, K), with its lattice,
velocity and temperature, and with white noise of the level measured on the trace. A
set of summary statistics of the observed trace (mean friction, force spread, upper
force percentiles, median positive slope, slip rate and mean slip drop) is compared
with their spread over the replicates. The goodness-of-fit number is the RMS z-score
over the statistics; a trace scoring above ``threshold`` is flagged as one the PT
model cannot describe (defects, domain crossings, a lost contact), as a person looking
at the overlay would.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from stickslip.estimators.noise import noise_nN
from stickslip.simulators.config import PhysicalSettings
from stickslip.simulators.simulate import simulate

STATISTICS = ("F_mean", "F_std", "F_p90", "F_p99", "slope_med", "slips_per_nm", "drop_mean")


def trace_statistics(x_nm: np.ndarray, force_nN: np.ndarray) -> np.ndarray:
    """Summary statistics (N, len(STATISTICS)) of traces sharing positions ``x_nm``."""
    F = np.atleast_2d(force_nN)
    dx = float(np.mean(np.diff(x_nm)))
    length = dx * (F.shape[1] - 1)
    dF = np.diff(F, axis=1)
    span = np.percentile(F, 99, axis=1) - np.percentile(F, 1, axis=1)
    slip = dF < -0.3 * span[:, None]
    n_slip = slip.sum(axis=1)
    drop = np.where(slip, -dF, 0.0).sum(axis=1) / np.maximum(n_slip, 1)
    slope = np.where(dF > 0, dF / dx, np.nan)
    return np.column_stack(
        [
            F.mean(axis=1),
            F.std(axis=1),
            np.percentile(F, 90, axis=1),
            np.percentile(F, 99, axis=1),
            np.nanmedian(slope, axis=1),
            n_slip / length,
            drop,
        ]
    )


@dataclass
class PPCResult:
    """Posterior predictive check of N traces.

    Attributes
    ----------
    gof : ndarray (N,)
        RMS z-score of the observed statistics against the replicates (about 1 for a
        trace the model describes; large when it does not).
    flagged : ndarray of bool (N,)
        ``gof > threshold``.
    z : ndarray (N, n_statistics)
        Per-statistic z-scores (names in :data:`STATISTICS`).
    replicate_nN : ndarray (N, P)
        One re-simulated trace per input, for overlay plots.
    """

    gof: np.ndarray
    flagged: np.ndarray
    z: np.ndarray
    replicate_nN: np.ndarray


def posterior_predictive_check(
    x_nm: np.ndarray,
    force_nN: np.ndarray,
    U0_eV: np.ndarray,
    K_N_m: np.ndarray,
    *,
    lattice_nm: float | np.ndarray = 0.246,
    velocity_nm_per_s: float | np.ndarray = 60.0,
    temperature_K: float | np.ndarray = 296.0,
    n_replicates: int = 8,
    threshold: float = 3.0,
    seed: int = 0,
) -> PPCResult:
    """Re-simulate traces at their estimates and score how well they are reproduced.

    Parameters
    ----------
    x_nm : ndarray (P,)
        Positions shared by the traces (uniform spacing).
    force_nN : ndarray (N, P)
        Observed traces.
    U0_eV, K_N_m : ndarray (N,)
        Estimates to check.
    lattice_nm, velocity_nm_per_s, temperature_K : float or ndarray (N,)
        Conditions of each trace.
    n_replicates : int
        Simulations per trace.
    threshold : float
        Flag traces whose goodness-of-fit number exceeds this.
    seed : int
        Seed of the replicates.
    """
    F = np.atleast_2d(np.asarray(force_nN, float))
    n, p = F.shape
    U0 = np.clip(np.asarray(U0_eV, float), 1e-3, None)
    K = np.clip(np.asarray(K_N_m, float), 1e-2, None)
    x = np.asarray(x_nm, float)
    settings = PhysicalSettings(length_nm=float(x[-1] - x[0]) * p / (p - 1), pixels=p)
    rep_n = n * n_replicates
    res = simulate(
        np.repeat(U0, n_replicates), np.repeat(K, n_replicates), settings, seed=seed,
        lattice_nm=np.repeat(np.broadcast_to(lattice_nm, (n,)), n_replicates),
        velocity_nm_per_s=np.repeat(np.broadcast_to(velocity_nm_per_s, (n,)), n_replicates),
        temperature_K=np.repeat(np.broadcast_to(temperature_K, (n,)), n_replicates),
    )  # fmt: skip
    rng = np.random.default_rng([seed, 1])
    # the replicates already carry thermal noise: add only the detector noise the
    # observed trace has beyond it
    intrinsic = noise_nN(res.force_nN).reshape(n, n_replicates).mean(axis=1)
    extra = np.sqrt(np.clip(noise_nN(F) ** 2 - intrinsic**2, 0.0, None))
    reps = res.force_nN + rng.standard_normal((rep_n, p)) * np.repeat(extra, n_replicates)[:, None]
    s_obs = trace_statistics(x, F)
    s_rep = trace_statistics(x, reps).reshape(n, n_replicates, -1)
    mu = s_rep.mean(axis=1)
    # spread over replicates, floored so that a statistic that barely varies in the
    # model (e.g. the slip rate) does not turn a small mismatch into a huge z
    floor = 0.03 * np.abs(mu) + 1e-3
    sd = np.sqrt(s_rep.var(axis=1, ddof=1) + floor**2)
    z = (s_obs - mu) / sd
    gof = np.sqrt(np.mean(z**2, axis=1))
    return PPCResult(gof=gof, flagged=gof > threshold, z=z, replicate_nN=reps[::n_replicates])


def plot_overlay(x_nm, force_nN, replicate_nN, title: str, out) -> None:
    """The trace and, if given, one replicate simulated at its estimate."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from stickslip.atomic import atomic_path

    fig, ax = plt.subplots(figsize=(8, 3.2), constrained_layout=True)
    ax.plot(x_nm, force_nN, lw=0.9, label="measured")
    if replicate_nN is not None:
        ax.plot(x_nm, replicate_nN, lw=0.9, alpha=0.8, label="PT model at estimate")
    ax.set_xlabel("x [nm]")
    ax.set_ylabel("F [nN]")
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=8, loc="upper right")
    with atomic_path(out, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
