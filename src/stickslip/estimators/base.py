"""The one estimator interface: traces with their conditions in, a :class:`ResultTable` out.

Every estimator (classical, the paper's window MLPs, the whole-line ensemble, and any
future one) satisfies :class:`Estimator`. :class:`TraceEstimator` implements the
shared part once: resolving each trace's conditions (user value, else the file's, else
the estimator's reference; :func:`stickslip.conditions.resolve`), provenance columns,
refusal rows; a subclass implements only :meth:`TraceEstimator.estimate`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol, runtime_checkable

from stickslip.conditions import GRAPHITE, Conditions, Reference, resolve
from stickslip.estimators.domain import ETA_WINDOW, assess
from stickslip.estimators.table import (
    OK,
    ResultTable,
    failure_row,
    provenance,
    to_volt_columns,
)
from stickslip.traces.trace import Trace

VOLTS_REFUSAL = ("forces in volts (no calibration) and this model was trained in nN: "
                 "pass --calibration NN_PER_V")
PIXEL_INDEX_REFUSAL = ("x is a pixel index (no x axis in the file): positions in nm are "
                       "needed (an x_nm column)")


def in_volts(trace: Trace) -> bool:
    """True for a trace read without a calibration (forces in volts)."""
    return trace.meta.get("calibrated") is False or trace.meta.get("unit") == "V"


@runtime_checkable
class Estimator(Protocol):
    """What every estimator offers.

    Attributes
    ----------
    name : str
        Short name written in the ``estimator`` column (``classical``, ``window-pi``,
        ``line-cnn`` ...).
    kind : str
        ``classical``, ``window`` or ``line``.
    reference : Reference
        Conditions used where neither the user nor the file gives them.
    intervals : bool
        Whether rows carry 68 % / 95 % intervals.
    """

    name: str
    kind: str
    reference: Reference
    intervals: bool

    def predict(
        self,
        traces: Sequence[Trace],
        *,
        lattice_nm: float | None = None,
        velocity_nm_per_s: float | None = None,
        temperature_K: float | None = None,
    ) -> ResultTable:
        """One row per trace (in input order), refusals included with their reason."""
        ...

    def describe(self) -> str:
        """One line saying what the estimator is (for logs and reports)."""
        ...


class TraceEstimator:
    """Base class: implements :meth:`predict` on top of :meth:`estimate`."""

    name: str = "estimator"
    kind: str = ""
    reference: Reference = GRAPHITE
    intervals: bool = False
    #: Whether the estimator reads traces in volts (uncalibrated): its estimates then
    #: come in volt units (:func:`~stickslip.estimators.table.to_volt_columns`). Models
    #: trained on forces in nN refuse them.
    accepts_volts: bool = False
    #: Whether :meth:`predict` adds the in/out-of-domain verdict to every row
    #: (``in_domain``, ``domain_score``, ``domain_reason``; :mod:`stickslip.estimators.domain`)
    #: and widens the intervals of rows out of domain.
    domain_verdict: bool = True
    #: Whether the verdict widens the intervals of rows out of domain (off only to
    #: measure how much they need: ``benchmarks/domain.py``).
    widen_out_of_domain: bool = True
    #: The least estimate of eta the verdict keeps in domain: the trained window's edge,
    #: or a little above it for models that cannot report an eta below their window
    #: (:data:`~stickslip.estimators.domain.ETA_EDGE`).
    eta_edge: float = ETA_WINDOW[0]

    def input_refusal(self, trace: Trace) -> str | None:
        """Why a trace gets no estimate before the estimator sees it, or None.

        A line the reader marked unusable (``meta["unusable"]``, e.g. mostly NaN), a
        trace whose positions are pixel indices (``meta["x_unit"] == "px"``: no x axis
        in the file), and a trace in volts for an estimator that reads only nN.
        """
        if trace.meta.get("unusable"):
            return str(trace.meta["unusable"])
        if trace.meta.get("x_unit") == "px":
            return PIXEL_INDEX_REFUSAL
        if in_volts(trace) and not self.accepts_volts:
            return VOLTS_REFUSAL
        return None

    def estimate(self, traces: Sequence[Trace], conditions: Sequence[Conditions]
                 ) -> tuple[list[dict[str, Any] | str], list[str]]:  # fmt: skip
        """Per trace, its estimate columns, or a one-line reason it has none; and notes.

        Subclasses implement this; the rows get their conditions and provenance in
        :meth:`predict`.
        """
        raise NotImplementedError

    def describe(self) -> str:
        """One line saying what the estimator is (here its ``name``)."""
        return self.name

    def conditions(
        self,
        traces: Sequence[Trace],
        lattice_nm: float | None = None,
        velocity_nm_per_s: float | None = None,
        temperature_K: float | None = None,
    ) -> list[Conditions]:
        """Each trace's conditions, resolved once (see :mod:`stickslip.conditions`)."""
        return [resolve(t.meta, self.reference, lattice_nm, velocity_nm_per_s, temperature_K)
                for t in traces]  # fmt: skip

    def predict(
        self,
        traces: Sequence[Trace],
        *,
        lattice_nm: float | None = None,
        velocity_nm_per_s: float | None = None,
        temperature_K: float | None = None,
    ) -> ResultTable:
        """One row per trace in input order; see :class:`Estimator`."""
        traces = list(traces)
        conds = self.conditions(traces, lattice_nm, velocity_nm_per_s, temperature_K)
        results: list[dict[str, Any] | str] = [self.input_refusal(t) or "" for t in traces]
        todo = [i for i, r in enumerate(results) if r == ""]
        notes: list[str] = []
        if todo:
            done, notes = self.estimate([traces[i] for i in todo], [conds[i] for i in todo])
            for i, res in zip(todo, done, strict=True):
                results[i] = res
        table = ResultTable(estimator=self.name, intervals=self.intervals, notes=list(notes))
        for t, c, res in zip(traces, conds, results, strict=True):
            if isinstance(res, str):
                row = failure_row(t.name, res, self.name)
            else:
                row = {"trace": t.name, "estimator": self.name, "quality": OK, **res}
                if in_volts(t):
                    row = to_volt_columns(row)
            row.update(c.as_row())
            for k, v in provenance(t).items():
                row.setdefault(k, v)
            table.rows.append(row)
        if self.domain_verdict:
            assess(table.rows, [t.x_nm for t in traces], [t.force_nN for t in traces],
                   [c.lattice_nm for c in conds], widen=self.widen_out_of_domain,
                   eta_edge=self.eta_edge)  # fmt: skip
        return table
