"""Finite-temperature Prandtl-Tomlinson simulator and synthetic datasets.

- :func:`simulate` -- per-trajectory parameters in, pixel-averaged traces out,
- :func:`run_sweep` -- sample the training range and write a chunked HDF5 dataset,
- settings dataclasses in :mod:`stickslip.simulators.config`,
- the numba kernel (:mod:`.kernel`), the CUDA kernel (:mod:`.cuda`) and the numpy
  reference (:mod:`.reference`) behind the backend interface (:mod:`.backends`).
"""

from stickslip.simulators.config import (
    PRESETS,
    ParameterRange,
    PhysicalSettings,
    SettingsError,
    SubstrateAugmentation,
    SweepConfig,
)
from stickslip.simulators.simulate import SimulationResult, simulate
from stickslip.simulators.sweep import run_sweep

__all__ = [
    "PRESETS",
    "ParameterRange",
    "PhysicalSettings",
    "SettingsError",
    "SimulationResult",
    "SubstrateAugmentation",
    "SweepConfig",
    "run_sweep",
    "simulate",
]
