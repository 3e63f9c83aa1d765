"""Plain-text and NumPy traces: column layouts, volts with calibration, friction loops.

Recognised column layouts (header names, any order; comma, tab, semicolon or
whitespace separated; ``#`` lines are comments):

- ``x_nm,force_nN``: one trace in nN (the project's own format). The unit is the part of
  the name after ``_``: any length unit for ``x`` (``x_pm``, ``x_A``, ``x_um``, ``x_mm``,
  ``x_m``) and any force unit for the force (``force_pN``, ``force_uN``, ``force_N``)
  are converted to nm and nN.
- ``t_s,force_nN`` (or ``t``, ``time``, ``time_ms``, ...; bare: seconds): one trace
  recorded against time, as macroscopic rigs log it; with the support's speed
  (``velocity_nm_per_s``, ``--velocity``) the positions are ``x = v (t - t_0)``. Without
  it the file is refused: time alone does not give the stick slope in N/m.
- ``x_nm,force_V`` (or ``force_mV``): one trace in volts; converted with
  ``calibration_nN_per_V``, else kept in volts and flagged (``meta["unit"] == "V"``,
  ``calibrated=False``).
- ``trace,retrace`` (volts; or with a unit, ``trace_V,retrace_V``,
  ``trace_nN,retrace_nN``), optionally with an ``x`` column or ``index``: one friction
  loop, read as one scan line (trace, retrace reversed and sign-flipped, see
  :mod:`.maps`).
- No header, three numeric columns ``index, trace, retrace`` in volts (the layout
  of exported friction profiles such as ``exampleFrictionProfileFull.txt``).

``.npy``: a structured array with the same field names; a plain ``(n, 2)`` array
``x_nm, force_nN``; or a 1-D array of forces in nN (positions from ``scan_size_nm``,
else pixel indices, ``meta["x_unit"] == "px"``: no estimator reads them as nm). The same
for a one-column ``force_nN`` file.
"""

from __future__ import annotations

import csv
import io
import re
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from stickslip.traces.formats.common import (
    RETRACE,
    TRACE,
    Channel,
    ScanFile,
    force_scale_to_nN,
    length_scale_to_nm,
    read_bytes,
    time_scale_to_s,
    volt_scale_to_V,
)
from stickslip.traces.formats.maps import map_to_traces, to_force
from stickslip.traces.trace import READ_NOTE, Trace, TraceReadError, validate_trace

NEEDED = ("needs columns x_nm,force_nN (any length unit for x: pm, A, nm, um, mm, m, or a time "
          "axis t_s with --velocity; any force or voltage unit for the force: pN, nN, uN, mN, "
          "N, V, mV), or trace,retrace")
FORMAT_LOOP = "friction loop (text)"


#: The name of a position column (``x_<length unit>``).
POSITION = "x"
#: The names of a time axis (``t_<time unit>``, ``time_<time unit>``; bare: seconds).
TIME_AXES = ("t", "time")
#: Every axis name: a column so named is where the samples are, not a signal.
AXES = (POSITION, *TIME_AXES)
#: The names of the signal columns (``<name>_<force or voltage unit>``).
SIGNALS = ("force", "trace", "retrace")


def column_kind(name: str) -> str:
    """What a column name says before its unit: ``x_nm`` -> ``x``, ``time`` -> ``time``."""
    return name.partition("_")[0]


def _unit_columns(header: Sequence[str], prefix: str, bare: bool = False) -> tuple[str, ...]:
    """The columns named ``<prefix>_<unit>`` whose unit this reader converts (lengths for
    the position, times for a time axis, forces or voltages for a signal), and the bare
    ``<prefix>`` where allowed (a signal in volts, a time axis in seconds)."""
    found = []
    for h in header:
        name, _, unit = h.partition("_")
        if name != prefix or (not unit and not bare):
            continue
        if not unit or (prefix == POSITION and length_scale_to_nm(unit)) or (
                prefix in TIME_AXES and time_scale_to_s(unit)) or (
                prefix not in AXES and (force_scale_to_nN(unit)
                                        or volt_scale_to_V(unit))):  # fmt: skip
            found.append(h)
    return tuple(found)


def _time_positions(path: Path, name: str, t: np.ndarray, options: dict[str, Any]
                    ) -> np.ndarray:  # fmt: skip
    """Positions ``x = v (t - t_0)`` (nm) of a time axis ``name`` with the support's speed
    from ``options``; a one-line refusal without it."""
    v = options.get("velocity_nm_per_s")
    if v is None:
        raise TraceReadError(path, f"the positions are a time axis ('{name}'): pass the "
                             "support's speed with --velocity (nm/s) to read them as x = v t")
    unit = name.partition("_")[2] or "s"
    return (t - t[0]) * time_scale_to_s(unit) * v


_SEPARATORS = {";": "semicolon", "\t": "tab", ",": "comma", None: "whitespace"}
#: A number written with a decimal comma (``0,1234``, ``-1,5e-3``): European-locale
#: spreadsheets export these, with ``;`` (or tab) between the columns.
_DECIMAL_COMMA = re.compile(r"^[+-]?(\d+,\d*|,\d+)([eE][+-]?\d+)?$")


def _separator(line: str) -> str | None:
    """The column separator a line uses: ``;`` first (it is never part of a number, and a
    line with decimal commas holds commas too), then tab, then comma; None: whitespace."""
    return next((sep for sep in (";", "\t", ",") if sep in line), None)


def _split(line: str, sep: str | None) -> list[str]:
    if sep is None or sep not in line:  # a line without the file's separator: its own
        sep = _separator(line)
    if sep is None:
        return line.split()
    return next(csv.reader(io.StringIO(line), delimiter=sep))


def read_rows(path: Path) -> tuple[list[list[str]], str]:
    """Non-empty, non-comment rows of a delimited text file, with one-line errors.

    The separator is the first row's (:func:`_separator`). In a file not separated by
    commas, numbers with a decimal comma (``0,1234``) are read as decimals. Returns
    the rows and a note saying so (``""`` for a file in the usual layout).
    """
    raw = read_bytes(path)
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise TraceReadError(path, "not a text file (it holds bytes that are not UTF-8 "
                             "text): export the trace as CSV") from None
    if "\x00" in text:
        raise TraceReadError(path, "not a text file (it holds binary zero bytes): export "
                             "the trace as CSV")
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise TraceReadError(path, "empty file (no rows besides comments): nothing to read")
    sep = _separator(lines[0])
    rows = [[c.strip() for c in _split(ln, sep)] for ln in lines]
    rows = [r for r in rows if any(r)]
    if not rows:
        raise TraceReadError(path, "empty file (no rows besides comments): nothing to read")
    note = ""
    if sep != "," and any(_DECIMAL_COMMA.match(c) for r in rows for c in r):
        rows = [[c.replace(",", ".") if _DECIMAL_COMMA.match(c) else c for c in r] for r in rows]
        note = f"read as {_SEPARATORS[sep]}-separated with decimal commas"
    return rows, note


def _is_number(s: str) -> bool:
    try:
        float(s)
    except ValueError:
        return False
    return True


def _numbers(rows: Sequence[Sequence[str]], ncol: int, path: Path) -> np.ndarray:
    short = next((i for i, r in enumerate(rows) if len(r) < ncol), None)
    if short is not None:
        raise TraceReadError(path, f"missing value: data row {short + 1} is shorter than the "
                             f"header ({len(rows[short])} of {ncol} columns)")
    bad = next(((i, j, v) for i, r in enumerate(rows) for j, v in enumerate(r[:ncol])
                if not _is_number(v)), None)  # fmt: skip
    if bad is not None:
        i, j, v = bad
        raise TraceReadError(
            path, f"non-numeric value {v[:40]!r} in data row {i + 1}, column {j + 1}: every "
            "value below the header must be a number (decimal point, or decimal comma with "
            "';' between the columns)")
    return np.array([[float(v) for v in r[:ncol]] for r in rows], dtype=float).reshape(-1, ncol)


def read_text(path: Path, **options: Any) -> list[Trace]:
    """Read the traces of a CSV/TXT file in any recognised layout."""
    rows, note = read_rows(path)
    traces = _text_traces(path, rows, **options)
    if note:  # said once per file by the run (stickslip.traces.trace.read_notes)
        for t in traces:
            t.meta[READ_NOTE] = note
    return traces


def _text_traces(path: Path, rows: list[list[str]], **options: Any) -> list[Trace]:
    if all(_is_number(c) for c in rows[0]):
        if len(rows[0]) < 3:
            raise TraceReadError(
                path, f"no header: {len(rows[0])} column(s) of numbers, no x axis or unit "
                "named; add a header x_nm,force_nN (or x_nm,force_V), or give 3 columns "
                "index,trace,retrace")
        if len(rows[0]) != 3:
            raise TraceReadError(
                path, f"{NEEDED}; a file without header must have 3 columns index,trace,retrace"
            )
        data = _numbers(rows, 3, path)
        return traces_from_columns(path, ["index", "trace", "retrace"], data, **options)
    header = rows[0]
    return traces_from_columns(path, header, _numbers(rows[1:], len(header), path), **options)


def _unit_of(name: str) -> str:
    return name.split("_", 1)[1] if "_" in name else "V"


def _one(header: Sequence[str], choices: Sequence[str], path: Path, what: str) -> str | None:
    found = [c for c in choices if c in header]
    if len(found) > 1:
        raise TraceReadError(path, f"mixed units: several {what} columns ({', '.join(found)})")
    return found[0] if found else None


def traces_from_columns(
    path: Path, header: Sequence[str], data: np.ndarray, **options: Any
) -> list[Trace]:
    """Traces from named numeric columns (``data`` has one column per header name).

    Raises
    ------
    TraceReadError
        If no layout matches (the reason names the needed columns), on mixed units,
        or if the values do not form a valid trace.
    """
    header = [h.strip() for h in header]
    xcol = _one(header, _unit_columns(header, POSITION), path, "position")
    times = tuple(c for axis in TIME_AXES for c in _unit_columns(header, axis, bare=True))
    tcol_time = None if xcol else _one(header, times, path, "time")
    fcol = _one(header, _unit_columns(header, "force"), path, "force")
    tcol = _one(header, _unit_columns(header, "trace", bare=True), path, "trace")
    rcol = _one(header, _unit_columns(header, "retrace", bare=True), path, "retrace")
    col = {h: data[:, i] for i, h in enumerate(header)}
    x = col[xcol] * length_scale_to_nm(_unit_of(xcol)) if xcol else None
    if tcol_time is not None:
        x = _time_positions(path, tcol_time, col[tcol_time], options)
    if fcol and (tcol or rcol):
        raise TraceReadError(path, "ambiguous layout: both force and trace/retrace columns")
    if tcol and rcol:
        if _unit_of(tcol) != _unit_of(rcol):
            raise TraceReadError(path, f"mixed units: {tcol} and {rcol}")
        return _loop_traces(path, col[tcol], col[rcol], _unit_of(tcol), x, **options)
    if fcol and (x is not None or len(header) == 1):
        pixels = x is None and not options.get("scan_size_nm")
        x = _positions(data.shape[0], options) if x is None else x
        trace = _single_trace(path, x, col[fcol], _unit_of(fcol), options, pixels)
        if tcol_time is not None:  # the speed that made the positions is the line's
            trace.meta["velocity_nm_per_s"] = options["velocity_nm_per_s"]
        return [trace]
    raise TraceReadError(path, f"{NEEDED} (found {','.join(header)})")


def _positions(n: int, options: dict[str, Any]) -> np.ndarray:
    size = options.get("scan_size_nm")
    return np.arange(n, dtype=float) * (size / n if size else 1.0)


def _single_trace(
    path: Path, x: np.ndarray, f: np.ndarray, unit: str, options: dict[str, Any],
    pixels: bool = False,
) -> Trace:
    """One trace; ``pixels``: ``x`` holds pixel indices (no x axis in the file), which
    ``meta["x_unit"] == "px"`` says (no estimator reads such a trace as nm)."""
    force, out_unit, calibrated = to_force(f, unit, options.get("calibration_nN_per_V"))
    x, force = np.ascontiguousarray(x, dtype=float), np.ascontiguousarray(force, dtype=float)
    validate_trace(x, force, str(path))
    meta = {"file": str(path), "unit": out_unit, "calibrated": calibrated}
    if pixels:
        meta["x_unit"] = "px"
    return Trace(x_nm=x, force_nN=force, name=path.stem, source=str(path), meta=meta)


def _loop_traces(
    path: Path,
    trace: np.ndarray,
    retrace: np.ndarray,
    unit: str,
    x: np.ndarray | None,
    **options: Any,
) -> list[Trace]:
    n = trace.size
    size = None
    if x is not None:
        dx = np.diff(x)
        if n < 2 or np.any(dx <= 0) or not np.all(np.isfinite(x)):
            raise TraceReadError(path, "x_nm is not strictly increasing")
        size = float(np.median(dx) * n)
    scan = ScanFile(path=path, fmt=FORMAT_LOOP, scan_size_nm=size)
    for direction, values in ((TRACE, trace), (RETRACE, retrace)):
        scan.channels.append(Channel("Friction", direction, unit, (1, n), values[None, :].copy()))
    traces = map_to_traces(scan, **options)
    for t in traces:
        validate_trace(t.x_nm, t.force_nN, str(path))
    return traces


def read_npy(path: Path, **options: Any) -> list[Trace]:
    """Read a ``.npy`` trace (structured, ``(n, 2)`` or 1-D; see the module docstring)."""
    head = read_bytes(path, 6)
    if head != b"\x93NUMPY":
        raise TraceReadError(path, "not a NumPy .npy file (bad magic)")
    try:
        with warnings.catch_warnings():
            # a header written the Python 2 way still reads; numpy's advice to save the
            # file again is not the user's concern here
            warnings.filterwarnings("ignore", message="Reading `.npy` or `.npz` file required",
                                    category=UserWarning)  # fmt: skip
            # numpy parses the header as a Python literal: a damaged one can warn of an
            # escape sequence before it fails (or reads), which the user has no use for
            warnings.simplefilter("ignore", DeprecationWarning)
            warnings.simplefilter("ignore", SyntaxWarning)
            arr = np.load(path, allow_pickle=False)
    except (ValueError, OSError, EOFError) as e:
        raise TraceReadError(path, f"damaged .npy file ({e})") from None
    if arr.dtype.names:
        names = list(arr.dtype.names)
        data = np.column_stack([np.asarray(arr[n], dtype=float).ravel() for n in names])
        return traces_from_columns(path, names, data, **options)
    if arr.dtype.kind not in "fiu":
        raise TraceReadError(path, f"array of {arr.dtype} is not numeric")
    if arr.ndim == 1:
        return traces_from_columns(path, ["force_nN"], arr.astype(float)[:, None], **options)
    if arr.ndim == 2 and arr.shape[1] == 2:
        return traces_from_columns(path, ["x_nm", "force_nN"], arr.astype(float), **options)
    raise TraceReadError(
        path, f"array of shape {arr.shape}: expected (n,) forces or (n, 2) x_nm, force_nN"
    )
