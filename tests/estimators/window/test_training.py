"""Training on a small simulated sweep: split by trajectory, learning beats a baseline."""

from __future__ import annotations

import numpy as np
import pytest

from stickslip.estimators.window.estimator import WindowEstimator
from stickslip.estimators.window.inference import map_trace, predict_array, predict_traces
from stickslip.estimators.window.training import (
    TrainConfig,
    spec_for_dataset,
    split_by_trajectory,
    train_model,
    window_set,
)
from stickslip.jobs.evaluate import evaluate_dataset
from stickslip.traces.trace import Trace


def test_split_is_by_trajectory_and_seeded():
    tr, va = split_by_trajectory(1600, 0.2, seed=3)
    assert tr.size == 1280 and va.size == 320
    assert not set(tr) & set(va) and set(tr) | set(va) == set(range(1600))
    tr2, va2 = split_by_trajectory(1600, 0.2, seed=3)
    np.testing.assert_array_equal(va, va2)
    assert not np.array_equal(va, split_by_trajectory(1600, 0.2, seed=4)[1])


def test_windows_carry_their_trajectory_labels(small_sweep):
    spec = spec_for_dataset(small_sweep, "pi", 64, 64, 16)
    y = np.arange(small_sweep.n * 3, dtype=float).reshape(-1, 3)
    x, yw = window_set(small_sweep.force_nN[:5], y[:5], spec, 16)
    per = (512 - 64) // 16 + 1
    assert x.shape == (5 * per, 64)
    np.testing.assert_array_equal(x[per + 1], small_sweep.force_nN[1, 16:80])
    np.testing.assert_array_equal(yw[per * 2 : per * 3], np.repeat(y[2:3], per, axis=0))


@pytest.fixture(scope="module")
def trained(small_sweep):
    spec = spec_for_dataset(small_sweep, "pi", 64, 64, 16)
    cfg = TrainConfig(epochs=15, seed=0)
    return train_model(small_sweep, spec, cfg, progress=False)


def test_small_training_beats_the_trivial_baseline(trained, small_sweep):
    model, hist, val_idx = trained
    assert len(hist.train_loss) == 15 and hist.train_loss[-1] < hist.train_loss[0]
    # the kept weights are those of the best validation epoch
    assert model.train_config["best_epoch"] == 1 + int(np.argmin(hist.val_loss))
    ev = evaluate_dataset(WindowEstimator(model), small_sweep, val_idx)
    train_idx = np.setdiff1d(np.arange(small_sweep.n), val_idx)
    for k in ("U0_eV", "K_N_m"):
        truth = small_sweep.params[k]
        # trivial baseline: predict the training mean for every held-out trajectory
        base = np.sqrt(np.mean((truth[val_idx] - truth[train_idx].mean()) ** 2))
        assert ev.metrics[k]["rmse"] < 0.5 * base, (k, ev.metrics[k]["rmse"], base)


def test_trace_path_matches_array_path_and_lattice_mapping(trained, small_sweep):
    model = trained[0]
    f = small_sweep.force_nN[:3].astype(float)
    fast = predict_array(model, f)
    traces = [Trace(small_sweep.x_nm, fi, f"t{i}") for i, fi in enumerate(f)]
    ests, failures = predict_traces(model, traces)
    assert not failures
    np.testing.assert_allclose([e.values["U0_eV"] for e in ests], fast["U0_eV"], rtol=1e-5)
    # the same trace, stretched to a lattice of 0.316 nm, gives U0 * s and K / s
    s = 0.316 / 0.246
    wide = [Trace(small_sweep.x_nm * s, fi, f"w{i}") for i, fi in enumerate(f)]
    mapped, _ = predict_traces(model, wide, lattice_nm=0.316)
    np.testing.assert_allclose([e.values["U0_eV"] for e in mapped], fast["U0_eV"] * s, rtol=1e-3)
    np.testing.assert_allclose([e.values["K_N_m"] for e in mapped], fast["K_N_m"] / s, rtol=1e-3)
    np.testing.assert_allclose([e.values["eta"] for e in mapped], fast["eta"], rtol=1e-3)
    # a trace too short for one window is reported, not raised
    short = Trace(small_sweep.x_nm[:40], f[0, :40], "short")
    ests, failures = predict_traces(model, [short, traces[0]])
    assert [e.trace for e in ests] == ["t0"] and failures[0][0] == "short"
    assert "too short" in failures[0][1]
    assert map_trace(small_sweep.x_nm, f[0], model, None).size == 512
    # a micron-scale line does not resolve the lattice: reported, not upsampled
    coarse = Trace(np.arange(512) * 10.0, f[0], "coarse")
    _, failures = predict_traces(model, [coarse])
    assert "does not resolve" in failures[0][1]
