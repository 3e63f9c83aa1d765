"""Helpers for the compiled per-line kernels: chunks of lines on threads, whether
numba's on-disk cache already holds a kernel, and compiling kernels side by side in
worker processes before their first call.

A numba ``parallel=True`` loop over a per-line kernel compiles the whole call graph
again through its parallel-loop passes: the classical estimator's batch took 11 s of
its 48 s first compile that way, and the verdict's trace checks minutes. Their batch
kernels are serial instead, compiled with ``nogil=True``, and :func:`run_chunks` runs
them on chunks of lines on Python threads: the same parallelism, without that compile.

The first run after installing still compiles every kernel it meets, and numba compiles
one kernel after another in the process that calls them (about 40 s for ``stickslip
demo`` on a 2-core VM; a second run takes 4 s). :func:`cached` lets a command say so
before it starts, and :func:`compile_ahead` spreads that compilation over worker
processes, whose on-disk cache the command's own first calls then read.
"""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numba
import numpy as np

__all__ = ["cached", "chunk_bounds", "compile_ahead", "made_up_line", "run_chunks"]


def chunk_bounds(n: int, min_lines: int, threads: int | None = None) -> np.ndarray:
    """Bounds ``b`` of the chunks of ``n`` lines (chunk ``i`` is ``b[i]:b[i + 1]``).

    Parameters
    ----------
    n : int
        Lines.
    min_lines : int
        Fewest lines per chunk (below twice this, one chunk): a thread must have more
        to do than it costs to start.
    threads : int, optional
        Most chunks; default numba's thread count (``NUMBA_NUM_THREADS``).
    """
    threads = numba.get_num_threads() if threads is None else int(threads)
    chunks = max(1, min(threads, n // max(1, min_lines)))
    return np.linspace(0, n, chunks + 1).astype(int)


def run_chunks(kernel: Callable[..., Any], parts: Sequence[tuple]) -> None:
    """``kernel(*p)`` for every ``p`` in ``parts``, each on its own thread when there
    are several (``kernel`` must release the GIL: numba ``nogil=True``)."""
    if len(parts) == 1:
        kernel(*parts[0])
        return
    with ThreadPoolExecutor(len(parts)) as pool:
        list(pool.map(lambda p: kernel(*p), parts))


def cached(*kernels: Any) -> bool:
    """Whether numba's on-disk cache holds every one of ``kernels`` (numba dispatchers
    compiled with ``cache=True``): False where one has no index file yet, so that its
    first call compiles; False also for a kernel without an on-disk cache."""
    for kernel in kernels:
        # numba's cache keeps one index file per function, beside the source file's
        # __pycache__ or in its user-wide cache folder; not a public API, so anything
        # unexpected reads as "not cached"
        index = getattr(getattr(getattr(kernel, "_cache", None), "_cache_file", None),
                        "_index_path", None)  # fmt: skip
        if not isinstance(index, str) or not os.path.exists(index):
            return False
    return True


def made_up_line() -> tuple[np.ndarray, np.ndarray]:
    """A sawtooth line, ``x_nm`` and ``force_nN`` (256 samples over 5.1 nm), for a compile
    step of :func:`compile_ahead` to run its kernels on: its types matter, not its values."""
    x = np.arange(256) * 0.02
    return x, 40.0 * np.mod(x, 0.25)


#: What a worker process of :func:`compile_ahead` runs: one step, named on its command line.
_STEP = ("import importlib, sys; m, f = sys.argv[1].split(':'); "
         "getattr(importlib.import_module(m), f)()")


def compile_ahead(steps: Sequence[Callable[[], object] | str], processes: int | None = None,
                  timeout_s: float = 600.0) -> list[int]:  # fmt: skip
    """Run compile steps side by side in worker processes and wait for every one.

    A step is a module-level function without arguments (or its name,
    ``"package.module:function"``, which a worker imports) that calls kernels (numba
    dispatchers with ``cache=True``) on a small made-up input, through the same code
    that real inputs take, so that they compile for the same argument types and land in
    numba's on-disk cache. The caller's own first calls then read them from
    there instead of compiling them one after another. A step that fails or times out
    costs its time only: the caller compiles what it lacks on first call, as it would
    have without this.

    Parameters
    ----------
    steps : sequence of callable or str
        The steps, longest first (each takes the next free process).
    processes : int, optional
        Worker processes at once; default the CPU count.
    timeout_s : float
        Longest a step may run.

    Returns
    -------
    list of int
        Each step's exit status, in the order given (0: done; -1: timed out, or no
        worker could start).
    """
    workers = max(1, min(len(steps), processes or os.cpu_count() or 1))

    def run(step: Callable[[], object] | str) -> int:
        if callable(step):
            step = f"{step.__module__}:{step.__qualname__}"
        try:
            # quiet: a step's output or failure is no concern of the command's user
            return subprocess.run([sys.executable, "-c", _STEP, step], stdin=subprocess.DEVNULL,
                                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                  timeout=timeout_s, check=False).returncode  # fmt: skip
        except (OSError, subprocess.TimeoutExpired):
            return -1

    if not steps or not sys.executable:  # an embedded interpreter has no python to run
        return [-1] * len(steps)
    with ThreadPoolExecutor(workers) as pool:
        return list(pool.map(run, steps))
