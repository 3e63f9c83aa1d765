"""High-level simulation API: per-trajectory parameters in, pixel-averaged traces out."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from stickslip.simulators.backends import get_backend
from stickslip.simulators.config import (
    PhysicalSettings,
    SettingsError,
    check_stable_time_step,
    gaussian_curvature_N_m,
    warmup_nm_for,
)
from stickslip.simulators.lanes import prepare_lanes
from stickslip.units import eta_from


@dataclass
class SimulationResult:
    """Traces of N trajectories.

    Attributes
    ----------
    force_nN : ndarray (N, pixels)
        Pixel-averaged lateral force ``K (X - x)``; each pixel is the mean over its
        support-travel window.
    x_nm : ndarray (pixels,)
        Recorded position, 0 at the first pixel (the trace CSV's ``x_nm``).
    support_nm : ndarray (N, pixels)
        Absolute support position X at each pixel centre (warm-up included).
    eta : ndarray (N,)
        PT parameter of each trajectory.
    dt_s : ndarray (N,)
        Time step actually used.
    fine_x_nm, fine_force_nN, fine_support_nm : ndarray (N, pixels * samples) or None
        Instantaneous tip position, force and support position at the end of each
        sub-pixel sample, if requested.
    """

    force_nN: np.ndarray
    x_nm: np.ndarray
    support_nm: np.ndarray
    eta: np.ndarray
    dt_s: np.ndarray
    fine_x_nm: np.ndarray | None = None
    fine_force_nN: np.ndarray | None = None
    fine_support_nm: np.ndarray | None = None


def _per_trajectory(value, default: float, n: int, name: str) -> np.ndarray:
    arr = np.broadcast_to(np.asarray(default if value is None else value, float), (n,)).copy()
    if not np.all(np.isfinite(arr)):
        raise SettingsError(f"{name} must be finite")
    return arr


def _barrier_factor(modulation, n: int) -> np.ndarray:
    """The largest factor the modulation puts on each trajectory's barrier."""
    if modulation is None:
        return np.ones(n)
    return 1.0 + np.abs(np.broadcast_to(np.asarray(modulation[0], float), (n,)))


def _defect_curvature_N_m(U0: np.ndarray, defects) -> np.ndarray:
    """An upper bound of the defects' curvature per trajectory (N/m): the sum of its
    Gaussians' largest curvatures (:func:`~stickslip.simulators.config.gaussian_curvature_N_m`)."""
    if defects is None:
        return np.zeros(U0.size)
    _, h, w = (np.atleast_2d(np.asarray(v, float)) for v in defects)
    return np.nansum(gaussian_curvature_N_m(U0[:, None], h, w), axis=1)


def simulate(
    U0_eV,
    K_N_m,
    settings: PhysicalSettings | None = None,
    *,
    seed: int = 0,
    indices: np.ndarray | None = None,
    lattice_nm=None,
    velocity_nm_per_s=None,
    temperature_K=None,
    damping_per_s=None,
    mass_kg=None,
    modulation: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    defects: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    samples_per_pixel: int = 0,
    backend: str = "cpu",
) -> SimulationResult:
    """Simulate finite-temperature Prandtl-Tomlinson friction traces (BAOAB, float64).

    Parameters
    ----------
    U0_eV, K_N_m : array_like (N,)
        Barrier (peak-to-peak, eV) and effective contact stiffness (N/m).
    settings : PhysicalSettings, optional
        Shared physical and recording settings (default: the paper preset).
    seed : int
        Run seed. Trajectory ``i`` draws from a stream derived from ``(seed, indices[i])``.
    indices : array_like of int, optional
        Global trajectory indices (default ``0..N-1``); give them when simulating a
        subset of a larger run so the subset reproduces the same traces.
    lattice_nm, velocity_nm_per_s, temperature_K, damping_per_s, mass_kg : array_like
        Per-trajectory overrides of ``settings``.
    modulation : (amplitude, wavelength_nm, phase_rad), optional
        Long-wavelength multiplicative modulation of the barrier, per trajectory.
    defects : (x_nm, height_in_U0, width_nm), each (N, D), optional
        Gaussian defects added to the potential; positions are absolute tip positions.
    samples_per_pixel : int
        If > 0, also return the instantaneous tip position and force this many times
        per pixel (diagnostics).
    backend : {"cpu", "cuda", "cuda-float32", "auto", "numpy"}
        Integrator backend (:mod:`stickslip.simulators.backends`): ``cpu`` (alias
        ``numba``) is the numba kernel, ``cuda`` the GPU kernel (same random streams),
        ``auto`` picks ``cuda`` when a CUDA device is present, ``numpy`` is the slow
        reference.

    Returns
    -------
    SimulationResult
    """
    s = settings or PhysicalSettings()
    U0 = np.atleast_1d(np.asarray(U0_eV, float))
    K = np.atleast_1d(np.asarray(K_N_m, float))
    if U0.shape != K.shape or U0.ndim != 1:
        raise SettingsError("U0_eV and K_N_m must be 1-D arrays of equal length")
    n = U0.size
    if np.any(~np.isfinite(K)) or np.any(K <= 0):
        raise SettingsError("K must be > 0 N/m")
    if np.any(~np.isfinite(U0)) or np.any(U0 < 0):
        raise SettingsError("U0 must be >= 0 eV")
    a = _per_trajectory(lattice_nm, s.lattice_nm, n, "lattice")
    v = _per_trajectory(velocity_nm_per_s, s.velocity_nm_per_s, n, "velocity")
    T = _per_trajectory(temperature_K, s.temperature_K, n, "temperature")
    gamma = _per_trajectory(damping_per_s, s.damping_per_s, n, "damping")
    m = _per_trajectory(mass_kg, s.mass_kg, n, "mass")
    for ok, msg in [
        (a > 0, "lattice spacing must be > 0 nm"),
        (v > 0, "velocity must be > 0 nm/s"),
        (T >= 0, "temperature must be >= 0 K"),
        (gamma >= 0, "damping must be >= 0 1/s"),
        (m > 0, "mass must be > 0 kg"),
    ]:
        if not np.all(ok):
            raise SettingsError(msg)
    check_stable_time_step(s.dt_s, U0 * _barrier_factor(modulation, n), K, a, m,
                           _defect_curvature_N_m(U0, defects))  # fmt: skip
    idx = np.arange(n) if indices is None else np.asarray(indices, dtype=np.int64)
    warm = warmup_nm_for(U0, K, a, s.warmup_nm)
    record_fine = samples_per_pixel > 0
    lanes = prepare_lanes(
        U0_eV=U0, K_N_m=K, lattice_nm=a, velocity_nm_per_s=v, temperature_K=T,
        damping_per_s=gamma, mass_kg=m, warmup_nm=warm, pixel_nm=s.pixel_nm,
        pixels=s.pixels, dt_s=s.dt_s, seed=seed, indices=idx,
        samples_per_pixel=max(1, samples_per_pixel), modulation=modulation, defects=defects,
    )  # fmt: skip
    run = get_backend(backend)
    n_sub = lanes.samples_per_pixel
    force = np.empty((n, s.pixels))
    fine_x = np.empty((n, s.pixels * n_sub)) if record_fine else None
    fine_F = np.empty((n, s.pixels * n_sub)) if record_fine else None
    # trajectories with different velocities have different step layouts: one call each
    for n_pp in np.unique(lanes.steps_per_pixel):
        sel = np.flatnonzero(lanes.steps_per_pixel == n_pp)
        # similar warm-ups share a block: lanes idle less while the longest one warms up
        sel = sel[np.argsort(lanes.n_warm[sel], kind="stable")]
        f, fx, fF = run(lanes.subset(sel), record_fine)
        force[sel] = f
        if record_fine:
            fine_x[sel], fine_F[sel] = fx, fF
    X0 = lanes.n_warm * lanes.dX  # support position at the first recorded step
    centres = (np.arange(s.pixels) + 0.5) * s.pixel_nm
    support = X0[:, None] + centres[None, :]
    fine_support = None
    if record_fine:
        ends = (np.arange(s.pixels * n_sub) + 1) * (s.pixel_nm / n_sub)
        fine_support = X0[:, None] + ends[None, :]
    return SimulationResult(
        force_nN=force,
        x_nm=np.arange(s.pixels) * s.pixel_nm,
        support_nm=support,
        eta=eta_from(U0, K, a),
        dt_s=2.0 * lanes.hdt * 1e-9,
        fine_x_nm=fine_x,
        fine_force_nN=fine_F,
        fine_support_nm=fine_support,
    )
