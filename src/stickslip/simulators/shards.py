"""Pieces of a sweep: the rows one kernel call or one Dask task simulates, and the cluster.

A sweep's rows are split into *shards* of consecutive rows (the chunks of a Zarr store,
the tasks of a Dask run, the unit of ``--resume`` there). Any set of rows simulates to
the same traces, bit for bit: each trajectory draws from its own stream derived from
``(seed, index)`` and its lane in a kernel block never depends on the other lanes. So a
sweep split over processes or machines equals the single-process run of its seed.

On a cluster the workers only simulate; the results come back to the process that runs
the sweep, which writes them. Workers need stickslip installed, no shared file system.
"""

from __future__ import annotations

import contextlib
import logging
import os
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from stickslip.simulators.config import PhysicalSettings
from stickslip.simulators.simulate import simulate

#: ``--dask local``: a cluster of worker processes on this machine.
LOCAL = "local"
DASK_NEEDED = "--dask needs dask and distributed: pip install 'stickslip[dask]'"
#: Module preloaded into local workers (they leave Ctrl-C to the client).
WORKER_SETUP = "stickslip.simulators.dask_worker"
#: Seconds to wait for a scheduler before giving up.
CONNECT_TIMEOUT_S = 10.0
# numba's default (workqueue) threading layer must not be entered by two threads at once
_KERNEL_LOCK = threading.Lock()


class ClusterError(RuntimeError):
    """The Dask cluster cannot be reached or a shard failed there; ``str()`` is one line."""


@dataclass(frozen=True)
class RowJob:
    """Everything needed to simulate some rows of a sweep (picklable, for workers).

    ``modulation`` and ``defects`` are the rows' substrate draws (None: plain substrate).
    """

    physics: PhysicalSettings
    seed: int
    rows: np.ndarray
    U0_eV: np.ndarray
    K_N_m: np.ndarray
    modulation: tuple[np.ndarray, np.ndarray, np.ndarray] | None
    defects: tuple[np.ndarray, np.ndarray, np.ndarray] | None
    backend: str = "cpu"


@dataclass(frozen=True)
class RowResult:
    """Simulated rows: forces and support positions (N, pixels), ``F_mean_nN``, ``dt_s``."""

    rows: np.ndarray
    force_nN: np.ndarray
    support_nm: np.ndarray
    F_mean_nN: np.ndarray
    dt_s: np.ndarray


def row_job(
    table: dict[str, np.ndarray],
    rows: np.ndarray,
    physics: PhysicalSettings,
    seed: int,
    *,
    modulated: bool,
    defects: bool,
    backend: str = "cpu",
) -> RowJob:
    """The job of ``rows`` of a sweep table (see :func:`stickslip.simulators.sweep.sweep_table`)."""
    rows = np.asarray(rows, dtype=np.int64)
    mod = tuple(table[k][rows] for k in ("mod_amplitude", "mod_wavelength_nm", "mod_phase_rad"))
    dfx = tuple(table[k][rows] for k in ("defect_x_nm", "defect_height_U0", "defect_width_nm"))
    return RowJob(
        physics=physics, seed=seed, rows=rows, U0_eV=table["U0_eV"][rows],
        K_N_m=table["K_N_m"][rows], modulation=mod if modulated else None,
        defects=dfx if defects else None, backend=backend,
    )  # fmt: skip


def simulate_job(job: RowJob) -> RowResult:
    """Simulate a job's rows in one kernel call (runs on Dask workers too)."""
    with _KERNEL_LOCK:
        res = simulate(
            job.U0_eV, job.K_N_m, job.physics, seed=job.seed, indices=job.rows,
            modulation=job.modulation, defects=job.defects, backend=job.backend,
        )  # fmt: skip
    return RowResult(
        rows=job.rows, force_nN=res.force_nN, support_nm=res.support_nm,
        F_mean_nN=res.force_nN.mean(axis=1), dt_s=res.dt_s,
    )  # fmt: skip


def shard_rows_for(n: int, shards: int | None, default_rows: int) -> int:
    """Rows per shard for ``shards`` shards of ``n`` rows (``default_rows`` if None)."""
    if shards is None:
        return max(1, min(default_rows, n))
    return max(1, -(-n // max(1, min(shards, n))))


def shard_bounds(n: int, shard_rows: int) -> list[tuple[int, int]]:
    """``[start, stop)`` of each shard of ``shard_rows`` consecutive rows."""
    return [(s, min(s + shard_rows, n)) for s in range(0, n, shard_rows)]


def local_workers() -> int:
    """Worker processes of ``--dask local``: one per core this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


@contextlib.contextmanager
def dask_client(address: str) -> Iterator[Any]:
    """A Dask client: ``"local"`` starts a :class:`distributed.LocalCluster` here (one
    single-threaded worker process per core, numba on one thread each, so the kernels
    of different shards run side by side); anything else is a scheduler address such as
    ``tcp://host:8786``. Cluster and client are closed on exit.

    Raises
    ------
    ClusterError
        If dask/distributed are missing or the scheduler cannot be reached.
    """
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise ClusterError(DASK_NEEDED) from None
    cluster = None
    try:
        if address == LOCAL:
            cluster = LocalCluster(
                n_workers=local_workers(), threads_per_worker=1, processes=True,
                dashboard_address=":0",  # any free port: 8787 may be taken
                silence_logs=logging.ERROR,  # cancelled tasks at Ctrl-C are expected
                env={"NUMBA_NUM_THREADS": "1"}, preload=[WORKER_SETUP],
            )  # fmt: skip
            client = Client(cluster)
        else:
            client = Client(address, timeout=CONNECT_TIMEOUT_S)
    except (OSError, ValueError) as e:  # TimeoutError is an OSError
        if cluster is not None:
            cluster.close()
        reason = " ".join(str(e).split())[:200]
        raise ClusterError(f"cannot reach the Dask scheduler at '{address}' ({reason})") from None
    try:
        yield client
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def run_jobs_on_dask(
    client: Any,
    jobs: Sequence[RowJob],
    on_result: Callable[[RowResult], None],
    stop: threading.Event,
    poll_s: float = 0.1,
) -> bool:
    """Run ``jobs`` on the cluster, handing each result to ``on_result`` as it arrives.

    Returns False if ``stop`` was set before every job was done (the rest are
    cancelled), True otherwise.

    Raises
    ------
    ClusterError
        If a job failed on the cluster (its one-line reason); finished jobs were handed on.
    """
    futures = {client.submit(simulate_job, job, pure=False): job for job in jobs}
    pending = set(futures)
    try:
        while pending:
            if stop.is_set():
                return False
            ready = [f for f in pending if f.done()]
            if not ready:
                time.sleep(poll_s)  # the wait is polled so that a stop request is seen
                continue
            for f in ready:
                pending.discard(f)
                try:
                    res = f.result()
                except Exception as e:
                    rows = futures[f].rows
                    reason = " ".join(f"{type(e).__name__}: {e}".split())[:200]
                    raise ClusterError(
                        f"rows {rows[0]}-{rows[-1]} failed on the cluster ({reason})"
                    ) from None
                on_result(res)
        return True
    finally:
        for f in pending:
            f.cancel()
