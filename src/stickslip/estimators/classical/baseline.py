"""The five-line estimator: the floor every other estimator must beat.

U0 from the 99th-percentile force (F_max = pi U0 / a), the stick slope k_exp as the
median positive pixel slope, then eta and K by the T = 0 inversion of PHYSICS.md.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from stickslip.conditions import Conditions
from stickslip.estimators.base import TraceEstimator
from stickslip.estimators.table import TARGETS
from stickslip.traces.trace import Trace
from stickslip.units import EV_TO_NN_NM


def five_line_estimate(
    x_nm: np.ndarray, force_nN: np.ndarray, lattice_nm: float | np.ndarray = 0.246
) -> dict[str, np.ndarray]:
    """Estimate (F_mean, U0, K, eta) for traces of shape (N, P) sharing ``x_nm`` (P,)."""
    F = np.atleast_2d(force_nN)
    a = np.asarray(lattice_nm, float)
    fmax = np.percentile(F, 99, axis=1)
    slope = np.diff(F, axis=1) / np.diff(x_nm)[None, :]
    k_exp = np.nanmedian(np.where(slope > 0, slope, np.nan), axis=1)
    eta = np.maximum(2 * np.pi * fmax / (a * k_exp) - 1.0, 1e-3)
    return {
        "F_mean_nN": F.mean(axis=1),
        "U0_eV": a * fmax / np.pi / EV_TO_NN_NM,
        "K_N_m": k_exp * (1 + eta) / eta,
        "eta": eta,
    }


class FiveLineEstimator(TraceEstimator):
    """The five-line baseline (:func:`five_line_estimate`) behind the estimator interface."""

    name = "five-line"
    kind = "baseline"

    def estimate(self, traces: Sequence[Trace], conditions: Sequence[Conditions]
                 ) -> tuple[list[dict[str, Any] | str], list[str]]:  # fmt: skip
        out: list[dict[str, Any] | str] = []
        for t, c in zip(traces, conditions, strict=True):
            est = five_line_estimate(t.x_nm, t.force_nN, c.lattice_nm)
            out.append({k: float(est[k][0]) for k in TARGETS})
        return out, []
