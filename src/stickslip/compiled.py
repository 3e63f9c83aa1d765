"""Helpers for the compiled per-line kernels: chunks of lines on threads, and whether
numba's on-disk cache already holds a kernel.

A numba ``parallel=True`` loop over a per-line kernel compiles the whole call graph
again through its parallel-loop passes: the classical estimator's batch took 11 s of
its 48 s first compile that way, and the verdict's trace checks minutes. Their batch
kernels are serial instead, compiled with ``nogil=True``, and :func:`run_chunks` runs
them on chunks of lines on Python threads: the same parallelism, without that compile.

The first run after installing still compiles every kernel it meets (about 50 s for
``stickslip demo`` on a 2-core VM; a second run takes 4 s): :func:`cached` lets a command
say so before it starts.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numba
import numpy as np

__all__ = ["cached", "chunk_bounds", "run_chunks"]


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
