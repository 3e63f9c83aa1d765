"""Shared pieces of the vendor readers: the in-memory scan, channel naming, units.

Every vendor reader turns a file into a :class:`ScanFile`: the images it holds
(:class:`Channel`, in the file's own units, rows = scan lines, columns = pixels in
increasing x) plus acquisition metadata. :mod:`stickslip.traces.formats.maps` turns
a :class:`ScanFile` into per-line :class:`~stickslip.traces.trace.Trace` objects.
"""

from __future__ import annotations

import importlib
import logging
import re
import struct
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from stickslip.traces.trace import TraceReadError

TRACE = "trace"
RETRACE = "retrace"

# Longest header, in bytes, that the text-header readers scan; real headers are < 100 kB.
MAX_HEADER_BYTES = 4_000_000

_LATERAL_WORDS = re.compile(r"friction|lateral|\blfm?\b|torsion", re.IGNORECASE)
_RETRACE_WORDS = re.compile(r"retrace|backward|\bbwd\b|\bback\b", re.IGNORECASE)
_TRACE_WORDS = re.compile(r"trace|forward|\bfwd\b", re.IGNORECASE)

# Scale factors of the force units to nN and of the voltage units to V.
_FORCE_TO_NN = {"N": 1e9, "mN": 1e6, "uN": 1e3, "µN": 1e3, "nN": 1.0, "pN": 1e-3}
_VOLT_TO_V = {"V": 1.0, "mV": 1e-3, "uV": 1e-6, "µV": 1e-6}
_TIME_TO_S = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6}
_LENGTH_TO_NM = {"m": 1e9, "mm": 1e6, "um": 1e3, "µm": 1e3, "~m": 1e3, "nm": 1.0, "pm": 1e-3,
                 "Å": 0.1, "A": 0.1}


@dataclass
class Channel:
    """One image channel of a scan.

    Attributes
    ----------
    name : str
        Channel name as the instrument writes it (e.g. ``"Friction"``).
    direction : str
        ``"trace"`` or ``"retrace"`` (``""`` if the file does not say).
    unit : str
        Unit of ``data`` as stored (``"V"``, ``"N"``, ``"m"`` ...).
    shape : tuple of int
        ``(lines, pixels)``.
    data : ndarray, shape (lines, pixels), or None
        Rows are scan lines in the stored order; columns run in increasing x for
        both directions (the display order every vendor uses). ``None`` for
        channels a reader lists but does not load (non-lateral ones).
    """

    name: str
    direction: str
    unit: str
    shape: tuple[int, int]
    data: np.ndarray | None = None

    @property
    def is_lateral(self) -> bool:
        """True if the name marks a lateral-force (friction) channel."""
        return is_lateral_name(self.name)


@dataclass
class Axis:
    """One axis of a stored data block (for ``inspect``).

    Attributes
    ----------
    name : str
        Axis name (``"x"``, ``"y"``, a spectroscopy variable ...).
    unit : str
        Unit of ``step`` as stored (``"um"``, ``"V"`` ...).
    size : int
        Number of points along the axis.
    step : float or None
        Spacing of the points in ``unit``, where the file states one.
    """

    name: str
    unit: str
    size: int
    step: float | None = None

    def describe(self) -> str:
        """One phrase: ``x 256 x 0.0117680 um``."""
        step = f" x {self.step:.6g}" if self.step is not None else ""
        unit = f" {self.unit}" if self.unit else ""
        return f"{self.name} {self.size}{step}{unit}"


@dataclass
class Frame:
    """One stored block of a multi-frame file (NT-MDT ``.mdt``), as ``inspect`` lists it.

    Attributes
    ----------
    index : int
        Position in the file, from 0.
    type_code : int
        The vendor's frame type number.
    kind : str
        What the type is (``"text"``, ``"MDA image"`` ...).
    title : str
        The frame's own title.
    shape : tuple of int
        Shape of the data (``(lines, pixels)`` for images); empty if it holds none.
    unit : str
        Unit of the data values.
    axes : list of Axis
        The data's axes (fast axis first).
    note : str
        Anything else worth one phrase (text content, what was not read).
    """

    index: int
    type_code: int
    kind: str
    title: str = ""
    shape: tuple[int, ...] = ()
    unit: str = ""
    axes: list[Axis] = field(default_factory=list)
    note: str = ""

    def describe(self) -> str:
        """One line: index, type, title, shape and unit, axes, note."""
        parts = [f"frame {self.index}: type {self.type_code} ({self.kind})"
                 + (f" '{self.title}'" if self.title else "")]
        if self.shape:
            parts.append("x".join(str(n) for n in self.shape)
                         + (f" {self.unit}" if self.unit else ""))
        if self.axes:
            parts.append("axes " + ", ".join(a.describe() for a in self.axes))
        if self.note:
            parts.append(self.note)
        return "; ".join(parts)


@dataclass
class ScanFile:
    """Everything a vendor reader extracts from one file.

    Attributes
    ----------
    path : Path
        The file.
    fmt : str
        Human-readable format name (``"Bruker NanoScope"``...).
    channels : list of Channel
        All image channels, lateral or not.
    scan_size_nm : float or None
        Length of a scan line in nm.
    meta : dict
        Acquisition metadata: ``scan_rate_hz``, ``velocity_nm_per_s``, ``load``,
        ``load_unit``, ``calibration_nN_per_V``, ``lattice_nm`` ... where known.
    frames : list of Frame
        For multi-frame formats (NT-MDT): every stored block, data or not.
    """

    path: Path
    fmt: str
    channels: list[Channel] = field(default_factory=list)
    scan_size_nm: float | None = None
    meta: dict[str, Any] = field(default_factory=dict)
    frames: list[Frame] = field(default_factory=list)

    def lateral(self) -> list[Channel]:
        """The lateral-force channels, in file order."""
        return [c for c in self.channels if c.is_lateral]


def is_lateral_name(name: str) -> bool:
    """True if a channel name denotes lateral force / friction."""
    return bool(_LATERAL_WORDS.search(name))


def direction_from_name(name: str) -> str:
    """``"retrace"``, ``"trace"`` or ``""`` from words in a channel name or title."""
    if _RETRACE_WORDS.search(name):
        return RETRACE
    if _TRACE_WORDS.search(name):
        return TRACE
    return ""


def base_name(name: str) -> str:
    """The channel name without its direction words (to pair trace with retrace)."""
    stripped = re.sub(r"[\s_\-:()\[\]]*(retrace|backward|forward|trace|fwd|bwd)[\s_\-:()\[\]]*",
                      " ", name, flags=re.IGNORECASE)
    return " ".join(stripped.split()) or name


def force_scale_to_nN(unit: str) -> float | None:
    """Factor from ``unit`` to nN, or ``None`` if ``unit`` is not a force unit."""
    return _FORCE_TO_NN.get(unit.strip())


def volt_scale_to_V(unit: str) -> float | None:
    """Factor from ``unit`` to V, or ``None`` if ``unit`` is not a voltage unit."""
    return _VOLT_TO_V.get(unit.strip())


def length_scale_to_nm(unit: str) -> float | None:
    """Factor from ``unit`` to nm, or ``None`` if ``unit`` is not a length unit."""
    return _LENGTH_TO_NM.get(unit.strip())


def time_scale_to_s(unit: str) -> float | None:
    """Factor from ``unit`` to s, or ``None`` if ``unit`` is not a time unit."""
    return _TIME_TO_S.get(unit.strip())


def length_to_nm(value: float, unit: str) -> float:
    """Convert a length to nm; raises ValueError for an unknown unit."""
    scale = length_scale_to_nm(unit)
    if scale is None:
        raise ValueError(f"unknown length unit '{unit}'")
    return float(value) * scale


def optional_import(module: str, path: Path, extra: str = "formats") -> ModuleType:
    """Import a third-party reader of an optional extra, or raise a one-line error."""
    try:
        return importlib.import_module(module)
    except ImportError:
        raise TraceReadError(
            path,
            f"reading {path.suffix or path.name} files needs the optional extra: "
            f"pip install 'stickslip[{extra}]'",
        ) from None


#: The format each suffix names, for the sentences of :func:`damage_reason`.
FORMAT_NAMES = {".spm": "Bruker NanoScope", ".nid": "Nanosurf NID", ".ibw": "Asylum/Igor IBW",
                ".gwy": "Gwyddion", ".mdt": "NT-MDT", ".jpk": "JPK image", ".csv": "CSV",
                ".txt": "text", ".npy": "NumPy .npy", ".h5": "HDF5", ".hdf5": "HDF5",
                ".zarr": "Zarr", ".mat": "MATLAB .mat"}  # fmt: skip
_RE_EXPORT = "re-export it from the instrument software (or open it there to check it)"
_WRITE_AGAIN = "write or export it again (a copy may have been cut short)"
#: Formats the project or a script writes (not an instrument): advice to write them again.
_WRITTEN = {".csv", ".txt", ".npy", ".h5", ".hdf5", ".zarr", ".mat"}


def damage_reason(error: BaseException, path: Path) -> str:
    """A sentence saying what an exception raised while reading a file means for the
    user, and what to try: never a bare exception name.

    A vendor file whose body is damaged makes its parser fail in many ways (a
    ``UnicodeDecodeError`` in a text header, a ``KeyError`` for a missing section, a
    ``struct.error`` or ``EOFError`` where the data end early ...); each kind becomes
    one plain sentence, the parser's own words kept short at the end as a detail.
    """
    suffix = path.suffix.lower()
    fmt = FORMAT_NAMES.get(".spm" if re.match(r"^\.\d{3}$", suffix) else suffix, "this format")
    detail = " ".join(str(error).split())[:120]
    if isinstance(error, UnicodeError):
        what = ("the file's body is damaged or not text where a text header was expected "
                f"(not a readable {fmt} file)")
    elif isinstance(error, KeyError):
        key = detail if len(detail) <= 40 else "entry"  # h5py puts whole sentences in keys
        what = (f"a part every {fmt} file has is missing (no {key}): the file is damaged, "
                "cut short, or from a version this reader does not know")
        detail = "" if key == detail else detail
    elif isinstance(error, (EOFError, struct.error, IndexError, BufferError)) or (
            isinstance(error, ValueError) and "buffer" in detail.lower()):  # fmt: skip
        what = f"the file ends early or its {fmt} data layout is damaged"
    elif isinstance(error, (MemoryError, OverflowError)):
        what = f"the {fmt} header states sizes no real file has: the header is damaged"
        detail = ""
    elif isinstance(error, PermissionError):
        return "cannot be opened: permission denied; check the file's permissions"
    elif isinstance(error, OSError):
        what = f"cannot be read: the {fmt} file is damaged, cut short or not a file"
        detail = " ".join(str(error.strerror or error).split())[:120]
    else:
        what = (f"not a readable {fmt} file: it is damaged or not in the format its "
                "suffix says")
    advice = _WRITE_AGAIN if suffix in _WRITTEN else _RE_EXPORT
    return f"{what}; {advice}" + (f" (detail: {detail})" if detail else "")


@contextmanager
def quiet_logger(name: str) -> Iterator[None]:
    """Mute a third-party reader's logger while it reads (it logs damaged files to the
    terminal): the error reaches the user once, as the reader's one line."""
    log = logging.getLogger(name)
    was = log.disabled
    log.disabled = True
    try:
        yield
    finally:
        log.disabled = was


def read_bytes(path: Path, limit: int | None = None) -> bytes:
    """Read a file (or its first ``limit`` bytes) with one-line errors."""
    try:
        with open(path, "rb") as fh:
            return fh.read() if limit is None else fh.read(limit)
    except IsADirectoryError:
        raise TraceReadError(path, "is a directory") from None
    except OSError as e:
        raise TraceReadError(path, damage_reason(e, path)) from None


def as_image(data: Any, path: Path, what: str) -> np.ndarray:
    """A finite float 2-D array, or a one-line error naming ``what``."""
    arr = np.asarray(data, dtype=float)
    if arr.ndim != 2 or min(arr.shape) < 1:
        raise TraceReadError(path, f"{what} is not a 2-D image (shape {arr.shape})")
    return arr
