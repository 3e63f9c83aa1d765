"""The lab bench's cache and eta window."""

import numpy as np
import pytest

from stickslip.simulators.bench import ETA_WINDOW, BenchConfig, bench_if_missing, in_eta_window
from stickslip.traces.dataset import load_dataset


def test_eta_window_includes_its_ends():
    lo, hi = ETA_WINDOW
    assert in_eta_window(np.array([lo, hi, lo - 1e-9, hi + 1e-9])).tolist() == [
        True, True, False, False]  # fmt: skip


@pytest.mark.slow  # six bench traces take about a minute and a half on two cores
def test_bench_if_missing_simulates_once_and_then_reuses_the_file(tmp_path):
    path = tmp_path / "b.h5"
    cfg = BenchConfig(n_per_material=2, seed=5)
    assert bench_if_missing(cfg, path) == path
    first = load_dataset(path)
    assert first.n == 6 and np.all(in_eta_window(first.params["eta"]))
    stamp = path.stat().st_mtime_ns
    bench_if_missing(BenchConfig(n_per_material=3, seed=6), path)  # an existing file is kept
    assert path.stat().st_mtime_ns == stamp and load_dataset(path).n == 6
