"""``stickslip simulate``: one trace as CSV, or a whole training sweep as HDF5."""

from __future__ import annotations

import shlex
import sys
from pathlib import Path

import numpy as np
import typer

from stickslip.cli.app import app
from stickslip.cli.common import error, info, usage_error
from stickslip.traces.dataset import DatasetError, check_output_path
from stickslip.traces.trace import write_trace_csv


def _range(text: str | None, name: str) -> tuple[float, float] | None:
    if text is None:
        return None
    try:
        lo, hi = (float(v) for v in text.split(","))
    except ValueError:
        usage_error(f"--{name} must be two numbers 'LOW,HIGH' (got '{text}')")
    if not lo <= hi:
        usage_error(f"--{name} must have LOW <= HIGH (got '{text}')")
    return lo, hi


@app.command("simulate")
def simulate_cmd(
    out: Path = typer.Option(
        ..., "--out", "-o", help="Output: .csv for one trace, .h5 or .zarr for a sweep."
    ),
    u0: float | None = typer.Option(None, "--u0", help="Barrier U0 in eV (single trace)."),
    k: float | None = typer.Option(None, "--k", help="Contact stiffness K in N/m (single trace)."),
    preset: str = typer.Option("paper", "--preset", help="Physical preset: paper, mos2, ws2."),
    n: int = typer.Option(1600, "--n", help="Sweep: number of trajectories."),
    seed: int = typer.Option(0, "--seed", help="Random seed (traces depend only on seed, index)."),
    temperature: float | None = typer.Option(None, "--temperature", help="T in K."),
    velocity: float | None = typer.Option(None, "--velocity", help="Support velocity, nm/s."),
    mass: float | None = typer.Option(None, "--mass", help="Tip mass, kg."),
    damping: float | None = typer.Option(None, "--damping", help="Damping rate Gamma, 1/s."),
    lattice: float | None = typer.Option(None, "--lattice", help="Lattice spacing a, nm."),
    length: float | None = typer.Option(None, "--length", help="Recorded line length, nm."),
    pixels: int | None = typer.Option(None, "--pixels", help="Pixels per line."),
    dt: float | None = typer.Option(None, "--dt", help="Time step, s."),
    warmup: float | None = typer.Option(
        None, "--warmup", help="Warm-up travel, nm (default: max(1, F_max/K + 4a))."
    ),
    u0_range: str | None = typer.Option(None, "--u0-range", help="Sweep: U0 range 'LO,HI' eV."),
    k_range: str | None = typer.Option(None, "--k-range", help="Sweep: K range 'LO,HI' N/m."),
    eta_range: str | None = typer.Option(None, "--eta-range", help="Sweep: eta window 'LO,HI'."),
    modulation: float = typer.Option(
        0.0, "--modulation", help="Sweep: max barrier modulation amplitude (augmented substrate)."
    ),
    defects: int = typer.Option(0, "--defects", help="Sweep: max Gaussian defects per line."),
    fine: int = typer.Option(
        0, "--fine", help="Single trace: also write instantaneous tip/force, N per pixel."
    ),
    resume: bool = typer.Option(False, "--resume", help="Sweep: continue an interrupted run."),
    overwrite: bool = typer.Option(
        False, "--overwrite", help="Sweep: discard an interrupted run's <out>.partial, start again."
    ),
    chunk: int = typer.Option(
        0, "--chunk", help="Sweep: trajectories per kernel call and write (0: 32 per thread)."
    ),
    dask: str | None = typer.Option(
        None, "--dask", help="Sweep: run the shards on Dask: 'local' or a scheduler address "
        "(tcp://host:8786)."
    ),  # fmt: skip
    shards: int | None = typer.Option(
        None, "--shards", help="Sweep: number of shards (Dask tasks, Zarr chunks; default: 64 "
        "trajectories each)."
    ),  # fmt: skip
    progress: bool = typer.Option(True, "--progress/--no-progress", help="Progress bar."),
    backend: str = typer.Option(
        "cpu",
        "--backend",
        help="Simulator: cpu (default; same traces on every machine), cuda (NVIDIA GPU, "
        "pip install 'stickslip[gpu]'), cuda-float32, or auto (cuda if a GPU is present).",
    ),
) -> None:
    """Simulate finite-temperature Prandtl-Tomlinson friction traces (BAOAB integrator).

    With --u0 and --k: one trace, written as CSV 'x_nm,force_nN'. Otherwise: a sweep of
    --n trajectories over the training range (Latin hypercube in U0 and K, eta window
    enforced), written as chunked HDF5 or, for --out *.zarr, a Zarr store. Ctrl-C keeps
    the finished trajectories in <out>.partial and prints the command that continues it.
    """
    from stickslip.simulators import (
        PRESETS,
        ParameterRange,
        SettingsError,
        SubstrateAugmentation,
        SweepConfig,
        run_sweep,
        simulate,
    )
    from stickslip.simulators.shards import ClusterError
    from stickslip.simulators.sweep import PartialExistsError, SweepInterrupted

    if preset not in PRESETS:
        usage_error(f"unknown preset '{preset}' (have: {', '.join(PRESETS)})")
    from stickslip.simulators.backends import BACKEND_NAMES

    if backend not in BACKEND_NAMES:
        usage_error(f"unknown --backend '{backend}' (have: {', '.join(BACKEND_NAMES)})")
    try:
        physics = PRESETS[preset].replace(
            temperature_K=temperature, velocity_nm_per_s=velocity, mass_kg=mass,
            damping_per_s=damping, lattice_nm=lattice, length_nm=length, pixels=pixels,
            dt_s=dt, warmup_nm=warmup,
        )  # fmt: skip
        if (u0 is None) != (k is None):
            usage_error("give both --u0 and --k for a single trace, or neither for a sweep")
        check_output_path(out)  # now, not after the run
        if u0 is not None:
            if k <= 0:
                raise SettingsError(f"K must be > 0 N/m (got {k})")
            if u0 < 0:
                raise SettingsError(f"U0 must be >= 0 eV (got {u0})")
            res = simulate([u0], [k], physics, seed=seed, samples_per_pixel=max(fine, 0),
                           backend=backend)  # fmt: skip
            if not np.all(np.isfinite(res.force_nN)):
                error(f"{out}: not written: the simulated force is not finite (the time "
                      "step is too long for this barrier, spring and mass)")  # fmt: skip
                raise typer.Exit(1)
            write_trace_csv(out, res.x_nm, res.force_nN[0])
            if fine > 0:
                _write_fine(out, res)
            info(f"wrote {out} (eta = {res.eta[0]:.3g}, <F> = {res.force_nN[0].mean():.4g} nN)")
            return
        if n < 1:
            raise SettingsError(f"--n must be >= 1 (got {n})")
        base = ParameterRange()
        ranges = ParameterRange(
            U0_eV=_range(u0_range, "u0-range") or base.U0_eV,
            K_N_m=_range(k_range, "k-range") or base.K_N_m,
            eta=_range(eta_range, "eta-range") or base.eta,
        )
        ranges.check_feasible(physics.lattice_nm)
        aug = SubstrateAugmentation(
            modulation_amplitude=(0.0, modulation), defects_per_line=(0, max(defects, 0))
        )
        config = SweepConfig(
            physics=physics, ranges=ranges, augmentation=aug, n=n, seed=seed, preset=preset,
            backend=backend,
        )  # fmt: skip
        if resume and overwrite:
            usage_error("give --resume or --overwrite, not both")
        if shards is not None and shards < 1:
            usage_error(f"--shards must be >= 1 (got {shards})")
        path = run_sweep(
            config, out, resume=resume, overwrite=overwrite, chunk=max(chunk, 0) or None,
            progress=progress, dask=dask, shards=shards,
        )  # fmt: skip
        info(f"wrote {path} ({n} trajectories, {physics.pixels} pixels)")
    except SettingsError as e:
        usage_error(str(e))
    except PartialExistsError as e:
        usage_error(f"{e.partial}: an interrupted run is kept there; continue it with --resume "
                    "or start again with --overwrite")  # fmt: skip
    except SweepInterrupted as e:
        error(f"interrupted: {e.done} of {e.total} trajectories kept in {e.partial}; "
              f"continue with: {_resume_command()}")  # fmt: skip
        raise typer.Exit(130) from None
    except (DatasetError, ClusterError) as e:
        error(str(e))
        raise typer.Exit(1) from None


def _resume_command() -> str:
    """This command line with --resume (and without --overwrite): it continues the run."""
    args = [a for a in sys.argv[1:] if a != "--overwrite"]
    return shlex.join(["stickslip", *args, *([] if "--resume" in args else ["--resume"])])


def _write_fine(out: Path, res) -> None:
    """Diagnostics beside the trace: instantaneous support, tip position and force."""
    from stickslip.atomic import atomic_path

    fine_path = out.with_name(out.stem + ".fine.csv")
    data = np.column_stack([res.fine_support_nm[0], res.fine_x_nm[0], res.fine_force_nN[0]])
    with atomic_path(fine_path) as tmp:
        np.savetxt(tmp, data, delimiter=",", header="support_nm,tip_nm,force_nN", comments="",
                   fmt="%.9g")  # fmt: skip
    info(f"wrote {fine_path}")
