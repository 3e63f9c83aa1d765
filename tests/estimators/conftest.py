"""A small simulated paper-preset sweep shared by the learning tests."""

from __future__ import annotations

import pytest

from stickslip.simulators import SweepConfig, run_sweep
from stickslip.traces.dataset import load_dataset


@pytest.fixture(scope="session")
def small_sweep(tmp_path_factory):
    """240 paper-preset trajectories (seed 5), loaded."""
    path = tmp_path_factory.mktemp("sweep") / "small.h5"
    run_sweep(SweepConfig(n=240, seed=5), path, progress=False)
    return load_dataset(path)
