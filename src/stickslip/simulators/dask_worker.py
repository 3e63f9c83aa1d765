"""Preloaded into the workers of ``--dask local`` (``distributed`` calls :func:`dask_setup`).

Ctrl-C in a terminal reaches every process of the foreground group, the local workers
included. The client stops the run and closes the cluster itself, so the workers ignore
SIGINT instead of dying with tracebacks over its one-line message.
"""

from __future__ import annotations

import signal
import threading
from typing import Any


def dask_setup(worker: Any) -> None:
    """Ignore SIGINT in this worker process (signals can be set only in the main thread)."""
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
