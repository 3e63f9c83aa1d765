"""The one estimator interface: traces with their conditions in, a :class:`ResultTable` out.

Every estimator (classical, the paper's window MLPs, the whole-line ensemble, and any
future one) satisfies :class:`Estimator`. :class:`TraceEstimator` implements the
shared part once: resolving each trace's conditions (user value, else the file's, else
the estimator's reference; :func:`stickslip.conditions.resolve`), provenance columns,
refusal rows; a subclass implements only :meth:`TraceEstimator.estimate`.

Nonsense never comes out as a number: a trace or conditions outside any physical range
are refused before estimating (:meth:`TraceEstimator.input_refusal`), and a row whose
estimate, std or interval bound is not finite is refused after
(:func:`~stickslip.estimators.table.nonfinite_reason`), each with a sentence saying why.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol, runtime_checkable

import numpy as np

from stickslip.conditions import GRAPHITE, Conditions, Reference, conditions_problem, resolve
from stickslip.estimators.domain import ETA_WINDOW, assess
from stickslip.estimators.table import (
    OK,
    ResultTable,
    failure_row,
    nonfinite_reason,
    provenance,
    to_volt_columns,
)
from stickslip.traces.trace import Trace, physical_problem, read_notes

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

    def input_refusal(self, trace: Trace, conditions: Conditions | None = None) -> str | None:
        """Why a trace gets no estimate before the estimator sees it, or None.

        A line the reader marked unusable (``meta["unusable"]``, e.g. mostly NaN), a
        trace whose positions are pixel indices (``meta["x_unit"] == "px"``: no x axis
        in the file), a trace or conditions outside any physical range
        (:func:`~stickslip.traces.trace.physical_problem`,
        :func:`~stickslip.conditions.conditions_problem`: forces beyond 1e4 nN, a scan
        length or lattice spacing off by orders of magnitude, positions not finite or
        not increasing), and a trace in volts for an estimator that reads only nN.
        """
        if trace.meta.get("unusable"):
            return str(trace.meta["unusable"])
        if trace.meta.get("x_unit") == "px":
            return PIXEL_INDEX_REFUSAL
        why = physical_problem(trace.x_nm, trace.force_nN, "V" if in_volts(trace) else "nN")
        if why is None and conditions is not None:
            why = conditions_problem(conditions)
        if why:
            return why
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
        results: list[dict[str, Any] | str] = [self.input_refusal(t, c) or ""
                                               for t, c in zip(traces, conds, strict=True)]
        todo = [i for i, r in enumerate(results) if r == ""]
        notes: list[str] = read_notes(traces)
        # floating-point overflow inside an estimator (a trace far outside what it reads)
        # is no error to print: its row becomes a refusal that says so (below)
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            if todo:
                done, more = self.estimate([traces[i] for i in todo], [conds[i] for i in todo])
                notes += more
                for i, res in zip(todo, done, strict=True):
                    results[i] = res
            table = ResultTable(estimator=self.name, intervals=self.intervals, notes=notes)
            table.rows = [self._row(t, c, res) for t, c, res in zip(traces, conds, results,
                                                                   strict=True)]
            if self.domain_verdict:
                assess(table.rows, [t.x_nm for t in traces], [t.force_nN for t in traces],
                       [c.lattice_nm for c in conds], widen=self.widen_out_of_domain,
                       eta_edge=self.eta_edge)  # fmt: skip
        # last, so that intervals the verdict widened are checked too: a number that is
        # not finite is never written as an answer
        for i, row in enumerate(table.rows):
            why = nonfinite_reason(row, self.intervals) if row.get("quality") == OK else None
            if why:
                table.rows[i] = self._row(traces[i], conds[i], why)
                if self.domain_verdict:
                    table.rows[i].update(in_domain=False, domain_score=None,
                                         domain_reason=f"no estimate: {why}")  # fmt: skip
        return table

    def _row(self, trace: Trace, conditions: Conditions, res: dict[str, Any] | str
             ) -> dict[str, Any]:  # fmt: skip
        """A trace's row: its estimate (or the reason it has none), conditions, provenance."""
        if isinstance(res, str):
            row = failure_row(trace.name, res, self.name)
        else:
            row = {"trace": trace.name, "estimator": self.name, "quality": OK, **res}
            if in_volts(trace):
                row = to_volt_columns(row)
        row.update(conditions.as_row())
        for k, v in provenance(trace).items():
            row.setdefault(k, v)
        return row
