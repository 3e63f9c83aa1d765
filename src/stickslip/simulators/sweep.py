"""Dataset generation: sample the training range, simulate in chunks, write chunked HDF5.

Writes go to ``<out>.partial`` and are renamed onto ``<out>`` only when every row is
done, so an interrupted run never leaves a file that looks complete; ``resume=True``
continues the rows a partial file still lacks (its stored config must match).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

from stickslip._version import __version__
from stickslip.simulators.config import SweepConfig, warmup_nm_for
from stickslip.simulators.sampling import sample_parameters, sample_substrate
from stickslip.simulators.simulate import simulate
from stickslip.traces.dataset import (
    DatasetError,
    create_dataset_file,
    read_attrs,
    read_done,
    write_rows,
)
from stickslip.units import eta_from


def partial_path(out: str | os.PathLike) -> Path:
    out = Path(out)
    return out.with_name(out.name + ".partial")


def sweep_table(config: SweepConfig) -> dict[str, np.ndarray]:
    """The per-trajectory parameter table of a sweep (everything but results)."""
    ph = config.physics
    U0, K = sample_parameters(config.ranges, config.n, config.seed, ph.lattice_nm)
    n = config.n
    warm = warmup_nm_for(U0, K, np.full(n, ph.lattice_nm), ph.warmup_nm)
    span = float(warm.max() + ph.length_nm + 1.0)
    sub = sample_substrate(config.augmentation, n, config.seed, span)
    table = {
        "index": np.arange(n),
        "U0_eV": U0,
        "K_N_m": K,
        "eta": eta_from(U0, K, ph.lattice_nm),
        "F_mean_nN": np.full(n, np.nan),
        "lattice_nm": np.full(n, ph.lattice_nm),
        "velocity_nm_per_s": np.full(n, ph.velocity_nm_per_s),
        "temperature_K": np.full(n, ph.temperature_K),
        "damping_per_s": np.full(n, ph.damping_per_s),
        "mass_kg": np.full(n, ph.mass_kg),
        "dt_s": np.full(n, np.nan),
        "warmup_nm": warm,
    }
    table.update(
        {
            "mod_amplitude": sub.mod_amplitude,
            "mod_wavelength_nm": sub.mod_wavelength_nm,
            "mod_phase_rad": sub.mod_phase_rad,
            "defect_x_nm": sub.defect_x_nm,
            "defect_height_U0": sub.defect_height,
            "defect_width_nm": sub.defect_width_nm,
        }
    )
    return table


def run_sweep(
    config: SweepConfig,
    out: str | os.PathLike,
    *,
    resume: bool = False,
    chunk: int = 256,
    progress: bool = True,
) -> Path:
    """Simulate a whole sweep into ``out`` (HDF5); returns the final path.

    Parameters
    ----------
    config : SweepConfig
        Physics, ranges, augmentation, size and seed; stored in the file.
    out : path-like
        Destination ``.h5`` file.
    resume : bool
        Continue ``<out>.partial`` if it exists (its config must match).
    chunk : int
        Trajectories per simulation call and per write.
    progress : bool
        Show a progress bar.
    """
    out = Path(out)
    part = partial_path(out)
    ph = config.physics
    table = sweep_table(config)
    attrs = {
        "config": config.to_json(),
        "seed": config.seed,
        "stickslip_version": __version__,
        "n": config.n,
        "pixels": ph.pixels,
    }
    if resume and part.exists():
        try:
            stored = read_attrs(part).get("config")
            done = read_done(part)
        except OSError as e:
            raise DatasetError(f"{part}: cannot resume, partial file unreadable ({e})") from None
        if stored != attrs["config"]:
            raise DatasetError(f"{part}: cannot resume, it was started with different settings")
    else:
        out.parent.mkdir(parents=True, exist_ok=True)
        x_nm = np.arange(ph.pixels) * ph.pixel_nm
        create_dataset_file(part, config.n, x_nm, table, attrs)
        done = np.zeros(config.n, bool)
    starts = [s for s in range(0, config.n, chunk) if not done[s : s + chunk].all()]
    mod = config.augmentation.modulation_amplitude[1] > 0
    dfx = config.augmentation.defects_per_line[1] > 0
    with tqdm(
        total=config.n, initial=int(done.sum()), disable=not progress, unit="traj",
        desc=f"simulate {out.name}",
    ) as bar:  # fmt: skip
        for s in starts:
            rows = np.arange(s, min(s + chunk, config.n))
            res = simulate(
                table["U0_eV"][rows], table["K_N_m"][rows], ph, seed=config.seed, indices=rows,
                modulation=(
                    table["mod_amplitude"][rows], table["mod_wavelength_nm"][rows],
                    table["mod_phase_rad"][rows],
                ) if mod else None,
                defects=(
                    table["defect_x_nm"][rows], table["defect_height_U0"][rows],
                    table["defect_width_nm"][rows],
                ) if dfx else None,
            )  # fmt: skip
            write_rows(
                part, rows, res.force_nN, res.support_nm,
                {"F_mean_nN": res.force_nN.mean(axis=1), "dt_s": res.dt_s},
            )  # fmt: skip
            bar.update(rows.size)
    os.replace(part, out)
    return out
