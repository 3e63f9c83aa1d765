"""Posterior predictive check: does the PT model at the estimate reproduce the trace?

Each trace is re-simulated several times at its estimated (U0, K), with its lattice,
velocity and temperature, and with white noise of the level measured on the trace. A
set of summary statistics (mean friction, force spread, upper force percentiles, median
positive slope, slip rate and mean slip drop) of the observed trace is compared with
their spread over the replicates, and so is the change of the mean friction along the
line. The goodness-of-fit number is the RMS z-score over them; a trace scoring above
``threshold`` is flagged as one the PT model cannot describe (defects, domain
crossings, a lost contact), as a person looking at the overlay would.

How, and why it is cheap:

- Replicates are short (:data:`REPLICATE_NM`, 2 nm: 8 graphite periods) and the trace
  is cut into segments of the same length: both sides give the same statistics of the
  same length of line (a slip threshold or a percentile depends on the length), each
  over a whole number of lattice periods (the mean of a periodic force over part of a
  period depends on where the line starts). A statistic's z is the difference of the
  mean over the segments and the mean over the replicates, in units of the model's
  spread of that difference; the segment means of <F> give a chi-square for the
  change along the line.
- 4 replicates per trace, a warm-up up to the first slip plus 2 lattice periods, and
  the largest time step a BAOAB step integrates well (``omega_max dt <= 0.5`` at the
  stiffest point of the potential, at most 50 ns; a pixel still spans thousands of
  steps); all replicates of a batch in as few simulate calls as the time steps allow.

Against the first version (8 full-length replicates at 10 ns: about 0.5 traces per CPU
second here) this simulates about 1/20 of the steps and keeps the verdicts: clean
traces at their truth pass, wrong estimates, domain crossings and a lost contact are
flagged (tests/diagnostics/test_ppc.py, tests/cli/test_first_day_defects.py).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from stickslip.compiled import made_up_line
from stickslip.estimators.noise import noise_nN
from stickslip.simulators.config import PhysicalSettings, omega_max_per_s
from stickslip.simulators.kernel import LANES
from stickslip.simulators.simulate import simulate
from stickslip.units import fmax_nN

STATISTICS = ("F_mean", "F_std", "F_p90", "F_p99", "slope_med", "slips_per_nm", "drop_mean")
#: Columns of :attr:`PPCResult.z`: the statistics, then the change of <F> along the line.
Z_NAMES = (*STATISTICS, "F_mean_along")


def trace_statistics(x_nm: np.ndarray, force_nN: np.ndarray,
                     lattice_nm: float | np.ndarray | None = None) -> np.ndarray:  # fmt: skip
    """Summary statistics (N, len(STATISTICS)) of traces sharing positions ``x_nm``.

    With ``lattice_nm`` (one value, or one per trace) they are taken over the longest
    whole number of lattice periods from the start of each line, the last pixel weighted
    by the part of it inside: the mean of a periodic force over a fraction of a period
    depends on where the line starts, which differs between a trace and its replicates
    (on a slowly slipping line that fraction is worth many times the mean friction).
    """
    F = np.atleast_2d(np.asarray(force_nN, float))
    n, p = F.shape
    dx = float(np.mean(np.diff(x_nm)))
    if lattice_nm is None:
        return _statistics(F, dx, np.ones(p))
    a = np.broadcast_to(np.asarray(lattice_nm, float), (n,))
    out = np.empty((n, len(STATISTICS)))
    for value in np.unique(a):
        rows = np.flatnonzero(a == value)
        periods = np.floor(p * dx / value)
        if periods < 1:
            out[rows] = _statistics(F[rows], dx, np.ones(p))
            continue
        m = min(float(p), periods * value / dx)  # pixels in whole periods
        full = int(np.floor(m + 1e-9))
        w = np.ones(min(p, full + 1))
        if w.size > full:
            w[full] = m - full
        out[rows] = _statistics(F[rows, : w.size], dx, w)
    return out


def _statistics(F: np.ndarray, dx: float, w: np.ndarray) -> np.ndarray:
    """:func:`trace_statistics` of lines ``F`` (N, P) with pixel weights ``w`` (P,)."""
    length = dx * (F.shape[1] - 1)
    mean = (F * w).sum(axis=1) / w.sum()
    std = np.sqrt(((F - mean[:, None]) ** 2 * w).sum(axis=1) / w.sum())
    dF = np.diff(F, axis=1)
    span = np.percentile(F, 99, axis=1) - np.percentile(F, 1, axis=1)
    slip = dF < -0.3 * span[:, None]
    n_slip = slip.sum(axis=1)
    drop = np.where(slip, -dF, 0.0).sum(axis=1) / np.maximum(n_slip, 1)
    slope = np.where(dF > 0, dF / dx, np.nan)
    return np.column_stack(
        [
            mean,
            std,
            np.percentile(F, 90, axis=1),
            np.percentile(F, 99, axis=1),
            np.nanmedian(slope, axis=1),
            n_slip / max(length, dx),
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
    z : ndarray (N, len(Z_NAMES))
        Per-statistic z-scores (names in :data:`Z_NAMES`; the last, the change of the
        mean force along the line, is NaN for a line no longer than one replicate).
    replicate_nN : ndarray (N, P)
        One re-simulated trace per input, for overlay plots (NaN beyond the simulated
        part of the line).
    """

    gof: np.ndarray
    flagged: np.ndarray
    z: np.ndarray
    replicate_nN: np.ndarray


#: Length simulated per replicate (nm); the statistics need a few lattice periods.
REPLICATE_NM = 2.0
#: Largest time step of the check (s), and the stability margin omega_max * dt.
MAX_DT_S = 5e-8
OMEGA_DT = 0.5
#: Warm-up of a replicate after the support has moved F_max/K, in lattice periods.
WARMUP_PERIODS = 2.0
MIN_REPLICATE_PIXELS = 16


def check_time_step(U0_eV: np.ndarray, K_N_m: np.ndarray, lattice_nm: np.ndarray,
                    mass_kg: float = 1e-12) -> np.ndarray:  # fmt: skip
    """The check's time step per trace (s): ``OMEGA_DT / omega_max``, at most
    :data:`MAX_DT_S`, where ``omega_max^2 = (K + 2 pi^2 U0 / a^2) / m`` is the stiffest
    curvature of the PT potential plus the spring; rounded down to a few levels
    (``MAX_DT_S / 2^(k/2)``) so that traces share simulate calls."""
    omega = omega_max_per_s(U0_eV, K_N_m, lattice_nm, mass_kg)
    level = np.ceil(2.0 * np.log2(np.maximum(1.0, MAX_DT_S * omega / OMEGA_DT)))
    return MAX_DT_S / 2.0 ** (level / 2.0)


def posterior_predictive_check(
    x_nm: np.ndarray,
    force_nN: np.ndarray,
    U0_eV: np.ndarray,
    K_N_m: np.ndarray,
    *,
    lattice_nm: float | np.ndarray = 0.246,
    velocity_nm_per_s: float | np.ndarray = 60.0,
    temperature_K: float | np.ndarray = 296.0,
    n_replicates: int = 4,
    threshold: float = 3.0,
    seed: int = 0,
    replicate_nm: float | None = REPLICATE_NM,
    dt_s: float | None = None,
) -> PPCResult:
    """Re-simulate traces at their estimates and score how well they are reproduced.

    All traces go through one simulate call (give as many as possible at once).

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
        Simulations per trace (at least 2).
    threshold : float
        Flag traces whose goodness-of-fit number exceeds this.
    seed : int
        Seed of the replicates.
    replicate_nm : float or None
        Length simulated per replicate (at most the trace's; None: the whole trace). The
        replicates' spread is scaled to the trace's length.
    dt_s : float, optional
        Time step of every replicate; default per trace, :func:`check_time_step`.

    Returns
    -------
    PPCResult
        ``replicate_nN`` covers the simulated part of each line (NaN beyond it).
    """
    F = np.atleast_2d(np.asarray(force_nN, float))
    n, p = F.shape
    U0 = np.clip(np.asarray(U0_eV, float), 1e-3, None)
    K = np.clip(np.asarray(K_N_m, float), 1e-2, None)
    x = np.asarray(x_nm, float)
    pixel = float(x[-1] - x[0]) / (p - 1)
    p_sim = p if replicate_nm is None else int(min(p, max(MIN_REPLICATE_PIXELS,
                                                          np.ceil(replicate_nm / pixel))))
    a = np.broadcast_to(np.asarray(lattice_nm, float), (n,))
    dt = check_time_step(U0, K, a) if dt_s is None else np.full(n, float(dt_s))
    rep_n = n * n_replicates
    sim = np.empty((rep_n, p_sim))
    every = np.arange(rep_n)
    per_rep = {"lattice_nm": np.repeat(a, n_replicates),
               "velocity_nm_per_s": np.repeat(np.broadcast_to(velocity_nm_per_s, (n,)),
                                              n_replicates),
               "temperature_K": np.repeat(np.broadcast_to(temperature_K, (n,)), n_replicates)}
    U0_rep, K_rep, dt_rep = (np.repeat(v, n_replicates) for v in (U0, K, dt))
    dt_rep = dt_rep.copy()
    # the kernel integrates LANES trajectories at a time, each block as long as its
    # longest member: one simulate call per time step (a step shared by too few
    # replicates to fill two blocks takes the next smaller one), split into calls of
    # similar warm-up (up to the first slip, then WARMUP_PERIODS lattice periods)
    for step in np.unique(dt_rep):
        if (dt_rep == step).sum() < 2 * LANES and (dt_rep < step).any():
            dt_rep[dt_rep == step] = dt_rep[dt_rep < step].max()
    lat = per_rep["lattice_nm"]
    warm = fmax_nN(U0_rep, lat) / K_rep + WARMUP_PERIODS * lat
    for step in np.unique(dt_rep):
        lanes = every[dt_rep == step]
        lanes = lanes[np.argsort(warm[lanes], kind="stable")]
        cuts = list(range(2 * LANES, lanes.size - 2 * LANES + 1, 2 * LANES))
        for sel in np.split(lanes, cuts):
            settings = PhysicalSettings(length_nm=pixel * p_sim, pixels=p_sim, dt_s=float(step),
                                        warmup_nm=float(warm[sel].max()))  # fmt: skip
            sim[sel] = simulate(U0_rep[sel], K_rep[sel], settings, seed=seed, indices=sel,
                                **{k: v[sel] for k, v in per_rep.items()}).force_nN
    rng = np.random.default_rng([seed, 1])
    # the replicates already carry thermal noise: add only the detector noise the
    # observed trace has beyond it
    intrinsic = noise_nN(sim).reshape(n, n_replicates).mean(axis=1)
    extra = np.sqrt(np.clip(noise_nN(F) ** 2 - intrinsic**2, 0.0, None))
    reps = sim + rng.standard_normal((rep_n, p_sim)) * np.repeat(extra, n_replicates)[:, None]
    # the trace is cut into segments as long as a replicate: the same statistics of the
    # same length of line (a slip threshold or a percentile depends on the length)
    n_seg = max(1, p // p_sim)
    seg = F[:, : n_seg * p_sim].reshape(n * n_seg, p_sim)
    s_obs = trace_statistics(x[:p_sim], seg, np.repeat(a, n_seg)).reshape(n, n_seg, -1)
    s_rep = trace_statistics(x[:p_sim], reps, per_rep["lattice_nm"]).reshape(n, n_replicates, -1)
    mu = s_rep.mean(axis=1)
    # the difference of two means: over the trace's segments and over the replicates,
    # with the model's spread of one segment (the replicates'), floored so that a
    # statistic that barely varies in the model (e.g. the slip rate) does not turn a
    # small mismatch into a huge z
    floor = 0.03 * np.abs(mu) + 1e-3
    var = s_rep.var(axis=1, ddof=1)
    sd = np.sqrt(var * (1.0 / n_seg + 1.0 / n_replicates) + floor**2)
    z = np.full((n, len(Z_NAMES)), np.nan)
    z[:, : len(STATISTICS)] = (s_obs.mean(axis=1) - mu) / sd
    if n_seg >= 2:
        # does <F> change along the line more than the model's segments do (a domain
        # crossing, a lost contact, drift)? chi-square of the segment means, as a z
        m = s_obs[:, :, 0]
        chi2 = ((m - m.mean(axis=1, keepdims=True)) ** 2).sum(axis=1) / (var[:, 0]
                                                                         + floor[:, 0] ** 2)
        z[:, -1] = (chi2 - (n_seg - 1)) / np.sqrt(2.0 * (n_seg - 1))
    gof = np.sqrt(np.nanmean(z**2, axis=1))
    overlay = np.full((n, p), np.nan)
    overlay[:, :p_sim] = reps[::n_replicates]
    return PPCResult(gof=gof, flagged=gof > threshold, z=z, replicate_nN=overlay)


def warm() -> None:
    """Compile the simulator kernel the check runs into numba's on-disk cache: one
    made-up line, checked (a step of :func:`stickslip.compiled.compile_ahead`)."""
    x, F = made_up_line()
    posterior_predictive_check(x, F[None], np.array([1.0]), np.array([10.0]), n_replicates=2)


def plot_overlay(x_nm, force_nN, replicate_nN, title: str, out) -> None:
    """The trace and, if given, one replicate simulated at its estimate."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from stickslip.atomic import atomic_path

    fig, ax = plt.subplots(figsize=(8, 3.2), constrained_layout=True)
    ax.plot(x_nm, force_nN, lw=0.9, label="measured")
    if replicate_nN is not None:
        part = np.isfinite(replicate_nN)
        label = "PT model at estimate" + ("" if part.all() else
                                           f" (first {np.asarray(x_nm)[part].max():.3g} nm)")
        ax.plot(x_nm, replicate_nN, lw=0.9, alpha=0.8, label=label)
    ax.set_xlabel("x [nm]")
    ax.set_ylabel("F [nN]")
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=8, loc="upper right")
    with atomic_path(out, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
