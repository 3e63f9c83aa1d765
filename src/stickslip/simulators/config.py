"""Simulation settings as dataclasses (saved next to every dataset).

Units are in the names. Defaults are the reference paper's "paper" preset
(../shared/PHYSICS.md): m = 1e-12 kg, Gamma = 1e7 1/s, v = 60 nm/s, T = 296 K,
a = 0.246 nm (graphene), dt = 10 ns, 11 nm recorded as 512 pixels.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from stickslip.units import EV_TO_NN_NM, eta_from, fmax_nN


class SettingsError(ValueError):
    """Invalid physical or sampling settings; ``str()`` is one line for the user."""


#: The integrator (BAOAB, velocity Verlet at its core) is stable on a harmonic well of
#: angular frequency omega only for ``omega dt`` below 2: beyond it every trajectory
#: diverges, whatever the temperature.
STABLE_OMEGA_DT = 2.0


def omega_max_per_s(U0_eV, K_N_m, lattice_nm, mass_kg, extra_N_m=0.0) -> np.ndarray:
    """The highest angular frequency (1/s) of the tip in the PT potential:
    ``sqrt((K + 2 pi^2 U0 / a^2 + extra) / m)``, the spring plus the lattice's largest
    curvature (``U = -(U0/2) cos(2 pi x/a)``) plus ``extra_N_m`` of any other potential
    (modulation, defects)."""
    curvature = 2.0 * np.pi**2 * np.asarray(U0_eV, float) * EV_TO_NN_NM \
        / np.asarray(lattice_nm, float) ** 2  # nN/nm = N/m  # fmt: skip
    stiffness = np.asarray(K_N_m, float) + curvature + np.asarray(extra_N_m, float)
    return np.sqrt(stiffness / np.asarray(mass_kg, float))


def gaussian_curvature_N_m(U0_eV, height_in_U0, width_nm) -> np.ndarray:
    """The largest curvature (N/m) of a Gaussian bump of height ``height_in_U0 * U0`` and
    std ``width_nm`` (a defect of the augmented substrate): ``|h| U0 / w^2``; 0 where
    ``w <= 0``. Broadcasts."""
    h = np.abs(np.asarray(height_in_U0, float))
    w = np.asarray(width_nm, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        per_eV = np.where(w > 0, h / (w * w), 0.0)
    return per_eV * np.asarray(U0_eV, float) * EV_TO_NN_NM


def check_stable_time_step(dt_s: float, U0_eV, K_N_m, lattice_nm, mass_kg,
                           extra_N_m=0.0) -> None:  # fmt: skip
    """Raise :class:`SettingsError` where ``dt_s`` is beyond the integrator's stability
    limit ``omega_max dt < 2`` (:data:`STABLE_OMEGA_DT`, :func:`omega_max_per_s`) for any
    of the trajectories: they would all diverge (a NaN trace), or, for a barrier of
    millions of eV, warm up for ever first."""
    omega = float(np.max(omega_max_per_s(U0_eV, K_N_m, lattice_nm, mass_kg, extra_N_m)))
    if not omega * dt_s < STABLE_OMEGA_DT:
        raise SettingsError(
            f"time step {dt_s:.3g} s is beyond the integrator's stability limit "
            f"{STABLE_OMEGA_DT / omega:.3g} s (2/omega_max at the stiffest point of the "
            "potential, spring and mass given): use a smaller time step (--dt), or check U0, "
            "K and the mass"
        )


@dataclass(frozen=True)
class PhysicalSettings:
    """Physical and recording settings shared by all trajectories of a run.

    Per-trajectory arrays given to :func:`stickslip.simulators.simulate` override the
    physical ones (mass, damping, velocity, temperature, lattice).

    Attributes
    ----------
    mass_kg : float
        Effective tip mass m.
    damping_per_s : float
        Langevin damping rate Gamma (friction term ``-m Gamma x'``).
    velocity_nm_per_s : float
        Support (cantilever base) velocity v.
    temperature_K : float
        Temperature T of the thermal noise.
    lattice_nm : float
        Lattice spacing a of ``U(x) = -(U0/2) cos(2 pi x / a)``.
    dt_s : float
        Nominal time step. The step actually used is adjusted by well under 0.1 % per
        trajectory so that a pixel holds an integer number of steps.
    length_nm : float
        Recorded support travel (the scan line).
    pixels : int
        Pixels of the recorded line; each is the mean force over its travel window.
    warmup_nm : float or None
        Support travel discarded before recording. ``None``: per trajectory
        ``max(1 nm, F_max/K + 4a)``, so the initial loading ramp is never recorded.
    """

    mass_kg: float = 1e-12
    damping_per_s: float = 1e7
    velocity_nm_per_s: float = 60.0
    temperature_K: float = 296.0
    lattice_nm: float = 0.246
    dt_s: float = 1e-8
    length_nm: float = 11.0
    pixels: int = 512
    warmup_nm: float | None = None

    def __post_init__(self) -> None:
        checks = [
            (self.mass_kg > 0, f"mass must be > 0 kg (got {self.mass_kg})"),
            (self.damping_per_s >= 0, f"damping must be >= 0 1/s (got {self.damping_per_s})"),
            (self.velocity_nm_per_s > 0, f"velocity must be > 0 nm/s ({self.velocity_nm_per_s})"),
            (self.temperature_K >= 0, f"temperature must be >= 0 K (got {self.temperature_K})"),
            (self.lattice_nm > 0, f"lattice spacing must be > 0 nm (got {self.lattice_nm})"),
            (self.dt_s > 0, f"time step must be > 0 s (got {self.dt_s})"),
            (self.length_nm > 0, f"line length must be > 0 nm (got {self.length_nm})"),
            (self.pixels >= 8, f"pixels must be >= 8 (got {self.pixels})"),
            (
                self.warmup_nm is None or self.warmup_nm >= 0,
                f"warm-up must be >= 0 nm (got {self.warmup_nm})",
            ),
        ]
        for ok, msg in checks:
            if not ok:
                raise SettingsError(msg)

    @property
    def pixel_nm(self) -> float:
        """Recorded pixel size in nm (``length_nm / pixels``)."""
        return self.length_nm / self.pixels

    def replace(self, **changes: Any) -> PhysicalSettings:
        """Copy with some fields changed (``None`` values are ignored)."""
        return dataclasses.replace(self, **{k: v for k, v in changes.items() if v is not None})


@dataclass(frozen=True)
class ParameterRange:
    """Training range of (U0, K), restricted to an eta window, sampled by Latin hypercube.

    The hypercube is drawn in (U0, K) over the rectangle; points outside the eta window
    are rejected and the draw is repeated with fresh strata until ``n`` points are kept,
    so the kept points are uniform over the allowed region.
    """

    U0_eV: tuple[float, float] = (0.3, 6.0)
    K_N_m: tuple[float, float] = (1.0, 50.0)
    eta: tuple[float, float] = (1.2, 40.0)

    def __post_init__(self) -> None:
        (u_lo, u_hi), (k_lo, k_hi), (e_lo, e_hi) = self.U0_eV, self.K_N_m, self.eta
        if not (0 <= u_lo <= u_hi):
            raise SettingsError(f"bad U0 range {self.U0_eV} eV")
        if not (0 < k_lo <= k_hi):
            raise SettingsError(f"bad K range {self.K_N_m} N/m (K must be > 0)")
        if not (0 <= e_lo <= e_hi):
            raise SettingsError(f"bad eta range {self.eta}")

    def check_feasible(self, lattice_nm: float) -> None:
        """Raise :class:`SettingsError` if no (U0, K) in the box has eta in the window."""
        (u_lo, u_hi), (k_lo, k_hi), (e_lo, e_hi) = self.U0_eV, self.K_N_m, self.eta
        eta_min = float(eta_from(u_lo, k_hi, lattice_nm))
        eta_max = float(eta_from(u_hi, k_lo, lattice_nm))
        if eta_max < e_lo or eta_min > e_hi:
            raise SettingsError(
                f"no eta in [{e_lo:g}, {e_hi:g}] inside U0 {self.U0_eV} eV x K {self.K_N_m} N/m "
                f"(eta spans [{eta_min:.3g}, {eta_max:.3g}] there at a = {lattice_nm:g} nm)"
            )


@dataclass(frozen=True)
class SubstrateAugmentation:
    """Ranges of the augmented substrate of the reference paper (off by default).

    The potential becomes
    ``U(x) = -(U0/2) [1 + A cos(2 pi x / lambda + phi)] cos(2 pi x / a)
    + sum_j h_j U0 exp(-(x - x_j)^2 / (2 w_j^2))``:
    a long-wavelength multiplicative modulation of the barrier and localised Gaussian
    defects whose heights are in units of U0. Each trajectory draws its own values.
    """

    modulation_amplitude: tuple[float, float] = (0.0, 0.0)
    modulation_wavelength_nm: tuple[float, float] = (5.0, 30.0)
    defects_per_line: tuple[int, int] = (0, 0)
    defect_height: tuple[float, float] = (-0.3, 0.3)
    defect_width_nm: tuple[float, float] = (0.1, 0.5)

    @property
    def enabled(self) -> bool:
        return self.modulation_amplitude[1] > 0 or self.defects_per_line[1] > 0


#: The substrate of a typical laboratory sample: every line's barrier modulated, up to
#: three defects (the test bench's; see also ``randomised.lab_config``).
LAB_SUBSTRATE = SubstrateAugmentation(
    modulation_amplitude=(0.0, 0.3),
    modulation_wavelength_nm=(4.0, 30.0),
    defects_per_line=(0, 3),
    defect_height=(-0.3, 0.3),
    defect_width_nm=(0.1, 0.5),
)


@dataclass(frozen=True)
class SweepConfig:
    """Everything needed to regenerate a dataset from its file alone.

    ``backend`` is the simulator backend (:mod:`stickslip.simulators.backends`). The JSON
    records it only when it is not ``cpu``: the CPU kernel gives the same traces on every
    machine, while a GPU backend's traces equal them only to rounding (and, at finite T,
    only statistically once a thermally activated slip goes the other way), so a dataset
    made on a GPU is regenerated exactly only by the same backend. ``cpu`` files keep the
    JSON they had before backends existed.
    """

    physics: PhysicalSettings = field(default_factory=PhysicalSettings)
    ranges: ParameterRange = field(default_factory=ParameterRange)
    augmentation: SubstrateAugmentation = field(default_factory=SubstrateAugmentation)
    n: int = 1600
    seed: int = 0
    preset: str = "paper"
    backend: str = "cpu"

    def __post_init__(self) -> None:
        # the box's stiffest corner at the settings' step, with the augmentation's largest
        # modulation and defects: refused before any shard runs
        p, aug, U0 = self.physics, self.augmentation, self.ranges.U0_eV[1]
        h = max(abs(v) for v in aug.defect_height)
        defects = aug.defects_per_line[1] * gaussian_curvature_N_m(U0, h, min(aug.defect_width_nm))
        modulated = U0 * (1.0 + max(abs(a) for a in aug.modulation_amplitude))
        check_stable_time_step(p.dt_s, modulated, self.ranges.K_N_m[1], p.lattice_nm,
                               p.mass_kg, defects)  # fmt: skip

    def to_json(self) -> str:
        """The whole configuration as JSON (stored in every sweep file)."""
        d = dataclasses.asdict(self)
        if d["backend"] in ("cpu", "numba"):
            del d["backend"]
        return json.dumps(d, sort_keys=True)

    @classmethod
    def from_json(cls, text: str) -> SweepConfig:
        """The configuration stored by :meth:`to_json`."""
        d = json.loads(text)
        return cls(
            physics=PhysicalSettings(**d["physics"]),
            ranges=ParameterRange(**{k: tuple(v) for k, v in d["ranges"].items()}),
            augmentation=SubstrateAugmentation(
                **{k: tuple(v) for k, v in d["augmentation"].items()}
            ),
            n=d["n"],
            seed=d["seed"],
            preset=d["preset"],
            backend=d.get("backend", "cpu"),
        )


PRESETS: dict[str, PhysicalSettings] = {
    "paper": PhysicalSettings(),
    # the reference paper's experiments: ~30 nm/s on MoS2 / WS2
    "mos2": PhysicalSettings(lattice_nm=0.316, velocity_nm_per_s=30.0),
    "ws2": PhysicalSettings(lattice_nm=0.315, velocity_nm_per_s=30.0),
}


def warmup_nm_for(
    U0_eV: np.ndarray, K_N_m: np.ndarray, lattice_nm: np.ndarray, warmup_nm: float | None
) -> np.ndarray:
    """Warm-up travel per trajectory: the given value, or ``max(1, F_max/K + 4a)`` nm."""
    if warmup_nm is not None:
        return np.full(np.shape(U0_eV), float(warmup_nm))
    return np.maximum(1.0, fmax_nN(U0_eV, lattice_nm) / K_N_m + 4.0 * lattice_nm)
