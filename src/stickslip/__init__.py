"""stickslip: Prandtl-Tomlinson parameters from atomic-scale stick-slip friction traces.

Subpackages follow the pipeline, each importing only those before it:

- :mod:`stickslip.traces` -- the trace, readers of plain and vendor files, datasets,
- :mod:`stickslip.simulators` -- the finite-temperature PT simulator, sweeps, effects,
- :mod:`stickslip.estimators` -- one interface (:class:`Estimator`) for the classical
  estimator, the paper's window MLP and the whole-line ensemble; the result table,
- :mod:`stickslip.diagnostics` -- metrics, coverage, posterior predictive checks, plots,
  reports,
- :mod:`stickslip.jobs` -- what each command does, returning tables,
- :mod:`stickslip.cli` -- the ``stickslip`` command (argument parsing only).

The functions below (:mod:`stickslip.api`) mirror the command line.
"""

from stickslip._version import __version__
from stickslip.api import evaluate, predict, read_traces, train
from stickslip.conditions import GRAPHITE, Conditions, Reference
from stickslip.estimators.base import Estimator
from stickslip.estimators.load import load_estimator
from stickslip.estimators.table import ResultTable
from stickslip.simulators import PhysicalSettings, SweepConfig, run_sweep, simulate
from stickslip.traces.trace import Trace

__all__ = [
    "GRAPHITE",
    "Conditions",
    "Estimator",
    "PhysicalSettings",
    "Reference",
    "ResultTable",
    "SweepConfig",
    "Trace",
    "__version__",
    "evaluate",
    "load_estimator",
    "predict",
    "read_traces",
    "run_sweep",
    "simulate",
    "train",
]
