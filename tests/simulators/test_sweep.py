"""Sweeps: sampling of the training range, HDF5 contents, atomic writes and resume."""

import json

import h5py
import numpy as np
import pytest

from stickslip.simulators import ParameterRange, PhysicalSettings, SweepConfig, run_sweep, simulate
from stickslip.simulators import sweep as sweep_mod
from stickslip.simulators.config import SettingsError
from stickslip.simulators.sampling import sample_parameters
from stickslip.traces.dataset import DatasetError, load_dataset

SHORT = PhysicalSettings(length_nm=1.0, pixels=16, velocity_nm_per_s=600.0)


def test_sampling_covers_range_and_respects_eta():
    r = ParameterRange()
    U0, K = sample_parameters(r, 2000, seed=0, lattice_nm=0.246)
    eta = 52.26 * U0 / K
    assert U0.min() >= 0.3 and U0.max() <= 6.0 and K.min() >= 1 and K.max() <= 50
    assert eta.min() >= 1.2 - 1e-9 and eta.max() <= 40 + 1e-9
    assert U0.max() > 5.5 and K.max() > 45 and eta.max() > 35  # the whole region is visited
    U0b, Kb = sample_parameters(r, 2000, seed=0, lattice_nm=0.246)
    np.testing.assert_array_equal(U0, U0b)


def test_infeasible_range_is_reported():
    with pytest.raises(SettingsError, match="no eta"):
        ParameterRange(U0_eV=(0.3, 0.4), K_N_m=(40, 50), eta=(30, 40)).check_feasible(0.246)


def test_sweep_file_contents(tmp_path):
    cfg = SweepConfig(physics=SHORT, n=40, seed=4)
    out = run_sweep(cfg, tmp_path / "s.h5", chunk=16, progress=False)
    ds = load_dataset(out)
    assert ds.force_nN.shape == (40, 16)
    for key in ("U0_eV", "K_N_m", "eta", "F_mean_nN", "temperature_K", "velocity_nm_per_s",
                "lattice_nm", "damping_per_s", "mass_kg", "dt_s", "warmup_nm"):  # fmt: skip
        assert ds.params[key].shape == (40,), key
    np.testing.assert_allclose(ds.params["F_mean_nN"], ds.force_nN.mean(axis=1), rtol=1e-5)
    assert SweepConfig.from_json(ds.attrs["config"]) == cfg
    assert json.loads(ds.attrs["config"])["physics"]["pixels"] == 16
    with h5py.File(out) as f:
        assert f["force_nN"].chunks is not None
    # a row reproduces from (seed, index) alone
    i = 17
    again = simulate(ds.params["U0_eV"][[i]], ds.params["K_N_m"][[i]], SHORT, seed=4, indices=[i])
    np.testing.assert_allclose(again.force_nN[0], ds.force_nN[i], rtol=1e-6)


def test_interrupted_sweep_leaves_no_dataset_and_resumes(tmp_path, monkeypatch):
    cfg = SweepConfig(physics=SHORT, n=40, seed=9)
    out = tmp_path / "s.h5"
    real = sweep_mod.write_rows
    calls = {"n": 0}

    def flaky(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 2:
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(sweep_mod, "write_rows", flaky)
    with pytest.raises(KeyboardInterrupt):
        run_sweep(cfg, out, chunk=16, progress=False)
    assert not out.exists() and sweep_mod.partial_path(out).exists()
    with pytest.raises(DatasetError):
        load_dataset(sweep_mod.partial_path(out))  # incomplete: refused
    monkeypatch.setattr(sweep_mod, "write_rows", real)
    run_sweep(cfg, out, chunk=16, progress=False, resume=True)
    assert out.exists() and not sweep_mod.partial_path(out).exists()
    fresh = run_sweep(cfg, tmp_path / "fresh.h5", chunk=16, progress=False)
    np.testing.assert_array_equal(load_dataset(out).force_nN, load_dataset(fresh).force_nN)


def test_resume_refuses_other_settings(tmp_path):
    out = tmp_path / "s.h5"
    part = sweep_mod.partial_path(out)
    run_sweep(SweepConfig(physics=SHORT, n=20, seed=1), part, progress=False)
    with pytest.raises(DatasetError, match="different settings"):
        run_sweep(SweepConfig(physics=SHORT, n=20, seed=2), out, resume=True, progress=False)
