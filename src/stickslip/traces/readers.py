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
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

from stickslip.traces.formats.asylum import read_ibw
from stickslip.traces.formats.bruker import read_bruker
from stickslip.traces.formats.common import ScanFile, damage_reason
from stickslip.traces.formats.gwyddion import read_gwy
from stickslip.traces.formats.hdf5 import read_h5
from stickslip.traces.formats.jpk import read_jpk
from stickslip.traces.formats.maps import apply_load_schedule, map_to_traces
from stickslip.traces.formats.matlab import read_mat
from stickslip.traces.formats.mdt import read_mdt
from stickslip.traces.formats.nanosurf import read_nid
from stickslip.traces.formats.text import read_npy, read_text
from stickslip.traces.formats.zarr_store import read_zarr
from stickslip.traces.trace import Trace, TraceReadError

Reader = Callable[..., list[Trace]]
ScanReader = Callable[[Path], ScanFile]

SCAN_READERS: dict[str, ScanReader] = {
    ".spm": read_bruker,
    ".nid": read_nid,
    ".ibw": read_ibw,
    ".gwy": read_gwy,
    ".mdt": read_mdt,
    ".jpk": read_jpk,
}
READERS: dict[str, Reader] = {
    ".csv": read_text,
    ".txt": read_text,
    ".npy": read_npy,
    ".mat": read_mat,
    ".h5": read_h5,
    ".hdf5": read_h5,
    ".zarr": read_zarr,  # a folder: a Zarr store is one dataset, never expanded
}
_BRUKER_NUMBERED = re.compile(r"^\.\d{3}$")


def _suffix(path: Path) -> str:
    s = path.suffix.lower()
    return ".spm" if _BRUKER_NUMBERED.match(s) else s


def is_readable_suffix(path: Path) -> bool:
    """True if a reader is registered for the file's suffix."""
    s = _suffix(path)
    return s in READERS or s in SCAN_READERS


def readable_suffixes() -> str:
    """The suffixes a reader is registered for, as a user reads them."""
    return f"{', '.join(sorted({*READERS, *SCAN_READERS}))}, Bruker's .000-.999"


def is_dataset_dir(path: str | os.PathLike) -> bool:
    """True for a folder that is one dataset (a ``.zarr`` store), not a folder of traces."""
    p = Path(path)
    return p.suffix.lower() == ".zarr" and p.is_dir()


def is_scan_file(path: str | os.PathLike) -> bool:
    """True if the file is a vendor scan (friction map) format."""
    return _suffix(Path(path)) in SCAN_READERS


def _guarded(path: Path, fn: Callable[[], Any]) -> Any:
    try:
        return fn()
    except TraceReadError:
        raise
    except Exception as e:  # a reader bug or a malformed file must never crash the batch
        raise TraceReadError(path, damage_reason(e, path)) from None


def _existing(path: str | os.PathLike) -> Path:
    p = Path(path)
    # a path that is not there is that first, whatever its name (a mistyped folder has
    # no suffix, and "unknown file format" would send the user looking for a reader)
    if not p.exists():
        raise TraceReadError(p, "file not found")
    if not is_readable_suffix(p):
        raise TraceReadError(p, f"unknown file format '{p.suffix or p.name}' (readable: "
                                f"{readable_suffixes()})")  # fmt: skip
    if p.is_dir() and not is_dataset_dir(p):
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

    ``options`` are the reader options of :func:`stickslip.traces.formats.reader_options`.
    """
    p = _existing(path)
    s = _suffix(p)
    if s in SCAN_READERS:
        traces = _guarded(p, lambda: map_to_traces(SCAN_READERS[s](p), **options))
    else:
        traces = _guarded(p, lambda: READERS[s](p, **options))
    return apply_load_schedule(traces, p, **options)


def read_trace_csv(path: str | os.PathLike, calibration_nN_per_V: float | None = None) -> Trace:
    """Read a single-trace CSV: ``x_nm,force_nN``, or ``x_nm,force_V`` (volts).

    A force column in volts is multiplied by ``calibration_nN_per_V``; without it the
    trace stays in volts and its meta says ``unit="V"``, ``calibrated=False``.
    Other layouts (trace/retrace loops) hold several traces: read them with
    :func:`collect_traces`.

    Raises
    ------
    TraceReadError
        With a one-line reason if the file is missing, lacks the columns, holds
        non-numeric values or NaNs, has fewer than 16 samples, or x is not increasing.
    """
    p = Path(path)
    if p.is_dir():
        raise TraceReadError(p, "is a directory")
    if not p.exists():
        raise TraceReadError(p, "file not found")
    traces = read_text(p, calibration_nN_per_V=calibration_nN_per_V)
    if len(traces) != 1:
        raise TraceReadError(p, f"holds {len(traces)} traces; read it with collect_traces")
    return traces[0]


def expand_paths(paths: Iterable[str | os.PathLike]) -> tuple[list[Path], list[TraceReadError]]:
    """Expand folders into the trace files they hold (sorted); files are kept as given.

    A ``.zarr`` store is a dataset, kept as given (also inside an expanded folder).

    Returns the paths and one error per empty argument (``Path("")`` is the current
    folder, so an empty argument, an unset shell variable, would otherwise read every
    trace there, some of them twice) and per folder that holds no file of a readable
    format (it would otherwise vanish without a word).
    """
    out: list[Path] = []
    errors: list[TraceReadError] = []
    for raw in paths:
        if not str(raw).strip():
            errors.append(TraceReadError("''", "empty path"))
            continue
        p = Path(raw)
        if p.is_dir() and not is_dataset_dir(p):
            found = sorted(q for q in p.iterdir()
                           if (q.is_file() or is_dataset_dir(q)) and is_readable_suffix(q))
            if not found:
                errors.append(TraceReadError(p, "the folder holds no file of a readable "
                                                f"format ({readable_suffixes()})"))  # fmt: skip
            out.extend(found)
        else:
            out.append(p)
    return out, errors


def collect_traces(
    paths: Sequence[str | os.PathLike],
    progress: Callable[[int], None] | None = None,
    **options: Any,
) -> tuple[list[Trace], list[TraceReadError]]:
    """Read every trace from files and folders, never stopping at a bad file.

    Parameters
    ----------
    paths : sequence of path-like
        Trace files, vendor files or folders of them.
    progress : callable, optional
        Called with the number of files read so far, after each file.
    **options
        Passed to the format readers (e.g. ``calibration_nN_per_V``).

    Returns
    -------
    traces : list of Trace
        Every trace that could be read, in input order.
    errors : list of TraceReadError
        One per file that could not be read, each with a one-line reason.
    """
    traces: list[Trace] = []
    files, errors = expand_paths(paths)
    for k, p in enumerate(files, 1):
        try:
            traces.extend(read_file(p, **options))
        except TraceReadError as e:
            errors.append(e)
        if progress is not None:
            progress(k)
    return traces, errors
