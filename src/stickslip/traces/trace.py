"""The trace: one line of lateral force versus support position, and its CSV format.

The project's plain trace format is a CSV file with header ``x_nm,force_nN``: support
position in nm (from 0 at the first recorded pixel) and lateral force in nN, positive
while sliding forward. Every command reads traces through :func:`collect_traces`,
which also reads vendor friction maps and other layouts (see
:mod:`stickslip.traces.formats` and docs/reference/formats.md).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from stickslip.atomic import atomic_path

MIN_SAMPLES = 16
#: The largest lateral force (nN, or V for a trace in volts) of any AFM friction trace:
#: real ones stay below a few hundred nN; larger values are a wrong unit or a damaged file.
MAX_ABS_FORCE = 1e4
#: The shortest and longest scan line (nm) of any AFM friction trace: under half a
#: nanometre holds no lattice period, over 100 um no atomic-scale stick-slip map is taken.
SCAN_RANGE_NM = (0.5, 1e5)
#: ``meta`` key of a line saying how a reader read a file that is not in the usual
#: layout (European CSV), shown once per file as a note of the run (:func:`read_notes`).
READ_NOTE = "read_note"


class TraceReadError(Exception):
    """A trace file that cannot be read; ``str()`` is one line naming the file."""

    def __init__(self, path: str | os.PathLike, reason: str):
        self.path = str(path)
        # one printable line, whatever bytes a damaged file put into the reason
        self.reason = "".join(c if c.isprintable() else "?" for c in " ".join(reason.split()))
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
        """Number of samples (pixels) in the trace."""
        return int(self.force_nN.size)

    @property
    def pixel_nm(self) -> float:
        """Mean spacing of the samples in nm."""
        return float((self.x_nm[-1] - self.x_nm[0]) / max(self.n - 1, 1))


def trace_problem(x_nm: np.ndarray, force_nN: np.ndarray) -> str | None:
    """Why the arrays do not form a usable trace (one line), or None when they do.

    Checks the shapes, the number of samples (:data:`MIN_SAMPLES`), that every value
    is finite, and that the positions strictly increase.
    """
    x_nm, force_nN = np.asarray(x_nm), np.asarray(force_nN)
    if x_nm.shape != force_nN.shape or x_nm.ndim != 1:
        return "position and force columns differ in length"
    if x_nm.size < MIN_SAMPLES:
        return f"only {x_nm.size} samples, at least {MIN_SAMPLES} needed"
    if not (np.all(np.isfinite(x_nm)) and np.all(np.isfinite(force_nN))):
        return "contains NaN or infinite values"
    if np.any(np.diff(x_nm) <= 0):
        return "x_nm is not strictly increasing"
    return None


def validate_trace(x_nm: np.ndarray, force_nN: np.ndarray, path: str) -> None:
    """Raise :class:`TraceReadError` unless the arrays form a usable trace
    (:func:`trace_problem`)."""
    why = trace_problem(x_nm, force_nN)
    if why:
        raise TraceReadError(path, why)


def physical_problem(x_nm: np.ndarray, force_nN: np.ndarray, unit: str = "nN") -> str | None:
    """Why a trace lies outside any physical range (a sentence), or None.

    A usable trace (:func:`trace_problem`) whose forces exceed :data:`MAX_ABS_FORCE`
    somewhere, or whose scan length lies outside :data:`SCAN_RANGE_NM`, is a wrong unit
    or a damaged file, never a friction measurement: no estimate can mean anything.

    Parameters
    ----------
    x_nm, force_nN : ndarray
        Positions (nm) and forces.
    unit : str
        The force unit, for the message (``nN``, or ``V`` for a trace in volts).

    Returns
    -------
    str or None
    """
    why = trace_problem(x_nm, force_nN)
    if why:
        return f"not a usable trace: {why}"
    peak = float(np.max(np.abs(force_nN)))
    if peak > MAX_ABS_FORCE:
        return (f"force outside any physical range: |F| reaches {peak:.3g} {unit} (more than "
                f"{MAX_ABS_FORCE:g} {unit}); check the force unit or the calibration")
    span = float(x_nm[-1] - x_nm[0])
    lo, hi = SCAN_RANGE_NM
    if not span >= lo:
        return (f"too short for any friction trace: the scan covers {span:.3g} nm (at least "
                f"{lo:g} nm needed); check that the positions are in nm")
    if span > hi:
        return (f"scan length outside any physical range: {span:.3g} nm (more than {hi:g} "
                "nm); check that the positions are in nm")
    return None


def read_notes(traces: Sequence[Trace]) -> list[str]:
    """One ``file: note`` line per file whose traces carry a :data:`READ_NOTE`."""
    seen: dict[str, None] = {}
    for t in traces:
        note = t.meta.get(READ_NOTE)
        if note:
            seen.setdefault(f"{t.source or t.name}: {note}", None)
    return list(seen)


def write_trace_csv(path: str | os.PathLike, x_nm: np.ndarray, force_nN: np.ndarray) -> None:
    """Write a trace as ``x_nm,force_nN`` CSV, atomically."""
    x_nm = np.asarray(x_nm, dtype=float)
    force_nN = np.asarray(force_nN, dtype=float)
    with atomic_path(path) as tmp:
        with open(tmp, "w", newline="") as fh:
            fh.write("x_nm,force_nN\n")
            np.savetxt(fh, np.column_stack([x_nm, force_nN]), delimiter=",", fmt="%.9g")
