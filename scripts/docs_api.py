"""The public Python API that the docs' reference shows, and a check of its docstrings.

``PUBLIC`` names every object the reference documents (the names ``import stickslip``
exports, and the estimator base class). ``python scripts/docs_api.py`` fails (exit 1)
when one of them, or one of its public methods or properties, has no docstring, or when
a name exported by ``stickslip.__all__`` is missing here; ``make docs`` runs it before
building the site.
"""

from __future__ import annotations

import importlib
import inspect
import sys

#: (module, name) of every documented object, in the order of the reference page.
PUBLIC = (
    ("stickslip.api", "read_traces"),
    ("stickslip.api", "predict"),
    ("stickslip.api", "evaluate"),
    ("stickslip.api", "train"),
    ("stickslip.estimators.load", "load_estimator"),
    ("stickslip.estimators.base", "Estimator"),
    ("stickslip.estimators.base", "TraceEstimator"),
    ("stickslip.estimators.table", "ResultTable"),
    ("stickslip.traces.trace", "Trace"),
    ("stickslip.conditions", "Conditions"),
    ("stickslip.conditions", "Reference"),
    ("stickslip.simulators.simulate", "simulate"),
    ("stickslip.simulators.simulate", "SimulationResult"),
    ("stickslip.simulators.config", "PhysicalSettings"),
    ("stickslip.simulators.config", "SweepConfig"),
    ("stickslip.simulators.sweep", "run_sweep"),
)
#: exported names that are constants, not callables (documented in prose)
CONSTANTS = {"GRAPHITE", "__version__"}


def _own_members(cls: type) -> list[tuple[str, object]]:
    out = []
    for name, value in vars(cls).items():
        if name.startswith("_"):
            continue
        if isinstance(value, (staticmethod, classmethod)):
            value = value.__func__
        if isinstance(value, property) or inspect.isfunction(value):
            out.append((name, value))
    return out


def missing_docstrings() -> list[str]:
    """Names of documented objects (and their public members) without a docstring."""
    missing = []
    for module, name in PUBLIC:
        obj = getattr(importlib.import_module(module), name)
        if not (inspect.getdoc(obj) or "").strip():
            missing.append(f"{module}.{name}")
        if inspect.isclass(obj):
            for member, value in _own_members(obj):
                if not (getattr(value, "__doc__", None) or "").strip():
                    missing.append(f"{module}.{name}.{member}")
    import stickslip

    shown = {name for _, name in PUBLIC}
    missing += [f"stickslip.{n} (exported, not in scripts/docs_api.py PUBLIC)"
                for n in stickslip.__all__ if n not in shown and n not in CONSTANTS]
    return missing


def main() -> int:
    missing = missing_docstrings()
    for name in missing:
        print(f"missing docstring: {name}", file=sys.stderr)
    if not missing:
        print(f"docstrings: all {len(PUBLIC)} public objects and their members documented")
    return 1 if missing else 0


if __name__ == "__main__":
    sys.exit(main())
