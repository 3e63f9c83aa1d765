"""Classical stick-slip estimator: slip detection, stick slopes, PT inversion.

- :func:`estimate_trace`, :func:`estimate_traces` -- one :class:`ClassicalEstimate` per trace,
- :func:`estimate_array` -- the vectorised core (a field table for many traces),
- :func:`analyse_trace` -- detected slips and fitted stick segments (diagnostics),
- :mod:`.pt_inversion` -- the PT relations and their finite-temperature correction.
"""

from stickslip.estimators.classical.estimator import (
    ClassicalEstimate,
    ClassicalEstimator,
    estimate_array,
    estimate_trace,
    estimate_traces,
)
from stickslip.estimators.classical.slips import SlipAnalysis, analyse_trace

__all__ = [
    "ClassicalEstimate",
    "ClassicalEstimator",
    "SlipAnalysis",
    "analyse_trace",
    "estimate_array",
    "estimate_trace",
    "estimate_traces",
]
