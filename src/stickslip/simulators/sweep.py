"""Dataset generation: sample the training range, simulate in pieces, write HDF5 or Zarr.

Writes go to ``<out>.partial`` and are renamed onto ``<out>`` only when every row is
done, so an interrupted run never leaves a file that looks complete; ``resume=True``
continues the rows a partial file still lacks (its stored config must match). An
existing partial file is never replaced unless ``overwrite=True``.

The kernel is called on a few trajectories at a time (one block of lanes per thread),
so Ctrl-C stops the run within about one call: every finished row is kept and
:class:`SweepInterrupted` says how many. With ``dask`` the rows are simulated shard by
shard on a Dask cluster (:mod:`stickslip.simulators.shards`) and written here.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import signal
import threading
from collections.abc import Iterator
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

from stickslip._version import __version__
from stickslip.simulators.backends import resolve_backend
from stickslip.simulators.config import SweepConfig, warmup_nm_for
from stickslip.simulators.sampling import sample_parameters, sample_substrate
from stickslip.simulators.shards import (
    RowResult,
    dask_client,
    row_job,
    run_jobs_on_dask,
    shard_bounds,
    shard_rows_for,
    simulate_job,
)
from stickslip.traces.dataset import (
    PARTIAL_SUFFIX,
    ROW_CHUNK,
    DatasetError,
    check_output_path,
    create_dataset_file,
    finish_dataset,
    read_attrs,
    read_done,
    remove_dataset,
    write_rows,
)
from stickslip.units import eta_from

#: Kernel calls per window of consecutive rows sorted together by warm-up: rows of
#: similar warm-up share a call (lanes idle less), and a write touches few HDF5 chunks.
WINDOW_CALLS = 8


class PartialExistsError(DatasetError):
    """``<out>.partial`` exists and neither resume nor overwrite was asked for."""

    def __init__(self, partial: Path):
        self.partial = partial
        super().__init__(f"{partial}: an interrupted run is kept there")


class SweepInterrupted(Exception):
    """The sweep was stopped (Ctrl-C); its finished rows are kept in ``partial``."""

    def __init__(self, partial: Path, done: int, total: int):
        self.partial, self.done, self.total = partial, done, total
        super().__init__(
            f"interrupted: {done} of {total} trajectories kept in {partial} "
            "(resume=True continues it)"
        )


def partial_path(out: str | os.PathLike) -> Path:
    out = Path(out)
    return out.with_name(out.name + PARTIAL_SUFFIX)


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


#: Trajectories per GPU kernel call: enough threads to fill a large GPU.
GPU_CHUNK = 65536


def default_chunk(backend: str = "cpu") -> int:
    """Trajectories per kernel call: one block of lanes for each numba thread (CPU), or
    :data:`GPU_CHUNK` for a GPU backend (a few thousand threads cannot fill a GPU)."""
    if backend.startswith("cuda"):
        return GPU_CHUNK
    import numba

    from stickslip.simulators.kernel import LANES

    return LANES * numba.get_num_threads()


def local_pieces(pending: np.ndarray, warmup_nm: np.ndarray, chunk: int) -> list[np.ndarray]:
    """Rows of the kernel calls: windows of ``WINDOW_CALLS * chunk`` consecutive pending
    rows, each sorted by warm-up and cut into calls of ``chunk`` rows."""
    window = WINDOW_CALLS * chunk
    pieces = []
    for s in range(0, pending.size, window):
        rows = pending[s : s + window]
        rows = rows[np.argsort(warmup_nm[rows], kind="stable")]
        pieces += [rows[i : i + chunk] for i in range(0, rows.size, chunk)]
    return pieces


@contextlib.contextmanager
def stop_on_sigint() -> Iterator[threading.Event]:
    """An event that the first Ctrl-C sets instead of raising KeyboardInterrupt.

    The run checks it between kernel calls, so it stops with every finished row
    written; a second Ctrl-C raises KeyboardInterrupt as usual. Only in the main thread
    and only where SIGINT has Python's default handler.
    """
    stop = threading.Event()
    if (
        threading.current_thread() is not threading.main_thread()
        or signal.getsignal(signal.SIGINT) is not signal.default_int_handler
    ):
        yield stop
        return

    def handler(signum: int, frame: object) -> None:
        stop.set()
        signal.signal(signal.SIGINT, signal.default_int_handler)

    signal.signal(signal.SIGINT, handler)
    try:
        yield stop
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)


def run_sweep(
    config: SweepConfig,
    out: str | os.PathLike,
    *,
    resume: bool = False,
    overwrite: bool = False,
    chunk: int | None = None,
    progress: bool = True,
    dask: str | None = None,
    shards: int | None = None,
    backend: str | None = None,
) -> Path:
    """Simulate a whole sweep into ``out`` (HDF5, or a Zarr store for ``*.zarr``).

    Parameters
    ----------
    config : SweepConfig
        Physics, ranges, augmentation, size and seed; stored in the file.
    out : path-like
        Destination ``.h5`` file or ``.zarr`` store (its folder is created).
    resume : bool
        Continue ``<out>.partial`` if it exists (its config must match).
    overwrite : bool
        Discard an existing ``<out>.partial`` and start again.
    chunk : int, optional
        Trajectories per kernel call and per write when running here (default: 32 per
        numba thread, so Ctrl-C is answered within about one call).
    progress : bool
        Show a progress bar.
    dask : str, optional
        Run the shards on Dask: ``"local"`` (a cluster on this machine) or a scheduler
        address such as ``tcp://host:8786``.
    shards : int, optional
        Number of shards: the Dask tasks and the Zarr chunks (default: 64 trajectories
        each). A resumed Zarr store keeps its own shards.
    backend : str, optional
        Simulator backend (see :mod:`stickslip.simulators.backends`); default
        ``config.backend``. ``auto`` is decided here and the file records the backend
        used (see :class:`SweepConfig`); a partial file resumes only with the same one.

    Raises
    ------
    PartialExistsError
        If ``<out>.partial`` exists and neither ``resume`` nor ``overwrite`` is set.
    SweepInterrupted
        On Ctrl-C, once the finished rows are written to ``<out>.partial``.
    DatasetError
        If ``out`` cannot be written or the partial file cannot be resumed.
    ClusterError
        If the Dask cluster cannot be reached or a shard fails there.
    """
    if resume and overwrite:
        raise ValueError("resume and overwrite exclude each other")
    backend = resolve_backend(config.backend if backend is None else backend)
    config = dataclasses.replace(config, backend=backend)
    out = Path(out)
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise DatasetError(f"{out}: cannot create its folder ({e.strerror or e})") from None
    check_output_path(out)  # before any work: an unwritable out fails now, not at the end
    part = partial_path(out)
    ph = config.physics
    n = config.n
    table = sweep_table(config)
    attrs = {
        "config": config.to_json(),
        "seed": config.seed,
        "stickslip_version": __version__,
        "n": n,
        "pixels": ph.pixels,
    }
    shard_rows = shard_rows_for(n, shards, ROW_CHUNK)
    if part.exists() and not (resume or overwrite):
        raise PartialExistsError(part)
    with contextlib.ExitStack() as stack:
        # the cluster first: an unreachable scheduler must not leave a new partial file
        client = None if dask is None else stack.enter_context(dask_client(dask))
        if resume and part.exists():
            try:
                stored = read_attrs(part)
                done = read_done(part)
            except (OSError, DatasetError) as e:
                reason = f"cannot resume, partial file unreadable ({e})"
                raise DatasetError(f"{part}: {reason}") from None
            if stored.get("config") != attrs["config"]:
                reason = "cannot resume, it was started with different settings"
                raise DatasetError(f"{part}: {reason}")
            shard_rows = int(stored.get("shard_rows", shard_rows))
        else:
            remove_dataset(part)
            x_nm = np.arange(ph.pixels) * ph.pixel_nm
            create_dataset_file(part, n, x_nm, table, attrs, shard_rows=shard_rows)
            done = np.zeros(n, bool)
        aug = config.augmentation
        kinds = {"modulated": aug.modulation_amplitude[1] > 0,
                 "defects": aug.defects_per_line[1] > 0}  # fmt: skip

        def job(rows: np.ndarray):
            return row_job(table, rows, ph, config.seed, backend=backend, **kinds)

        bar = stack.enter_context(tqdm(
            total=n, initial=int(done.sum()), disable=not progress, unit="traj",
            desc=f"simulate {out.name}",
        ))  # fmt: skip
        stop = stack.enter_context(stop_on_sigint())

        def write(res: RowResult) -> None:
            extra = {"F_mean_nN": res.F_mean_nN, "dt_s": res.dt_s}
            write_rows(part, res.rows, res.force_nN, res.support_nm, extra)
            done[res.rows] = True
            bar.update(res.rows.size)

        if client is None:
            pending = np.flatnonzero(~done)
            pieces = local_pieces(pending, table["warmup_nm"], chunk or default_chunk(backend))
            for rows in pieces:
                if stop.is_set():
                    break
                write(simulate_job(job(rows)))
        else:
            jobs = []
            for lo, hi in shard_bounds(n, shard_rows):
                rows = lo + np.flatnonzero(~done[lo:hi])
                if rows.size:
                    jobs.append(job(rows))
            run_jobs_on_dask(client, jobs, write, stop)
    if not done.all():
        raise SweepInterrupted(part, int(done.sum()), n)
    return finish_dataset(part, out)
