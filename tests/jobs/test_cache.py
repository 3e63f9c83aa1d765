"""The cached sweeps of jobs.cache: a leftover ``.partial`` never blocks a cache."""

from __future__ import annotations

import os

import numpy as np

from stickslip.jobs.cache import sweep_if_missing
from stickslip.simulators.sweep import partial_path
from stickslip.traces.dataset import load_dataset


def test_leftover_partial_is_resumed_or_replaced(tmp_path):
    """Old: a .partial left by an interrupted cache run made every later run fail with
    'partial exists'."""
    ref = load_dataset(sweep_if_missing(tmp_path / "ref.h5", 3, seed=7))
    # an interrupted run of the same sweep: its partial is resumed, the rows agree
    out = tmp_path / "same.h5"
    os.replace(tmp_path / "ref.h5", partial_path(out))
    same = load_dataset(sweep_if_missing(out, 3, seed=7))
    np.testing.assert_array_equal(same.force_nN, ref.force_nN)
    # a partial of another sweep (other seed) is replaced, not resumed
    other = tmp_path / "other.h5"
    os.replace(out, partial_path(other))
    fresh = load_dataset(sweep_if_missing(other, 3, seed=8))
    assert fresh.attrs["seed"] == 8 and not partial_path(other).exists()
    assert not np.array_equal(fresh.force_nN, ref.force_nN)
