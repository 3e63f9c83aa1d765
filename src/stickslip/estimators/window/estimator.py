"""The reference paper's window MLP behind the one estimator interface."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from stickslip.conditions import TEMPERATURE_TOLERANCE_K, Conditions
from stickslip.estimators.base import TraceEstimator
from stickslip.estimators.domain import ETA_EDGE
from stickslip.estimators.window.inference import OUTPUTS, TraceEstimate, predict_traces
from stickslip.estimators.window.modelfile import TrainedModel
from stickslip.traces.trace import Trace

VELOCITY_TOLERANCE = 0.01  # relative velocity mismatch that earns a note


class WindowEstimator(TraceEstimator):
    """The paper's MLP (``raw`` or ``pi`` input) on windows of ``p`` pixels.

    Per trace: the mean over its windows (``U0_eV``, ``K_N_m``, ``eta``), their spread
    over windows (``*_std``; no intervals), ``n_windows``; ``F_mean_nN`` is the trace's
    own mean and ``F_mean_net`` the network's estimate of it. Traces on another lattice
    are mapped onto the training lattice (:mod:`stickslip.estimators.mapping`).
    """

    kind = "window"
    intervals = False
    eta_edge = ETA_EDGE  # trained on eta >= 1.2: smooth lines land at the edge

    def __init__(self, model: TrainedModel, source: str = "bundled") -> None:
        self.model = model
        self.source = source
        self.reference = model.features.reference
        self.name = f"window-{model.features.recipe}"

    def describe(self) -> str:
        spec = self.model.features
        return (f"the reference paper's MLP, {spec.recipe} input, windows of {spec.window} px "
                f"({self.source})")  # fmt: skip

    def window_estimates(self, traces: Sequence[Trace], lattice_nm: Sequence[float]
                         ) -> tuple[list[TraceEstimate], list[tuple[str, str]]]:  # fmt: skip
        """Per-trace estimates with their per-window values (for panels)."""
        return predict_traces(self.model, list(traces), list(lattice_nm), keep_windows=True)

    def estimate(self, traces: Sequence[Trace], conditions: Sequence[Conditions]
                 ) -> tuple[list[dict[str, Any] | str], list[str]]:  # fmt: skip
        ests, failures = predict_traces(self.model, list(traces),
                                        [c.lattice_nm for c in conditions])  # fmt: skip
        out: list[dict[str, Any] | str] = [""] * len(traces)
        for e in ests:
            row: dict[str, Any] = {k: e.values[k] for k in OUTPUTS}
            row.update({f"{k}_std": e.std[k] for k in OUTPUTS})
            row["F_mean_net"] = e.values["F_mean_net"]
            row["n_windows"] = e.n_windows
            out[e.index] = row
        reasons = iter(r for _, r in failures)
        out = [r if r != "" else next(reasons) for r in out]
        return out, self._notes(conditions)

    def _notes(self, conditions: Sequence[Conditions]) -> list[str]:
        ref = self.reference
        v = sorted({c.velocity_nm_per_s for c in conditions})
        T = sorted({c.temperature_K for c in conditions})
        off_v = any(abs(x / ref.velocity_nm_per_s - 1) > VELOCITY_TOLERANCE for x in v)
        off_T = any(abs(x - ref.temperature_K) > TEMPERATURE_TOLERANCE_K for x in T)
        if not (off_v or off_T):
            return []
        return [f"model trained at v = {ref.velocity_nm_per_s:g} nm/s, T = "
                f"{ref.temperature_K:g} K; traces at v = {', '.join(f'{x:g}' for x in v)} nm/s, "
                f"T = {', '.join(f'{x:g}' for x in T)} K: thermal activation is not mapped "
                "(error on simulated traces: docs/explanation/learned-model.md)"]  # fmt: skip


