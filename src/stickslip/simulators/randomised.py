"""Domain-randomised training sets: many lattices, velocities and substrates.

Parameters are drawn in the reference frame (lattice a0 = 0.246 nm) over a range a bit
wider than the paper's, each trajectory then gets a lattice spacing ``a`` (uniform over
``lattice_nm``, or exactly ``a0`` for a ``reference_fraction`` of them) with
``U0 = U0_ref (a / a0)^2`` (same eta), a scan velocity from
``velocities_nm_per_s`` (a few discrete values: one simulator call per velocity), and
an augmented substrate (modulation and defects) for all but ``clean_fraction`` of them.
Detector effects are not simulated here: the training pipeline adds them on the fly.

The contact's dynamics and the acquisition can be randomised too (``velocity_range``,
``temperature_range_K``, ``damping_factor``, ``mass_factor``): a real contact's damping
and effective mass are on no label (PHYSICS.md), so a model trained over a range of
them integrates over them instead of assuming the preset's. Velocities are drawn
log-uniform and rounded to :data:`VELOCITY_STEPS` log-spaced values over the range, so
that one simulator call serves many trajectories.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

from stickslip._version import __version__
from stickslip.simulators.config import (
    LAB_SUBSTRATE,
    ParameterRange,
    PhysicalSettings,
    SubstrateAugmentation,
)
from stickslip.simulators.sampling import SubstrateDraw, sample_parameters, sample_substrate
from stickslip.simulators.simulate import simulate
from stickslip.traces.dataset import (
    Dataset,
    create_dataset_file,
    load_dataset,
    open_dataset,
    read_attrs,
    write_rows,
)
from stickslip.units import eta_from

A_REF_NM = 0.246
#: log-spaced velocities a continuous velocity range is rounded to (one simulator call each)
VELOCITY_STEPS = 16


@dataclass(frozen=True)
class RandomisedConfig:
    """Everything that defines a randomised training set (stored in its file)."""

    n: int = 4000
    seed: int = 101
    ranges: ParameterRange = field(
        default_factory=lambda: ParameterRange(U0_eV=(0.15, 6.5), K_N_m=(1.0, 55.0),
                                               eta=(1.2, 42.0))  # fmt: skip
    )
    lattice_nm: tuple[float, float] = (0.235, 0.335)
    velocities_nm_per_s: tuple[float, ...] = (30.0, 45.0, 60.0, 90.0)
    temperature_K: float = 296.0
    substrate: SubstrateAugmentation = field(
        default_factory=lambda: SubstrateAugmentation(
            modulation_amplitude=(0.0, 0.35),
            modulation_wavelength_nm=(3.0, 35.0),
            defects_per_line=(0, 4),
            defect_height=(-0.35, 0.35),
            defect_width_nm=(0.08, 0.6),
        )
    )
    clean_fraction: float = 0.25
    # lines recorded exactly on the reference lattice (graphite, the most common sample)
    # need no resampling when mapped, so they look slightly sharper than mapped ones:
    # the network must see such lines too
    reference_fraction: float = 0.3
    length_nm: float = 11.0
    pixels: int = 512
    chunk: int = 500
    #: log-uniform velocity range (nm/s); None: the discrete ``velocities_nm_per_s``
    velocity_range: tuple[float, float] | None = None
    #: uniform temperature range (K); None: ``temperature_K`` for every trajectory
    temperature_range_K: tuple[float, float] | None = None
    #: log-uniform factors on the preset's damping rate and tip mass (PhysicalSettings)
    damping_factor: tuple[float, float] = (1.0, 1.0)
    mass_factor: tuple[float, float] = (1.0, 1.0)
    #: the share of trajectories whose (U0, K) are drawn log-uniform over ``ranges``
    #: (:func:`~stickslip.simulators.sampling.sample_parameters` with ``log``), the rest
    #: uniform as in the reference paper. The uniform draw puts about 3 % of the lines
    #: below 5 N/m and two thirds at 20-55 N/m; half log-uniform, 20 % and 44 %.
    log_fraction: float = 0.0

    def to_json(self) -> str:
        d = dataclasses.asdict(self)
        if d["log_fraction"] == 0.0:  # as sets made before the field was added: same digest
            del d["log_fraction"]
        return json.dumps(d, sort_keys=True)

    @classmethod
    def from_json(cls, text: str) -> RandomisedConfig:
        """The config stored in a set's file (fields added later take the value that
        files written before them were made with: no lines on the reference lattice)."""
        d = {"reference_fraction": 0.0, **json.loads(text)}
        for k in ("velocity_range", "temperature_range_K"):
            if d.get(k) is not None:
                d[k] = tuple(d[k])

        def tuples(sub: dict) -> dict:
            return {k: tuple(v) if isinstance(v, list) else v for k, v in sub.items()}

        d["ranges"] = ParameterRange(**tuples(d["ranges"]))
        d["substrate"] = SubstrateAugmentation(**tuples(d["substrate"]))
        return cls(**tuples(d))


def lab_config(n: int, seed: int) -> RandomisedConfig:
    """A randomised set on a typical laboratory's substrate rather than a broad one: the
    training sets' parameters, lattices and velocities on
    :data:`~stickslip.simulators.config.LAB_SUBSTRATE` (every line augmented). With the
    :data:`~stickslip.simulators.instrument.LAB` detector effects added, it lies between
    the training distribution and the test bench (which also fixes the materials'
    lattices and the scan velocity)."""
    return RandomisedConfig(n=n, seed=seed, substrate=LAB_SUBSTRATE, clean_fraction=0.0)


#: the contact dynamics and acquisition the bundled line model is trained over: velocity
#: log-uniform 10-200 nm/s, temperature 250-350 K, damping 0.1-10x and tip mass 0.3-3x
#: the preset's (the scan length and pixel count stay at the reference: lines are mapped
#: onto its pixel, benchmarks/lattice_mapping.py)
DYNAMICS_PRIOR = {"velocity_range": (10.0, 200.0), "temperature_range_K": (250.0, 350.0),
                  "damping_factor": (0.1, 10.0), "mass_factor": (0.3, 3.0)}  # fmt: skip


def with_dynamics(config: RandomisedConfig, prior: dict | None = None) -> RandomisedConfig:
    """``config`` with the contact dynamics and acquisition randomised (default
    :data:`DYNAMICS_PRIOR`)."""
    return dataclasses.replace(config, **(DYNAMICS_PRIOR if prior is None else prior))


def draw_randomised(config: RandomisedConfig) -> tuple[dict[str, np.ndarray], SubstrateDraw]:
    """The per-trajectory draws of a randomised set, without simulating it.

    Returns the parameter table (``U0_eV``, ``K_N_m``, ``eta``, ``lattice_nm``,
    ``velocity_nm_per_s``, ... as stored in the set's file) and the substrate draw.
    """
    rng = np.random.default_rng([config.seed, 31])
    n = config.n
    U0_ref, K = _draw_barriers(config)
    a = rng.uniform(*config.lattice_nm, n)
    U0 = U0_ref * (a / A_REF_NM) ** 2
    v = rng.choice(np.asarray(config.velocities_nm_per_s, float), n)
    sub = sample_substrate(config.substrate, n, config.seed, span_nm=16.0)
    clean = rng.random(n) < config.clean_fraction
    if config.reference_fraction > 0:  # drawn last: earlier draws stay as they were
        on_ref = rng.random(n) < config.reference_fraction
        a[on_ref] = A_REF_NM
        U0[on_ref] = U0_ref[on_ref]
    sub.mod_amplitude[clean] = 0.0
    sub.defect_height[clean] = 0.0
    # the dynamics and acquisition come from a stream of their own: the draws above are
    # the same whether they are randomised or not
    v, T, gamma, m = _draw_dynamics(config, v)
    table = {
        "index": np.arange(n), "U0_eV": U0, "K_N_m": K, "eta": eta_from(U0, K, a),
        "F_mean_nN": np.full(n, np.nan), "lattice_nm": a, "velocity_nm_per_s": v,
        "temperature_K": T, "damping_per_s": gamma, "mass_kg": m,
        "mod_amplitude": sub.mod_amplitude,
        "defect_count": np.count_nonzero(sub.defect_height, axis=1),
    }  # fmt: skip
    return table, sub


def _draw_barriers(config: RandomisedConfig) -> tuple[np.ndarray, np.ndarray]:
    """(U0, K) on the reference lattice per trajectory: a ``log_fraction`` of them
    log-uniform, the rest uniform, in an order of their own stream."""
    n_log = int(round(config.log_fraction * config.n))
    U0, K = sample_parameters(config.ranges, config.n - n_log, config.seed, A_REF_NM)
    if n_log == 0:
        return U0, K
    U0_log, K_log = sample_parameters(config.ranges, n_log, config.seed, A_REF_NM, log=True)
    order = np.random.default_rng([config.seed, 33]).permutation(config.n)
    return np.concatenate([U0, U0_log])[order], np.concatenate([K, K_log])[order]


def _draw_dynamics(config: RandomisedConfig, v: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """Velocity, temperature, damping rate and mass per trajectory (see the module)."""
    n = v.size
    rng = np.random.default_rng([config.seed, 32])
    preset = PhysicalSettings()

    def log_uniform(lo: float, hi: float) -> np.ndarray:
        return np.exp(rng.uniform(np.log(lo), np.log(hi), n))

    if config.velocity_range is not None:
        lo, hi = config.velocity_range
        grid = np.geomspace(lo, hi, VELOCITY_STEPS)
        u = rng.uniform(0.0, 1.0, n) * (VELOCITY_STEPS - 1)
        v = grid[np.rint(u).astype(int)]
    T = (np.full(n, config.temperature_K) if config.temperature_range_K is None
         else rng.uniform(*config.temperature_range_K, n))  # fmt: skip
    gamma = preset.damping_per_s * log_uniform(*config.damping_factor)
    m = preset.mass_kg * log_uniform(*config.mass_factor)
    return v, T, gamma, m


def make_randomised_set(config: RandomisedConfig, out: str | os.PathLike,
                        progress: bool = True) -> Path:  # fmt: skip
    """Simulate the set into ``out`` (dataset layout of :mod:`stickslip.traces.dataset`)."""
    out = Path(out)
    n = config.n
    table, sub = draw_randomised(config)
    U0, K, a, v, T, gamma, m = (table[k] for k in (
        "U0_eV", "K_N_m", "lattice_nm", "velocity_nm_per_s", "temperature_K", "damping_per_s",
        "mass_kg"))  # fmt: skip
    physics = PhysicalSettings(temperature_K=config.temperature_K, length_nm=config.length_nm,
                               pixels=config.pixels)  # fmt: skip
    x_nm = np.arange(physics.pixels) * physics.pixel_nm
    attrs = {"config": config.to_json(), "seed": config.seed, "stickslip_version": __version__,
             "n": n, "pixels": physics.pixels, "kind": "randomised"}  # fmt: skip
    out.parent.mkdir(parents=True, exist_ok=True)
    part = out.with_name(out.name + ".partial")
    create_dataset_file(part, n, x_nm, table, attrs)
    # chunks in order of velocity: the kernel integrates lanes in blocks that share their
    # step layout, so a chunk of one or two velocities fills its blocks (the same traces:
    # each trajectory's random stream depends only on its index)
    order = np.argsort(v, kind="stable")
    for s in tqdm(range(0, n, config.chunk), desc=f"simulate {out.name}", disable=not progress):
        rows = np.sort(order[s : s + config.chunk])
        res = simulate(
            U0[rows], K[rows], physics, seed=config.seed, indices=rows, lattice_nm=a[rows],
            velocity_nm_per_s=v[rows], temperature_K=T[rows], damping_per_s=gamma[rows],
            mass_kg=m[rows],
            modulation=(sub.mod_amplitude[rows], sub.mod_wavelength_nm[rows],
                        sub.mod_phase_rad[rows]),
            defects=(sub.defect_x_nm[rows], sub.defect_height[rows], sub.defect_width_nm[rows]),
        )  # fmt: skip
        write_rows(part, rows, res.force_nN, res.support_nm,
                   {"F_mean_nN": res.force_nN.mean(axis=1)})  # fmt: skip
    os.replace(part, out)
    return out


def cache_path(config: RandomisedConfig, work: str | os.PathLike) -> Path:
    """Where :func:`cached_randomised_set` keeps a set: ``work/randomised_{n}_{seed}.h5``
    for the default settings, with a digest of the config appended for any other, so
    that sets of the same size and seed but other settings (an ablation's, the
    laboratory prior's) do not replace each other in a shared folder."""
    name = f"randomised_{config.n}_{config.seed}"
    if config != RandomisedConfig(n=config.n, seed=config.seed):
        name += "_" + hashlib.sha256(config.to_json().encode()).hexdigest()[:10]
    return Path(work) / f"{name}.h5"


def cached_randomised_set(config: RandomisedConfig, work: str | os.PathLike,
                          progress: bool = True, lazy: bool = False) -> Dataset:  # fmt: skip
    """The set at :func:`cache_path`, simulated first if it is missing or was made with
    other settings than ``config``; with ``lazy``, its forces are left on disk
    (:func:`~stickslip.traces.dataset.open_dataset`, for streamed training)."""
    path = cache_path(config, work)
    # the stored config is in the file's attributes: no need to read its traces twice
    if not path.exists() or RandomisedConfig.from_json(
            str(read_attrs(path).get("config", "{}"))) != config:  # fmt: skip
        make_randomised_set(config, path, progress)  # replaces the file only when done
    return open_dataset(path) if lazy else load_dataset(path)
