"""The laboratory test bench: simulated traces that carry real-world effects, with truth.

Three materials (graphite a = 0.246 nm, MoS2 0.316 nm, WS2 0.315 nm), scanned at 30 nm/s
and 296 K, on a substrate with long-wavelength barrier modulation and Gaussian defects,
then passed through the instrument chain of :mod:`stickslip.simulators.instrument`
(precursor softening, detector low-pass, white and 1/f noise, offset drift, 16-bit
digitisation). Its seeds are disjoint from anything used for training (training seeds
are small integers; the bench's is a date).

The truth of ``F_mean_nN`` is the mean of the clean simulated trace (before the
instrument), so an offset drift counts as an error, as it would in a real measurement.
"""

from __future__ import annotations

import dataclasses
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
from stickslip.simulators.instrument import LAB, InstrumentEffects, apply_instrument
from stickslip.simulators.sampling import sample_parameters, sample_substrate
from stickslip.simulators.simulate import simulate
from stickslip.traces.dataset import create_dataset_file, write_rows
from stickslip.units import eta_from

MATERIALS: dict[str, float] = {"graphite": 0.246, "MoS2": 0.316, "WS2": 0.315}
BENCH_SEED = 20261121
#: The eta range of the bench's draws and of the targets' scoring (stick-slip regime).
ETA_WINDOW = (1.5, 40.0)


def in_eta_window(eta: np.ndarray) -> np.ndarray:
    """Boolean mask of the traces with ``eta`` inside :data:`ETA_WINDOW` (ends included)."""
    eta = np.asarray(eta)
    return (eta >= ETA_WINDOW[0]) & (eta <= ETA_WINDOW[1])


@dataclass(frozen=True)
class BenchConfig:
    """Everything that defines a bench; stored in its file."""

    n_per_material: int = 200
    seed: int = BENCH_SEED
    velocity_nm_per_s: float = 30.0
    temperature_K: float = 296.0
    ranges: ParameterRange = field(default_factory=lambda: ParameterRange(eta=ETA_WINDOW))
    substrate: SubstrateAugmentation = LAB_SUBSTRATE
    instrument: InstrumentEffects = LAB

    def to_json(self) -> str:
        return json.dumps(dataclasses.asdict(self), sort_keys=True)


def bench_if_missing(config: BenchConfig, path: str | os.PathLike) -> Path:
    """``path``, simulated with ``config`` first if it does not exist yet (a cache: an
    existing file is used as it is)."""
    path = Path(path)
    if not path.exists():
        make_bench(config, path)
    return path


def make_bench(config: BenchConfig, out: str | os.PathLike, progress: bool = True) -> Path:
    """Simulate the bench and write it as a dataset file (same layout as sweeps).

    Extra per-trace columns: ``material`` (index into :data:`MATERIALS`), the substrate
    draw, and the instrument draw (``white_nN``, ``pink_nN``, ``lowpass_px``,
    ``drift_nN``, ``softening``).
    """
    out = Path(out)
    physics = PhysicalSettings(
        velocity_nm_per_s=config.velocity_nm_per_s, temperature_K=config.temperature_K
    )
    names = list(MATERIALS)
    tables, forces = [], []
    for m, name in enumerate(tqdm(names, desc="bench", disable=not progress)):
        a = MATERIALS[name]
        seed = config.seed + 1000 * m
        n = config.n_per_material
        U0, K = sample_parameters(config.ranges, n, seed, a)
        sub = sample_substrate(config.substrate, n, seed, span_nm=physics.length_nm + 4.0)
        res = simulate(
            U0, K, physics, seed=seed, lattice_nm=np.full(n, a),
            modulation=sub.modulation(), defects=sub.defects(),
        )  # fmt: skip
        rng = np.random.default_rng([seed, 77])
        noisy, drawn = apply_instrument(res.force_nN, config.instrument, rng)
        forces.append(noisy)
        tables.append(
            {
                "U0_eV": U0, "K_N_m": K, "eta": eta_from(U0, K, a),
                "F_mean_nN": res.force_nN.mean(axis=1), "lattice_nm": np.full(n, a),
                "velocity_nm_per_s": np.full(n, config.velocity_nm_per_s),
                "temperature_K": np.full(n, config.temperature_K),
                "material": np.full(n, m), "mod_amplitude": sub.mod_amplitude,
                "defect_count": np.count_nonzero(sub.defect_height, axis=1),
                **drawn,
            }
        )  # fmt: skip
    table = {k: np.concatenate([t[k] for t in tables]) for k in tables[0]}
    table["index"] = np.arange(table["U0_eV"].size)
    force = np.vstack(forces)
    x_nm = np.arange(physics.pixels) * physics.pixel_nm
    attrs = {
        "config": config.to_json(), "seed": config.seed, "stickslip_version": __version__,
        "n": force.shape[0], "pixels": physics.pixels, "kind": "lab-bench",
        "materials": json.dumps(names),
    }  # fmt: skip
    out.parent.mkdir(parents=True, exist_ok=True)
    part = out.with_name(out.name + ".partial")
    create_dataset_file(part, force.shape[0], x_nm, table, attrs)
    support = np.broadcast_to(x_nm, force.shape)
    write_rows(part, np.arange(force.shape[0]), force, support, {})
    os.replace(part, out)
    return out
