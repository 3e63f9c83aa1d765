"""Measurement conditions: the reference an estimator was built for, and a trace's own.

A trace is read at a lattice spacing ``a`` (nm), a scan velocity ``v`` (nm/s) and a
temperature ``T`` (K). Each is resolved once per trace, in this order: a value the user
gives (``"flag"``), the trace file's metadata (``"file"``), the estimator's reference
(``"model"``). The result table records which source each value came from.

:data:`GRAPHITE` is the project's one reference: the reference paper's preset, graphite
(a0 = 0.246 nm), 11 nm recorded as 512 pixels, 60 nm/s, 296 K.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import Any

GRAPHITE_LATTICE_NM = 0.246
PAPER_PIXEL_NM = 11.0 / 512
PAPER_VELOCITY_NM_PER_S = 60.0
ROOM_TEMPERATURE_K = 296.0
#: how far (K) a trace's temperature may lie from the ones a model was trained at
TEMPERATURE_TOLERANCE_K = 1.0

#: The lattice spacings (nm) of any crystal surface a friction map reads: graphite's
#: 0.246 nm, MoS2's 0.316 nm, up to a few nm for large-cell surfaces. A value outside
#: is a wrong unit (m or A for nm) or a damaged file.
LATTICE_RANGE_NM = (0.05, 5.0)

FLAG, FILE, MODEL = "flag", "file", "model"
QUANTITIES = ("lattice_nm", "velocity_nm_per_s", "temperature_K")


@dataclass(frozen=True)
class Reference:
    """The conditions a model was trained at (or an estimator assumes by default).

    Attributes
    ----------
    lattice_nm : float
        Reference lattice spacing a0 in nm.
    pixel_nm : float
        Reference pixel (support travel per recorded sample) in nm.
    velocity_nm_per_s : float
        Reference scan velocity in nm/s.
    temperature_K : float
        Reference temperature in K.
    """

    lattice_nm: float = GRAPHITE_LATTICE_NM
    pixel_nm: float = PAPER_PIXEL_NM
    velocity_nm_per_s: float = PAPER_VELOCITY_NM_PER_S
    temperature_K: float = ROOM_TEMPERATURE_K

    def to_dict(self) -> dict[str, float]:
        """The reference conditions as a plain dict (lattice in nm, velocity in nm/s,
        temperature in K)."""
        return asdict(self)


GRAPHITE = Reference()


@dataclass(frozen=True)
class Conditions:
    """The conditions one trace is read at, with the source of each value."""

    lattice_nm: float
    velocity_nm_per_s: float
    temperature_K: float
    lattice_source: str = MODEL
    velocity_source: str = MODEL
    temperature_source: str = MODEL

    def as_row(self) -> dict[str, Any]:
        """The table columns: each value and its source."""
        return {
            "lattice_nm": self.lattice_nm, "lattice_source": self.lattice_source,
            "velocity_nm_per_s": self.velocity_nm_per_s, "velocity_source": self.velocity_source,
            "temperature_K": self.temperature_K, "temperature_source": self.temperature_source,
        }  # fmt: skip


def resolve(
    meta: Mapping[str, Any],
    reference: Reference = GRAPHITE,
    lattice_nm: float | None = None,
    velocity_nm_per_s: float | None = None,
    temperature_K: float | None = None,
) -> Conditions:
    """The conditions of one trace: the user's value, else the file's, else the reference.

    Parameters
    ----------
    meta : mapping
        The trace's metadata (``lattice_nm``, ``velocity_nm_per_s``, ``temperature_K``
        where the file states them).
    reference : Reference
        The estimator's reference conditions (the fallback).
    lattice_nm, velocity_nm_per_s, temperature_K : float, optional
        Values given by the user; they win over the file.

    Returns
    -------
    Conditions
    """
    flags = {"lattice_nm": lattice_nm, "velocity_nm_per_s": velocity_nm_per_s,
             "temperature_K": temperature_K}  # fmt: skip
    values: dict[str, Any] = {}
    for q in QUANTITIES:
        src, val = MODEL, getattr(reference, q)
        if flags[q] is not None:
            src, val = FLAG, flags[q]
        elif meta.get(q) is not None:
            src, val = FILE, meta[q]
        values[q] = _as_float(val)
        values[q.split("_")[0] + "_source"] = src
    return Conditions(**values)


def _as_float(value: Any) -> float:
    """A condition as a float; NaN for a value that is no number (a damaged file's
    metadata), which :func:`conditions_problem` then refuses with its reason."""
    try:
        return float(value)
    except (TypeError, ValueError, OverflowError):
        return math.nan


def check_values(
    lattice_nm: float | None = None,
    velocity_nm_per_s: float | None = None,
    temperature_K: float | None = None,
) -> str | None:
    """A one-line reason if a user-given condition is unphysical, else None."""
    for name, v in (("lattice", lattice_nm), ("velocity", velocity_nm_per_s)):
        if v is not None and not v > 0:
            return f"--{name} must be > 0 (got {v:g})"
    lo, hi = LATTICE_RANGE_NM
    if lattice_nm is not None and not lo <= lattice_nm <= hi:
        return f"--lattice must be within {lo:g} to {hi:g} nm (got {lattice_nm:g}): is it in nm?"
    if temperature_K is not None and not temperature_K >= 0:
        return f"--temperature must be >= 0 K (got {temperature_K:g})"
    return None


def conditions_problem(conditions: Conditions) -> str | None:
    """Why a trace's resolved conditions lie outside any physical range (a sentence
    naming where the value came from), or None.

    The lattice spacing must lie within :data:`LATTICE_RANGE_NM`, the velocity be
    finite and > 0, the temperature finite and >= 0.
    """
    c = conditions
    src = {FLAG: "the command line", FILE: "the file", MODEL: "the estimator's reference"}
    lo, hi = LATTICE_RANGE_NM
    if not lo <= c.lattice_nm <= hi:
        return (f"lattice spacing outside any physical range: {c.lattice_nm:.3g} nm (from "
                f"{src[c.lattice_source]}; not within {lo:g} to {hi:g} nm); state it in nm "
                "with --lattice")
    if not (math.isfinite(c.velocity_nm_per_s) and c.velocity_nm_per_s > 0):
        return (f"scan velocity outside any physical range: {c.velocity_nm_per_s:.3g} nm/s "
                f"(from {src[c.velocity_source]}); state it in nm/s with --velocity")
    if not (math.isfinite(c.temperature_K) and c.temperature_K >= 0):
        return (f"temperature outside any physical range: {c.temperature_K:.3g} K (from "
                f"{src[c.temperature_source]}); state it in K with --temperature")
    return None
