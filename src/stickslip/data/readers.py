"""Reader registry: file suffix -> reader returning a list of traces.

Every command reads through :func:`read_file`. Vendor formats (friction maps) are
registered in :data:`SCAN_READERS`: they return a :class:`~.formats.ScanFile`, which
:func:`~.formats.maps.map_to_traces` turns into per-line traces; :func:`read_scan`
gives the scan itself (for ``stickslip inspect``). Bruker files also come with
numeric suffixes (``.000``, ``.001``...).
"""

from __future__ import annotations

import os
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

from stickslip.data.formats.asylum import read_ibw
from stickslip.data.formats.bruker import read_bruker
from stickslip.data.formats.common import ScanFile
from stickslip.data.formats.gwyddion import read_gwy
from stickslip.data.formats.hdf5 import read_h5
from stickslip.data.formats.maps import apply_load_schedule, map_to_traces
from stickslip.data.formats.nanosurf import read_nid
from stickslip.data.formats.text import read_npy, read_text
from stickslip.data.trace import Trace, TraceReadError

Reader = Callable[..., list[Trace]]
ScanReader = Callable[[Path], ScanFile]

SCAN_READERS: dict[str, ScanReader] = {
    ".spm": read_bruker,
    ".nid": read_nid,
    ".ibw": read_ibw,
    ".gwy": read_gwy,
}
READERS: dict[str, Reader] = {
    ".csv": read_text,
    ".txt": read_text,
    ".npy": read_npy,
    ".h5": read_h5,
    ".hdf5": read_h5,
}
_BRUKER_NUMBERED = re.compile(r"^\.\d{3}$")


def _suffix(path: Path) -> str:
    s = path.suffix.lower()
    return ".spm" if _BRUKER_NUMBERED.match(s) else s


def is_readable_suffix(path: Path) -> bool:
    """True if a reader is registered for the file's suffix."""
    s = _suffix(path)
    return s in READERS or s in SCAN_READERS


def is_scan_file(path: str | os.PathLike) -> bool:
    """True if the file is a vendor scan (friction map) format."""
    return _suffix(Path(path)) in SCAN_READERS


def _guarded(path: Path, fn: Callable[[], Any]) -> Any:
    try:
        return fn()
    except TraceReadError:
        raise
    except Exception as e:  # a reader bug or a malformed file must never crash the batch
        reason = " ".join(str(e).split())[:200]
        raise TraceReadError(path, f"cannot read ({type(e).__name__}: {reason})") from None


def _existing(path: str | os.PathLike) -> Path:
    p = Path(path)
    if not is_readable_suffix(p):
        raise TraceReadError(p, f"unknown file format '{p.suffix or p.name}'")
    if not p.exists():
        raise TraceReadError(p, "file not found")
    if p.is_dir():
        raise TraceReadError(p, "is a directory")
    return p


def read_scan(path: str | os.PathLike) -> ScanFile:
    """Read a vendor scan file's channels and metadata, or raise one-line TraceReadError."""
    p = _existing(path)
    reader = SCAN_READERS.get(_suffix(p))
    if reader is None:
        raise TraceReadError(p, "not a scan (image) format")
    return _guarded(p, lambda: reader(p))


def read_file(path: str | os.PathLike, **options: Any) -> list[Trace]:
    """Read all traces a file holds, or raise :class:`TraceReadError` with one line.

    ``options`` are the reader options of :func:`stickslip.data.formats.reader_options`.
    """
    p = _existing(path)
    s = _suffix(p)
    if s in SCAN_READERS:
        traces = _guarded(p, lambda: map_to_traces(SCAN_READERS[s](p), **options))
    else:
        traces = _guarded(p, lambda: READERS[s](p, **options))
    return apply_load_schedule(traces, p, **options)
