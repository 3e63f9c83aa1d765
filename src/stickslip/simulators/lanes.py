"""Per-trajectory integration parameters in internal units (nm, ns, nN), shared by backends.

:func:`prepare_lanes` turns user-facing per-trajectory arrays (eV, N/m, kg, 1/s, K, nm/s)
into the quantities the BAOAB step needs, and fixes the step layout: every trajectory
gets ``n_warm`` warm-up steps and ``pixels * steps_per_pixel`` recorded steps, with its
time step adjusted (well under 0.1 %) so that a pixel holds an integer, even number of
steps (the kernels draw Gaussian numbers in Box-Muller pairs, one pair per two steps).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from stickslip.units import (
    EV_TO_NN_NM,
    KB_NN_NM_PER_K,
    KG_TO_INTERNAL_MASS,
    PER_S_TO_PER_NS,
    S_TO_NS,
)

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
MAX_DEFECTS = 4  # defects per line (the kernel's defect sum is written out for 4)


@dataclass
class Lanes:
    """Arrays of length N (one entry per trajectory) in internal units.

    ``f0`` = pi U0 / a [nN], ``inv_a`` [1/nm], ``K`` [nN/nm], ``hdt`` = dt/2 [ns],
    ``hdt_m`` = dt/(2m) [nm/(nN ns)], ``c`` = exp(-Gamma dt), ``sig`` =
    sqrt((1 - c^2) kB T / m) [nm/ns], ``dX`` = v dt [nm], ``n_warm`` (even) warm-up steps,
    ``rng0``/``rng1`` xoroshiro128++ states. Augmentation: ``half_U0`` = U0/2 [nN nm],
    ``mod_amp``, ``mod_q`` [rad/nm], ``mod_phase``, and defects ``def_x`` [nm], ``def_H``
    [nN nm], ``def_c`` = 1/(2 w^2) [1/nm^2] of shape (N, D).
    """

    f0: np.ndarray
    inv_a: np.ndarray
    K: np.ndarray
    hdt: np.ndarray
    hdt_m: np.ndarray
    c: np.ndarray
    sig: np.ndarray
    dX: np.ndarray
    n_warm: np.ndarray
    rng0: np.ndarray
    rng1: np.ndarray
    half_U0: np.ndarray
    mod_amp: np.ndarray
    mod_q: np.ndarray
    mod_phase: np.ndarray
    def_x: np.ndarray
    def_H: np.ndarray
    def_c: np.ndarray
    steps_per_pixel: np.ndarray
    samples_per_pixel: int
    pixels: int

    @property
    def n(self) -> int:
        return int(self.f0.size)

    @property
    def augmented(self) -> bool:
        return bool(np.any(self.mod_amp != 0) or np.any(self.def_H != 0))

    def subset(self, idx: np.ndarray) -> Lanes:
        """Lanes restricted to trajectories ``idx`` (same step layout)."""
        kw = {}
        for name, val in vars(self).items():
            kw[name] = val[idx] if isinstance(val, np.ndarray) else val
        return Lanes(**kw)


def _splitmix64(z: np.ndarray) -> np.ndarray:
    """SplitMix64 finaliser (vectorised, wrapping uint64 arithmetic)."""
    with np.errstate(over="ignore"):
        z = z + _GOLDEN
        z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        return z ^ (z >> np.uint64(31))


def rng_states(seed: int, indices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """xoroshiro128++ states for trajectories ``indices`` of a run with ``seed``.

    A trajectory's stream depends only on ``(seed, index)``: results do not depend on
    batch split or thread count.
    """
    idx = np.asarray(indices, dtype=np.uint64)
    with np.errstate(over="ignore"):
        base = _splitmix64(np.full(idx.shape, np.uint64(seed & 0xFFFFFFFFFFFFFFFF)))
        z = base ^ (idx * np.uint64(0xD1B54A32D192ED03))
    s0 = _splitmix64(z)
    s1 = _splitmix64(s0 ^ np.uint64(0x5851F42D4C957F2D))
    s1 = np.where((s0 == 0) & (s1 == 0), np.uint64(1), s1)  # the all-zero state is absorbing
    return s0, s1


def step_layout(
    pixel_nm: float, velocity_nm_per_s: np.ndarray, dt_s: float, samples_per_pixel: int
) -> tuple[np.ndarray, np.ndarray]:
    """Steps per pixel and the time step actually used, per trajectory.

    Steps per pixel is the nearest multiple of ``2 * samples_per_pixel`` to
    ``pixel / (v dt)``; the step is then ``pixel / (v n_pp)``. Both depend only on the
    trajectory's own velocity, so results never depend on how trajectories are batched.
    """
    v = np.asarray(velocity_nm_per_s, dtype=float)
    per_sample = pixel_nm / (v * dt_s) / samples_per_pixel
    n_ps = np.maximum(2, 2 * np.round(per_sample / 2.0)).astype(np.int64)
    n_pp = n_ps * samples_per_pixel
    dt_eff = pixel_nm / (v * n_pp)
    return n_pp, dt_eff


def prepare_lanes(
    *,
    U0_eV: np.ndarray,
    K_N_m: np.ndarray,
    lattice_nm: np.ndarray,
    velocity_nm_per_s: np.ndarray,
    temperature_K: np.ndarray,
    damping_per_s: np.ndarray,
    mass_kg: np.ndarray,
    warmup_nm: np.ndarray,
    pixel_nm: float,
    pixels: int,
    dt_s: float,
    seed: int,
    indices: np.ndarray,
    samples_per_pixel: int = 1,
    modulation: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    defects: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> Lanes:
    """Convert per-trajectory physical arrays into :class:`Lanes`.

    ``modulation`` is ``(amplitude, wavelength_nm, phase_rad)``; ``defects`` is
    ``(x_nm, height_in_U0, width_nm)`` of shape (N, D) each (height 0 = no defect).
    """
    U0 = np.asarray(U0_eV, float) * EV_TO_NN_NM
    a = np.asarray(lattice_nm, float)
    K = np.asarray(K_N_m, float)
    v_nm_ns = np.asarray(velocity_nm_per_s, float) * PER_S_TO_PER_NS
    m = np.asarray(mass_kg, float) * KG_TO_INTERNAL_MASS
    gamma = np.asarray(damping_per_s, float) * PER_S_TO_PER_NS
    kT = np.asarray(temperature_K, float) * KB_NN_NM_PER_K
    n_pp, dt_eff_s = step_layout(pixel_nm, velocity_nm_per_s, dt_s, samples_per_pixel)
    dt = dt_eff_s * S_TO_NS
    c = np.exp(-gamma * dt)
    dX = v_nm_ns * dt
    n_warm = 2 * np.ceil(np.asarray(warmup_nm, float) / dX / 2.0).astype(np.int64)
    r0, r1 = rng_states(seed, indices)
    n = U0.size
    if modulation is None:
        mod_amp, mod_q, mod_phase = np.zeros(n), np.zeros(n), np.zeros(n)
    else:
        amp, wl, ph = (np.asarray(v, float) for v in modulation)
        mod_amp, mod_q, mod_phase = amp, 2 * np.pi / wl, ph
    if defects is None:
        def_x, def_H, def_c = np.zeros((n, 1)), np.zeros((n, 1)), np.ones((n, 1))
    else:
        dx_, dh, dw = (np.atleast_2d(np.asarray(v, float)) for v in defects)
        if dx_.shape[1] > MAX_DEFECTS:
            from stickslip.simulators.config import SettingsError

            raise SettingsError(f"at most {MAX_DEFECTS} defects per line (got {dx_.shape[1]})")
        def_x, def_H, def_c = dx_, dh * U0[:, None], 1.0 / (2.0 * dw**2)
    return Lanes(
        f0=np.pi * U0 / a,
        inv_a=1.0 / a,
        K=K,
        hdt=0.5 * dt,
        hdt_m=0.5 * dt / m,
        c=c,
        sig=np.sqrt((1.0 - c**2) * kT / m),
        dX=dX,
        n_warm=n_warm,
        rng0=r0,
        rng1=r1,
        half_U0=0.5 * U0,
        mod_amp=mod_amp,
        mod_q=mod_q,
        mod_phase=mod_phase,
        def_x=np.ascontiguousarray(def_x),
        def_H=np.ascontiguousarray(def_H),
        def_c=np.ascontiguousarray(def_c),
        steps_per_pixel=n_pp,
        samples_per_pixel=samples_per_pixel,
        pixels=pixels,
    )
