"""Reader registry: file suffix -> reader returning a list of traces.

Every command reads through :func:`read_file`. Vendor formats register here too.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

from stickslip.data.trace import Trace, TraceReadError, read_trace_csv

Reader = Callable[..., list[Trace]]


def _read_csv(path: Path, **_: Any) -> list[Trace]:
    return [read_trace_csv(path)]


READERS: dict[str, Reader] = {".csv": _read_csv, ".txt": _read_csv}


def is_readable_suffix(path: Path) -> bool:
    """True if a reader is registered for the file's suffix."""
    return path.suffix.lower() in READERS


def read_file(path: str | os.PathLike, **options: Any) -> list[Trace]:
    """Read all traces a file holds, or raise :class:`TraceReadError` with one line."""
    p = Path(path)
    reader = READERS.get(p.suffix.lower())
    if reader is None:
        raise TraceReadError(p, f"unknown file format '{p.suffix or p.name}'")
    if not p.exists():
        raise TraceReadError(p, "file not found")
    try:
        return reader(p, **options)
    except TraceReadError:
        raise
    except Exception as e:  # a reader bug or a malformed file must never crash the batch
        raise TraceReadError(p, f"cannot read ({type(e).__name__}: {e})") from None
