"""MATLAB ``.mat`` files: the file's named vectors read as the text reader's columns.

A recording saved from MATLAB holds named variables, not a fixed layout. The vectors
(numeric arrays with one dimension longer than 1) are read as named columns, with the
names and units of the CSV reader (:func:`~.text.traces_from_columns`): ``x_nm`` and
``force_nN`` (any length and force unit after the ``_``), ``trace``/``retrace``
friction loops, or a time axis (``t``, ``t_s``, ``time``, ``time_ms``; bare: seconds)
that the support's speed turns into positions (``--velocity``).

A signal stored without a unit (a force divided by ``m g``, a detector's raw reading)
is read where it is the only vector beside the axis: ``--calibration`` gives its nN
per unit, and without a calibration it is refused with that advice. Vectors of other
lengths, matrices and structs are left out.

Files up to version 7 are read with :func:`scipy.io.loadmat`; version 7.3 files are
HDF5 and are read with h5py. scipy's compiled reader of version 5-7 files crashes the
process (a segmentation fault) on a data element whose type code is not one of the
format's, as a damaged file can hold (scipy 1.17); so the element tags of such a file
are walked first (:func:`check_v5_tags`), and a file with a bad tag is refused in a
sentence instead.
"""

from __future__ import annotations

import io
import struct
import zlib
from pathlib import Path
from typing import Any

import numpy as np

from stickslip.traces.formats.common import FORMAT_NAMES, read_bytes
from stickslip.traces.formats.text import (
    AXES,
    POSITION,
    SIGNALS,
    column_kind,
    traces_from_columns,
)
from stickslip.traces.trace import Trace, TraceReadError

#: The text that opens a version 7.3 file's header (the rest of the file is HDF5).
MAT73 = b"MATLAB 7.3"
#: What ``inspect`` and the rows call the format.
FORMAT = FORMAT_NAMES[".mat"]
_NO_VECTOR = ("holds no vector of numbers: save the recording as vectors, e.g. x_nm and "
              "force_nN, or t and the force with its unit")


#: The data types of a version 5 element tag (miINT8 ... miUTF32; 8, 10, 11 are unused).
_MI_TYPES = frozenset({1, 2, 3, 4, 5, 6, 7, 9, 12, 13, 14, 15, 16, 17, 18})
_MI_MATRIX, _MI_COMPRESSED = 14, 15
#: The largest element a compressed one may inflate to (bytes): no real trace is larger.
_MAX_INFLATED = 1 << 31
_V5_HEADER = 128


def _walk_tags(buf: bytes, start: int, end: int, order: str, depth: int = 0) -> str | None:
    """The first problem with the element tags of ``buf[start:end]``, or None."""
    pos = start
    while pos + 8 <= end:
        word, size = struct.unpack_from(order + "II", buf, pos)
        if word >> 16:  # small data element: type and size packed in one word
            mdtype, size, body, step = word & 0xFFFF, word >> 16, pos + 4, 8
            if size > 4:
                return f"a small data element at byte {pos} claims {size} bytes"
        else:
            mdtype, body = word, pos + 8
            step = 8 + size + (-size % 8 if mdtype != _MI_COMPRESSED else 0)
        if mdtype not in _MI_TYPES:
            return f"an element at byte {pos} has the unknown data type {mdtype}"
        if body + size > end:
            return f"an element at byte {pos} runs past the end of its container"
        if mdtype == _MI_MATRIX and depth < 32:
            why = _walk_tags(buf, body, body + size, order, depth + 1)
            if why:
                return why
        elif mdtype == _MI_COMPRESSED:
            inflater = zlib.decompressobj()
            try:
                inner = inflater.decompress(buf[body:body + size], _MAX_INFLATED)
            except zlib.error as e:
                return f"a compressed element at byte {pos} does not inflate ({e})"
            why = _walk_tags(inner, 0, len(inner), order, depth + 1)
            if why:
                return why
        pos += step
    return None


def check_v5_tags(raw: bytes) -> str | None:
    """What is wrong with the element tags of a version 5-7 ``.mat`` file, or None.

    Walks every data element (into matrices and compressed elements) and checks that
    its data type is one the format defines and that it fits in its container, which
    is what scipy's compiled reader assumes without checking.
    """
    if len(raw) < _V5_HEADER:
        return None  # too short for a version 5 header: the reader says what it is
    order = {b"IM": "<", b"MI": ">"}.get(raw[126:128])
    if order is None:
        return None  # not version 5 (version 4 is read in Python)
    return _walk_tags(raw, _V5_HEADER, len(raw), order)


def _vector(value: Any) -> np.ndarray | None:
    """``value`` as a 1-D float array if it is a numeric vector of 2 or more values."""
    arr = np.asarray(value)
    if arr.dtype.kind not in "fiu" or arr.size < 2:
        return None
    arr = arr.squeeze()
    return arr.astype(float) if arr.ndim == 1 else None


def _v73_variables(path: Path) -> dict[str, Any]:
    import h5py

    out: dict[str, Any] = {}
    with h5py.File(path, "r") as h:
        for name, item in h.items():
            if isinstance(item, h5py.Dataset) and item.dtype.kind in "fiu":
                out[name] = item[()]
    return out


def mat_variables(path: Path) -> dict[str, np.ndarray]:
    """The numeric vectors of a ``.mat`` file, by name, in the file's order.

    A damaged file raises the parser's own exception, which the reader registry turns
    into one sentence (:func:`~.common.damage_reason`).
    """
    if read_bytes(path, 128).startswith(MAT73):
        raw = _v73_variables(path)
    else:
        from scipy.io import loadmat

        content = read_bytes(path)  # read once: walked here, then parsed from memory
        why = check_v5_tags(content)
        if why:
            raise TraceReadError(path, f"damaged MATLAB .mat file: {why}; write or export "
                                 "it again (a copy may have been cut short)")  # fmt: skip
        raw = loadmat(io.BytesIO(content))
    found = {str(k): _vector(v) for k, v in raw.items() if not str(k).startswith("__")}
    return {k: v for k, v in found.items() if v is not None}


def _is_axis(name: str) -> bool:
    return column_kind(name) in AXES


def read_mat(path: Path, **options: Any) -> list[Trace]:
    """Read the traces of a MATLAB ``.mat`` file (see the module docstring)."""
    vectors = mat_variables(path)
    if not vectors:
        raise TraceReadError(path, _NO_VECTOR)
    # the vectors of one length form the table; the length of the longest axis wins
    axes = [n for n in vectors if _is_axis(n)]
    length = max((vectors[n].size for n in axes), default=max(v.size for v in vectors.values()))
    names = [n for n, v in vectors.items() if v.size == length]
    data = np.column_stack([vectors[n] for n in names])
    signals = [n for n in names if not _is_axis(n)]
    named = any(column_kind(n) in SIGNALS for n in signals)
    if not named and len(signals) == 1 and any(_is_axis(n) for n in names):
        traces = [_unitless(path, names, data, signals[0], options)]
    else:
        traces = traces_from_columns(path, names, data, **options)
    for t in traces:
        t.meta["format"] = FORMAT
    return traces


def _unitless(path: Path, names: list[str], data: np.ndarray, signal: str,
              options: dict[str, Any]) -> Trace:  # fmt: skip
    """The one trace of a signal without a unit, in nN by ``--calibration``."""
    cal = options.get("calibration_nN_per_V")
    if cal is None:
        timed = not any(column_kind(n) == POSITION for n in names)
        speed = (" and the support's speed with --velocity (nm/s; the axis is time)"
                 if timed and options.get("velocity_nm_per_s") is None else "")
        raise TraceReadError(path, f"'{signal}' has no unit: pass --calibration with its "
                             f"nN per unit{speed}, or save it as force_nN (or force_N, ...)")
    j = names.index(signal)
    data = data.copy()
    data[:, j] *= cal
    header = [("force_nN" if n == signal else n) for n in names]
    trace = traces_from_columns(path, header, data, **options)[0]
    trace.meta["signal"] = f"{signal} x {cal:g} nN per unit (--calibration)"
    return trace
