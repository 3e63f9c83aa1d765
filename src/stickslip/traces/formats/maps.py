"""From friction maps to per-line traces; friction loops; load schedules.

Conventions (see docs/reference/formats.md):

- A lateral-force image with trace and retrace channels becomes one trace per scan
  line and direction. Vendors store both images with columns in increasing x; the
  retrace line is therefore reversed in x and sign-flipped, so that both read as
  friction in the scan direction (positive while sliding forward, as in PHYSICS.md).
- Positions: ``x_nm = i * scan_size_nm / pixels`` (from 0 at the first recorded
  pixel of the line, in the scan direction).
- Forces: a channel in newtons is converted to nN; a channel in volts is multiplied
  by the calibration factor (nN/V) passed as ``calibration_nN_per_V`` (the user's
  ``--calibration``), else the one stored in the file; without either it stays in volts
  and the trace's meta says ``unit="V"``, ``calibrated=False``. The factor used and its
  source (``flag`` or ``file``) are in ``meta["calibration_nN_per_V"]`` and
  ``meta["calibration_source"]``.
- Missing pixels (NaN or inf) are interpolated linearly along the line and counted in
  ``meta["masked_pixels"]`` (on every line of a map that has any); a line with more than
  :data:`MAX_NAN_FRACTION` of its pixels missing, or a gap longer than
  :data:`MAX_NAN_RUN` pixels, is kept with ``meta["unusable"]`` saying why, and no
  estimator reads it.
- Friction loop of a line: ``(trace - retrace) / 2`` (both in x order, raw sign),
  its mean is the friction, ``(trace + retrace) / 2`` the lateral offset.
- Lines are numbered in the order the file stores them (0-based).

Reader options
--------------
:func:`reader_options` builds the ``**options`` dict that commands pass to
:func:`stickslip.traces.collect_traces` (and so to every reader). Keys, all optional:

``calibration_nN_per_V`` (float > 0)
    Lateral calibration for channels in volts; it wins over one stored in the file.
``lines_per_load`` (int >= 1)
    Consecutive lines recorded at one load; sets ``meta["load_group"]`` and, with
    ``loads``, ``meta["load"]`` on every trace that has a ``line``.
``loads`` (list of float)
    Load (or setpoint) of each group of ``lines_per_load`` lines, in order.
``load_unit`` (str)
    Unit of ``loads`` (default ``"nN"``).
``scan_size_nm`` (float > 0)
    Line length for files that do not state it (text friction loops).
``directions`` (tuple of str)
    Which traces to emit per line, from ``"trace"``, ``"retrace"``, ``"loop"``
    (default trace and retrace).

Readers ignore options they do not use, so the same dict serves every format.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from stickslip.traces.formats.common import (
    RETRACE,
    TRACE,
    Channel,
    ScanFile,
    base_name,
    force_scale_to_nN,
    volt_scale_to_V,
)
from stickslip.traces.trace import Trace, TraceReadError

LOOP = "loop"
DIRECTIONS = (TRACE, RETRACE, LOOP)
DEFAULT_DIRECTIONS = (TRACE, RETRACE)
#: A line with more missing (NaN) pixels than this fraction is not estimated.
MAX_NAN_FRACTION = 0.25
#: Nor is a line with a longer run of missing pixels (interpolating over it would
#: invent a stick-slip cycle or more).
MAX_NAN_RUN = 4


def reader_options(
    calibration_nN_per_V: float | None = None,
    lines_per_load: int | None = None,
    loads: Sequence[float] | None = None,
    *,
    load_unit: str = "nN",
    scan_size_nm: float | None = None,
    directions: Sequence[str] | None = None,
    velocity_nm_per_s: float | None = None,
) -> dict[str, Any]:
    """Validate command-line reading options and return them as reader ``**options``.

    Parameters
    ----------
    calibration_nN_per_V : float, optional
        Lateral-force calibration in nN/V, used where the file stores none.
    lines_per_load : int, optional
        Number of consecutive scan lines recorded at one load.
    loads : sequence of float, optional
        Loads (or setpoints) of the successive line groups; needs ``lines_per_load``.
    load_unit : str
        Unit of ``loads``.
    scan_size_nm : float, optional
        Scan-line length for files that do not state it.
    directions : sequence of str, optional
        Subset of ``("trace", "retrace", "loop")`` to emit per line.
    velocity_nm_per_s : float, optional
        The support's speed, which turns a recording's time axis into positions
        (``x = v t``; :func:`stickslip.traces.formats.text.traces_from_columns`).

    Returns
    -------
    dict
        Only the options that were given (see the module docstring for the keys).

    Raises
    ------
    ValueError
        With a one-line message for an invalid combination or value.
    """
    opts: dict[str, Any] = {}
    if calibration_nN_per_V is not None:
        if not (math.isfinite(calibration_nN_per_V) and calibration_nN_per_V > 0):
            raise ValueError("calibration must be a positive number of nN per V")
        opts["calibration_nN_per_V"] = float(calibration_nN_per_V)
    if lines_per_load is not None:
        if lines_per_load < 1:
            raise ValueError("lines per load must be at least 1")
        opts["lines_per_load"] = int(lines_per_load)
    if loads:
        if lines_per_load is None:
            raise ValueError("loads need --lines-per-load (how many lines share one load)")
        if not all(math.isfinite(v) for v in loads):
            raise ValueError("loads must be finite numbers")
        opts["loads"] = [float(v) for v in loads]
        opts["load_unit"] = load_unit
    if scan_size_nm is not None:
        if not (math.isfinite(scan_size_nm) and scan_size_nm > 0):
            raise ValueError("scan size must be a positive length in nm")
        opts["scan_size_nm"] = float(scan_size_nm)
    if directions is not None:
        bad = [d for d in directions if d not in DIRECTIONS]
        if bad or not directions:
            raise ValueError(f"directions must be among {', '.join(DIRECTIONS)}")
        opts["directions"] = tuple(directions)
    if velocity_nm_per_s is not None:
        if not (math.isfinite(velocity_nm_per_s) and velocity_nm_per_s > 0):
            raise ValueError("velocity must be a positive number of nm/s")
        opts["velocity_nm_per_s"] = float(velocity_nm_per_s)
    return opts


def friction_loop(trace_img: np.ndarray, retrace_img: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Friction and lateral offset per line from a trace/retrace pair.

    Parameters
    ----------
    trace_img, retrace_img : ndarray, shape (lines, pixels) or (pixels,)
        Lateral signal of both directions, columns in increasing x (as stored).

    Returns
    -------
    friction : ndarray, shape (lines,) or scalar array
        Mean over the line of ``(trace - retrace) / 2``.
    offset : ndarray, shape (lines,) or scalar array
        Mean over the line of ``(trace + retrace) / 2`` (the lateral offset).
    """
    t = np.asarray(trace_img, dtype=float)
    r = np.asarray(retrace_img, dtype=float)
    if t.shape != r.shape:
        raise ValueError(f"trace and retrace differ in shape ({t.shape} vs {r.shape})")
    return ((t - r) / 2.0).mean(axis=-1), ((t + r) / 2.0).mean(axis=-1)


def to_force(
    data: np.ndarray, unit: str, calibration_nN_per_V: float | None
) -> tuple[np.ndarray, str, bool]:
    """Convert a lateral signal to nN where possible.

    Returns
    -------
    force : ndarray
        In nN if ``calibrated`` else in V.
    unit : str
        ``"nN"`` or ``"V"``.
    calibrated : bool
        True when the values are forces.

    Raises
    ------
    ValueError
        If ``unit`` is neither a force nor a voltage unit.
    """
    f = force_scale_to_nN(unit)
    if f is not None:
        return data * f, "nN", True
    v = volt_scale_to_V(unit)
    if v is None:
        raise ValueError(f"unit '{unit}' is neither a force nor a voltage")
    if calibration_nN_per_V is not None:
        return data * (v * calibration_nN_per_V), "nN", True
    return data * v, "V", False


def pair_channels(channels: Iterable[Channel]) -> list[tuple[str, Channel | None, Channel | None]]:
    """Pair lateral channels by name: ``(name, trace, retrace)``, in file order.

    A channel whose direction is unknown counts as a trace.
    """
    pairs: dict[str, list[Channel | None]] = {}
    for ch in channels:
        slot = pairs.setdefault(base_name(ch.name), [None, None])
        i = 1 if ch.direction == RETRACE else 0
        if slot[i] is None:
            slot[i] = ch
    return [(name, t, r) for name, (t, r) in pairs.items()]


def map_to_traces(
    scan: ScanFile,
    calibration_nN_per_V: float | None = None,
    directions: Sequence[str] = DEFAULT_DIRECTIONS,
    scan_size_nm: float | None = None,
    **_: Any,
) -> list[Trace]:
    """Turn the lateral-force images of a scan into one trace per line and direction.

    Parameters
    ----------
    scan : ScanFile
        What a vendor reader extracted.
    calibration_nN_per_V : float, optional
        Used for channels in volts; wins over ``scan.meta["calibration_nN_per_V"]``
        (a calibration stored in the file).
    directions : sequence of str
        Which of ``"trace"``, ``"retrace"``, ``"loop"`` to emit.
    scan_size_nm : float, optional
        Used when the file does not state the scan size; without either, positions
        are pixel indices and ``meta["x_unit"]`` is ``"px"``.

    Returns
    -------
    list of Trace
        Named ``<stem>:<channel>:<direction>:L<line>``, with provenance in ``meta``.

    Raises
    ------
    TraceReadError
        If the scan has no usable lateral-force image.
    """
    path = scan.path
    lateral = [c for c in scan.lateral() if c.data is not None]
    if not lateral:
        found = ", ".join(f"{c.name} ({c.direction or '?'})" for c in scan.channels)
        found = f"found: {found}" if found else "no image channels: a force curve or spectrum?"
        raise TraceReadError(path, f"no lateral-force channel ({found})")
    stored = scan.meta.get("calibration_nN_per_V")
    cal = calibration_nN_per_V if calibration_nN_per_V is not None else stored
    cal_meta = {"calibration_nN_per_V": cal,
                "calibration_source": "flag" if calibration_nN_per_V is not None else "file"}
    size = scan.scan_size_nm or scan_size_nm
    traces: list[Trace] = []
    for name, tr, rt in pair_channels(lateral):
        images: dict[str, np.ndarray] = {}
        unit, calibrated, volts = "V", False, False
        for direction, ch in ((TRACE, tr), (RETRACE, rt)):
            if ch is None or ch.data is None:
                continue
            try:
                images[direction], unit, calibrated = to_force(ch.data, ch.unit, cal)
            except ValueError as e:
                raise TraceReadError(path, f"channel {ch.name}: {e}") from None
            volts = volts or volt_scale_to_V(ch.unit) is not None
        lines = _line_traces(scan, name, images, unit, calibrated, size, directions)
        for t in lines:
            t.meta.pop("calibration_nN_per_V", None)  # the file's, perhaps not the one used
            if volts and cal is not None:
                t.meta.update(cal_meta)
        traces.extend(lines)
    if not traces:
        raise TraceReadError(path, "no traces for the requested directions")
    return traces


def _line_traces(
    scan: ScanFile,
    channel: str,
    images: Mapping[str, np.ndarray],
    unit: str,
    calibrated: bool,
    size_nm: float | None,
    directions: Sequence[str],
) -> list[Trace]:
    first = next(iter(images.values()))
    n_lines, n_px = first.shape
    if TRACE in images and RETRACE in images and images[TRACE].shape != images[RETRACE].shape:
        raise TraceReadError(scan.path, f"channel {channel}: trace and retrace differ in shape")
    missing = {d: ~np.isfinite(img) for d, img in images.items()}
    any_missing = any(m.any() for m in missing.values())
    if any_missing:
        images = {d: fill_missing(img, missing[d]) for d, img in images.items()}
    x = np.arange(n_px, dtype=float) * (size_nm / n_px if size_nm else 1.0)
    loops = None
    if TRACE in images and RETRACE in images:
        loops = friction_loop(images[TRACE], images[RETRACE])
    base_meta = {
        "file": str(scan.path),
        "format": scan.fmt,
        "channel": channel,
        "unit": unit,
        "calibrated": calibrated,
        "scan_size_nm": size_nm,
        "x_unit": "nm" if size_nm else "px",
        "load": scan.meta.get("load"),
        "load_unit": scan.meta.get("load_unit"),
    }
    base_meta.update({k: v for k, v in scan.meta.items() if k not in base_meta})
    width = max(3, len(str(n_lines - 1)))
    stem = Path(scan.path).stem
    out: list[Trace] = []
    for line in range(n_lines):
        rows = {
            TRACE: images[TRACE][line] if TRACE in images else None,
            RETRACE: -images[RETRACE][line][::-1] if RETRACE in images else None,
            LOOP: (images[TRACE][line] - images[RETRACE][line]) / 2 if loops is not None else None,
        }
        for direction in directions:
            f = rows.get(direction)
            if f is None:
                continue
            meta = dict(base_meta, direction=direction, line=line)
            if any_missing:
                meta.update(_masked(_missing_of(missing, direction, line)))
            if loops is not None:
                meta["loop_friction"] = float(loops[0][line])
                meta["loop_offset"] = float(loops[1][line])
            out.append(
                Trace(
                    x_nm=x.copy(),
                    force_nN=np.ascontiguousarray(f, dtype=float),
                    name=f"{stem}:{channel}:{direction}:L{line:0{width}d}",
                    source=str(scan.path),
                    meta=meta,
                )
            )
    return out


def fill_missing(image: np.ndarray, missing: np.ndarray) -> np.ndarray:
    """A copy of ``image`` (lines, pixels) with its ``missing`` pixels interpolated
    linearly along each line (the nearest value at the ends; zeros for an empty line)."""
    out = np.array(image, dtype=float)
    idx = np.arange(out.shape[1])
    for line in np.flatnonzero(missing.any(axis=1)):
        bad = missing[line]
        out[line, bad] = np.interp(idx[bad], idx[~bad], out[line, ~bad]) if not bad.all() else 0.0
    return out


def _missing_of(missing: Mapping[str, np.ndarray], direction: str, line: int) -> np.ndarray:
    """Missing pixels of one line in the trace's own x order."""
    if direction == TRACE:
        return missing[TRACE][line]
    if direction == RETRACE:
        return missing[RETRACE][line][::-1]
    return missing[TRACE][line] | missing[RETRACE][line]


def _masked(bad: np.ndarray) -> dict[str, Any]:
    """``masked_pixels`` of a line, and ``unusable`` where too much of it is missing."""
    n = int(bad.sum())
    meta: dict[str, Any] = {"masked_pixels": n}
    edges = np.diff(np.concatenate([[0], bad.astype(np.int8), [0]]))
    run = int((np.flatnonzero(edges == -1) - np.flatnonzero(edges == 1)).max()) if n else 0
    if n > MAX_NAN_FRACTION * bad.size or run > MAX_NAN_RUN:
        meta["unusable"] = (f"{n} of {bad.size} pixels are NaN (longest gap {run}): too much "
                            "of the line is missing to estimate it")  # fmt: skip
    return meta


def assign_loads(
    traces: Sequence[Trace],
    lines_per_load: int,
    loads: Sequence[float] | None = None,
    load_unit: str = "nN",
) -> list[Trace]:
    """Group lines by load: set ``load_group`` (and ``load``) in each trace's meta.

    Line ``i`` belongs to group ``i // lines_per_load``; with ``loads`` its load is
    ``loads[group]``. Traces without a ``line`` in their meta are left unchanged.
    The traces are modified in place and returned.

    Raises
    ------
    ValueError
        If a line's group has no entry in ``loads``.
    """
    if lines_per_load < 1:
        raise ValueError("lines per load must be at least 1")
    for t in traces:
        line = t.meta.get("line")
        if not isinstance(line, int):
            continue
        group = line // lines_per_load
        t.meta["load_group"] = group
        if loads is not None:
            if group >= len(loads):
                raise ValueError(
                    f"line {line} is in load group {group + 1} but only {len(loads)} "
                    f"loads were given"
                )
            t.meta["load"] = float(loads[group])
            t.meta["load_unit"] = load_unit
    return list(traces)


def apply_load_schedule(
    traces: list[Trace], path: str | os.PathLike, **options: Any
) -> list[Trace]:
    """Apply ``lines_per_load``/``loads`` reader options, with one-line errors."""
    n = options.get("lines_per_load")
    if not n:
        return traces
    try:
        return assign_loads(traces, n, options.get("loads"), options.get("load_unit", "nN"))
    except ValueError as e:
        raise TraceReadError(path, str(e)) from None


def _load_of(row: Any) -> Any:
    meta = row.meta if isinstance(row, Trace) else row
    return meta.get("load")


def group_by_load(rows: Iterable[Any]) -> list[tuple[float | None, list[Any]]]:
    """Group result rows (mappings with a ``load`` key, or traces) by load.

    Returns
    -------
    list of (load, rows)
        Sorted by increasing load; rows without a load come last, under ``None``.
    """
    groups: dict[float | None, list[Any]] = {}
    for row in rows:
        load = _load_of(row)
        key = None if load is None or (isinstance(load, float) and math.isnan(load)) else load
        groups.setdefault(key, []).append(row)
    return sorted(groups.items(), key=lambda kv: (kv[0] is None, kv[0] if kv[0] is not None else 0))


def summarise_by_load(rows: Iterable[Mapping[str, Any]], keys: Sequence[str]) -> list[dict]:
    """Mean, standard deviation and count of numeric ``keys`` per load group.

    Returns
    -------
    list of dict
        One per group: ``load``, ``load_unit``, ``n`` and ``<key>_mean``, ``<key>_std``.
    """
    out = []
    for load, group in group_by_load(rows):
        unit = group[0].get("load_unit")
        rec: dict[str, Any] = {"load": load, "load_unit": unit, "n": len(group)}
        for k in keys:
            vals = np.array([float(r[k]) for r in group if r.get(k) is not None], dtype=float)
            vals = vals[np.isfinite(vals)]
            rec[f"{k}_mean"] = float(vals.mean()) if vals.size else math.nan
            rec[f"{k}_std"] = float(vals.std(ddof=1)) if vals.size > 1 else math.nan
        out.append(rec)
    return out


def parse_loads(text: str | None) -> list[float] | None:
    """Parse a comma-separated list of loads (``"10,8,6"``); ``None`` or empty gives None.

    Raises
    ------
    ValueError
        With a one-line message naming the bad entry.
    """
    if not text or not text.strip():
        return None
    out = []
    for part in text.split(","):
        try:
            v = float(part)
        except ValueError:
            raise ValueError(f"bad load '{part.strip()}' (expected numbers like 10,8,6)") from None
        if not math.isfinite(v):
            raise ValueError(f"bad load '{part.strip()}' (not finite)")
        out.append(v)
    return out
