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
from stickslip.estimators.table import OK, ResultTable, failure_row, provenance
from stickslip.traces.trace import Trace


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

    def estimate(self, traces: Sequence[Trace], conditions: Sequence[Conditions]
                 ) -> tuple[list[dict[str, Any] | str], list[str]]:  # fmt: skip
        """Per trace, its estimate columns, or a one-line reason it has none; and notes.

        Subclasses implement this; the rows get their conditions and provenance in
        :meth:`predict`.
        """
        raise NotImplementedError

    def describe(self) -> str:
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
        results, notes = self.estimate(traces, conds) if traces else ([], [])
        table = ResultTable(estimator=self.name, intervals=self.intervals, notes=list(notes))
        for t, c, res in zip(traces, conds, results, strict=True):
            if isinstance(res, str):
                row = failure_row(t.name, res, self.name)
            else:
                row = {"trace": t.name, "estimator": self.name, "quality": OK, **res}
            row.update(c.as_row())
            for k, v in provenance(t).items():
                row.setdefault(k, v)
            table.rows.append(row)
        return table
