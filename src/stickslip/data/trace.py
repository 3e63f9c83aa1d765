"""The trace: one line of lateral force versus support position, and its CSV format.

The project's plain trace format is a CSV file with header ``x_nm,force_nN``: support
position in nm (from 0 at the first recorded pixel) and lateral force in nN, positive
while sliding forward. Every command reads traces through :func:`collect_traces`,
which also reads vendor friction maps and other layouts (see
:mod:`stickslip.data.formats` and docs/formats.md).
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from stickslip.data.atomic import atomic_path

MIN_SAMPLES = 16
TRACE_SUFFIXES = (".csv", ".txt")


class TraceReadError(Exception):
    """A trace file that cannot be read; ``str()`` is one line naming the file."""

    def __init__(self, path: str | os.PathLike, reason: str):
        self.path = str(path)
        self.reason = reason
        super().__init__(f"{self.path}: {reason}")


@dataclass
class Trace:
    """One friction trace.

    Attributes
    ----------
    x_nm : ndarray
        Support (scan) position in nm, strictly increasing.
    force_nN : ndarray
        Lateral force in nN, positive while sliding forward.
    name : str
        Identifier used in result tables (the file stem for single-trace files).
    source : str
        Path of the file the trace came from.
    meta : dict
        Provenance and acquisition metadata (channel, direction, line, load,
        lattice_nm, velocity_nm_per_s, temperature_K, unit ...), where known.
    """

    x_nm: np.ndarray
    force_nN: np.ndarray
    name: str
    source: str = ""
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def n(self) -> int:
        return int(self.force_nN.size)

    @property
    def pixel_nm(self) -> float:
        """Mean spacing of the samples in nm."""
        return float((self.x_nm[-1] - self.x_nm[0]) / max(self.n - 1, 1))


def validate_trace(x_nm: np.ndarray, force_nN: np.ndarray, path: str) -> None:
    """Raise :class:`TraceReadError` unless the arrays form a usable trace."""
    if x_nm.shape != force_nN.shape or x_nm.ndim != 1:
        raise TraceReadError(path, "position and force columns differ in length")
    if x_nm.size < MIN_SAMPLES:
        raise TraceReadError(path, f"only {x_nm.size} samples, at least {MIN_SAMPLES} needed")
    if not (np.all(np.isfinite(x_nm)) and np.all(np.isfinite(force_nN))):
        raise TraceReadError(path, "contains NaN or infinite values")
    if np.any(np.diff(x_nm) <= 0):
        raise TraceReadError(path, "x_nm is not strictly increasing")


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
    from stickslip.data.formats.text import read_text

    p = Path(path)
    if p.is_dir():
        raise TraceReadError(p, "is a directory")
    if not p.exists():
        raise TraceReadError(p, "file not found")
    traces = read_text(p, calibration_nN_per_V=calibration_nN_per_V)
    if len(traces) != 1:
        raise TraceReadError(p, f"holds {len(traces)} traces; read it with collect_traces")
    return traces[0]


def write_trace_csv(path: str | os.PathLike, x_nm: np.ndarray, force_nN: np.ndarray) -> None:
    """Write a trace as ``x_nm,force_nN`` CSV, atomically."""
    x_nm = np.asarray(x_nm, dtype=float)
    force_nN = np.asarray(force_nN, dtype=float)
    with atomic_path(path) as tmp:
        with open(tmp, "w", newline="") as fh:
            fh.write("x_nm,force_nN\n")
            np.savetxt(fh, np.column_stack([x_nm, force_nN]), delimiter=",", fmt="%.9g")


def expand_paths(paths: Iterable[str | os.PathLike]) -> tuple[list[Path], list[TraceReadError]]:
    """Expand folders into the trace files they hold (sorted); files are kept as given.

    Returns the paths and one error per empty argument: ``Path("")`` is the current
    folder, so an empty argument (an unset shell variable) would otherwise read every
    trace there, some of them twice.
    """
    out: list[Path] = []
    errors: list[TraceReadError] = []
    for raw in paths:
        if not str(raw).strip():
            errors.append(TraceReadError("''", "empty path"))
            continue
        p = Path(raw)
        if p.is_dir():
            out.extend(sorted(q for q in p.iterdir() if q.is_file() and _is_trace_file(q)))
        else:
            out.append(p)
    return out, errors


def _is_trace_file(p: Path) -> bool:
    from stickslip.data import readers

    return readers.is_readable_suffix(p)


def collect_traces(
    paths: Sequence[str | os.PathLike], **options: Any
) -> tuple[list[Trace], list[TraceReadError]]:
    """Read every trace from files and folders, never stopping at a bad file.

    Parameters
    ----------
    paths : sequence of path-like
        Trace files, vendor files or folders of them.
    **options
        Passed to the format readers (e.g. ``calibration_nN_per_V``).

    Returns
    -------
    traces : list of Trace
        Every trace that could be read, in input order.
    errors : list of TraceReadError
        One per file that could not be read, each with a one-line reason.
    """
    from stickslip.data import readers

    traces: list[Trace] = []
    files, errors = expand_paths(paths)
    for p in files:
        try:
            traces.extend(readers.read_file(p, **options))
        except TraceReadError as e:
            errors.append(e)
    return traces, errors
