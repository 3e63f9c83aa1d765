"""The whole-line CNN ensemble behind the one estimator interface."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from stickslip.conditions import Conditions
from stickslip.estimators.base import TraceEstimator
from stickslip.estimators.line.ensemble import LineEnsemble, predict_raw_lines
from stickslip.estimators.mapping import refusal
from stickslip.estimators.table import BOUNDS, TARGETS
from stickslip.traces.trace import Trace

TEMPERATURE_TOLERANCE_K = 1.0


class LineEstimator(TraceEstimator):
    """The default estimator: a whole-line CNN ensemble with calibrated intervals.

    Per trace: ``F_mean_nN, U0_eV, K_N_m, eta``, ``*_std`` (the std of the Gaussian, or
    log-normal, with the same 68 % interval) and the central 68 % / 95 % intervals. The
    lattice and the velocity of each trace enter the mapping and the network's
    conditioning; the temperature is the model's (a note says when traces differ).
    """

    kind = "line"
    intervals = True
    name = "line-cnn"

    def __init__(self, ensemble: LineEnsemble, source: str = "bundled") -> None:
        self.ensemble = ensemble
        self.source = source
        self.reference = ensemble.spec.reference

    def describe(self) -> str:
        return (f"whole-line CNN ensemble of {len(self.ensemble.members)} with calibrated "
                f"68/95 % intervals ({self.source})")  # fmt: skip

    def estimate(self, traces: Sequence[Trace], conditions: Sequence[Conditions]
                 ) -> tuple[list[dict[str, Any] | str], list[str]]:  # fmt: skip
        spec = self.ensemble.spec
        out: list[dict[str, Any] | str] = [
            refusal(t.x_nm, c.lattice_nm, self.reference, spec.min_pixels) or ""
            for t, c in zip(traces, conditions, strict=True)
        ]
        ok = [i for i, r in enumerate(out) if r == ""]
        notes = []
        T = sorted({c.temperature_K for c in conditions})
        if any(abs(x - spec.temperature_K) > TEMPERATURE_TOLERANCE_K for x in T):
            listed = ", ".join(f"{x:g}" for x in T)
            notes.append(f"model trained at T = {spec.temperature_K:g} K, traces at {listed} K: "
                         "estimates are extrapolated")  # fmt: skip
        if not ok:
            return out, notes
        pred = predict_raw_lines(
            self.ensemble, [traces[i].x_nm for i in ok], [traces[i].force_nN for i in ok],
            np.array([conditions[i].lattice_nm for i in ok]),
            np.array([conditions[i].velocity_nm_per_s for i in ok]),
        )  # fmt: skip
        for j, i in enumerate(ok):
            row: dict[str, Any] = {k: float(pred.values[k][j]) for k in TARGETS}
            row.update({f"{k}_std": float(pred.std[k][j]) for k in TARGETS})
            for b in BOUNDS:
                row.update({f"{k}_{b}": float(getattr(pred, b)[k][j]) for k in TARGETS})
            out[i] = row
        return out, notes
