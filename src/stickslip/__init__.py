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

from __future__ import annotations

import importlib
from typing import Any

from stickslip._version import __version__

# Imported on first use (PEP 562): ``import stickslip.simulators`` in a Dask worker or a
# CLI command must not pay for torch and matplotlib, which only some of these need.
_EXPORTS = {
    "evaluate": "stickslip.api",
    "predict": "stickslip.api",
    "read_traces": "stickslip.api",
    "train": "stickslip.api",
    "GRAPHITE": "stickslip.conditions",
    "Conditions": "stickslip.conditions",
    "Reference": "stickslip.conditions",
    "Estimator": "stickslip.estimators.base",
    "load_estimator": "stickslip.estimators.load",
    "ResultTable": "stickslip.estimators.table",
    "PhysicalSettings": "stickslip.simulators",
    "SweepConfig": "stickslip.simulators",
    "run_sweep": "stickslip.simulators",
    "simulate": "stickslip.simulators",
    "Trace": "stickslip.traces.trace",
}


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'stickslip' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value  # later lookups skip this function
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))


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
