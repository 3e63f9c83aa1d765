"""The line a benchmark prints first: the machine it ran on and when."""

from __future__ import annotations

import datetime as dt
import os
import platform


def cpu_model() -> str:
    """The CPU's model name (from /proc/cpuinfo where there is one)."""
    try:
        with open("/proc/cpuinfo") as f:
            return next(line.split(":", 1)[1].strip() for line in f if "model name" in line)
    except (OSError, StopIteration):
        return platform.processor() or platform.machine()


def machine_line() -> str:
    """CPU model, cores, OS, Python, the thread settings and the UTC time, in one line."""
    return (f"machine: {cpu_model()}, {os.cpu_count()} cores, "
            f"{platform.system()} {platform.machine()}, "
            f"python {platform.python_version()}, "
            f"NUMBA_NUM_THREADS={os.environ.get('NUMBA_NUM_THREADS')}, "
            f"OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS')}; "
            f"{dt.datetime.now(dt.timezone.utc):%Y-%m-%d %H:%M} UTC")  # fmt: skip
