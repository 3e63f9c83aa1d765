"""The trace: one line of lateral force versus support position, and its CSV format.

The project's plain trace format is a CSV file with header ``x_nm,force_nN``: support
position in nm (from 0 at the first recorded pixel) and lateral force in nN, positive
while sliding forward. Every command reads traces through :func:`collect_traces`,
which also reads vendor friction maps and other layouts (see
:mod:`stickslip.traces.formats` and docs/reference/formats.md).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from stickslip.atomic import atomic_path

MIN_SAMPLES = 16


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
        """Number of samples (pixels) in the trace."""
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


def write_trace_csv(path: str | os.PathLike, x_nm: np.ndarray, force_nN: np.ndarray) -> None:
    """Write a trace as ``x_nm,force_nN`` CSV, atomically."""
    x_nm = np.asarray(x_nm, dtype=float)
    force_nN = np.asarray(force_nN, dtype=float)
    with atomic_path(path) as tmp:
        with open(tmp, "w", newline="") as fh:
            fh.write("x_nm,force_nN\n")
            np.savetxt(fh, np.column_stack([x_nm, force_nN]), delimiter=",", fmt="%.9g")
