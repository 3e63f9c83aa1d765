"""Effect families in the line model's training batches (LineTrainConfig.families)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from stickslip.estimators.line.ensemble import LineSpec
from stickslip.estimators.line.training import (
    LineTrainConfig,
    _prepare_rows,
    corrupt_and_map,
    prepare_batch,
    train_line_ensemble,
    training_families,
)
from stickslip.simulators import effects as fx


@pytest.fixture(scope="module")
def lines(sawtooth_lines):
    """Hand-made sawtooth lines (no simulation) and their params; checks the plumbing."""
    return sawtooth_lines(48, 512, 4, velocities=(30.0, 60.0))


def _batch(lines, config, keep_clean=None, seed=0):
    force, x, params = lines
    rows = np.arange(force.shape[0])
    keep = np.zeros(rows.size, bool) if keep_clean is None else keep_clean
    return _prepare_rows(force, rows, keep, np.random.default_rng(seed), params=params, x_nm=x,
                         spec=LineSpec(crop=None), config=config)  # fmt: skip


def test_default_config_is_unchanged():
    cfg = LineTrainConfig()
    assert cfg.families is None
    d = cfg.to_dict()  # a run without families is described as before the option existed
    assert "families" not in d and "family_fraction" not in d
    assert training_families(d) == (None, 0.0)


def test_families_round_trip_through_the_saved_config():
    prior = fx.NuisancePrior().without("mains").replace("precursor", p=0.7)
    d = json.loads(json.dumps(LineTrainConfig(families=prior, family_fraction=0.4).to_dict()))
    assert training_families(d) == (prior, 0.4)


def test_without_families_the_batches_are_the_detector_effects_ones(lines):
    force, x, params = lines
    X, C, ref = _batch(lines, LineTrainConfig())
    X0, C0, ref0 = prepare_batch(force, params["lattice_nm"], params["velocity_nm_per_s"], x,
                                 LineSpec(crop=None), LineTrainConfig().effects,
                                 np.random.default_rng(0), crop=None,
                                 clean_fraction=LineTrainConfig.clean_fraction,
                                 keep_clean=np.zeros(force.shape[0], bool))  # fmt: skip
    assert np.array_equal(X.numpy(), X0.numpy()) and np.array_equal(C.numpy(), C0.numpy())
    assert np.array_equal(ref, ref0)


def test_families_change_the_batches_and_keep_the_targets_consistent(lines):
    force, x, params = lines
    plain = _batch(lines, LineTrainConfig())
    # precursor alone: the recorded force is the contact force, so the friction target
    # (F_mean_nN - reference) is contact mean - recorded mean = 0 on every family line
    only = fx.NuisancePrior().only("precursor", p=1.0)
    X, C, ref = _batch(lines, LineTrainConfig(families=only, family_fraction=1.0))
    assert not np.allclose(X.numpy(), plain[0].numpy())
    assert np.allclose(ref, params["F_mean_nN"])
    assert np.allclose(C.numpy(), plain[1].numpy())  # no stated conditions: true velocity
    # several families: the reference is the recorded mean shifted by the clean mean
    # minus the contact force's mean (replayed here from the same random stream)
    prior = fx.NuisancePrior().only("precursor", "crosstalk", "detector", p=1.0)
    _, _, ref = _batch(lines, LineTrainConfig(families=prior, family_fraction=1.0))
    rng = np.random.default_rng(0)
    rng.random(force.shape[0])
    corrupt_and_map(force, params["lattice_nm"], x, LineSpec(crop=None),
                    LineTrainConfig().effects, rng, LineTrainConfig.clean_fraction,
                    np.zeros(force.shape[0], bool))  # fmt: skip
    d = fx.draw(prior, force.shape[0], rng, "train")
    F, _ = fx.apply(d, x, force, params["velocity_nm_per_s"], rng)
    contact = fx.contact_force(d, force).mean(axis=1)
    assert np.allclose(ref, F.mean(axis=1) + params["F_mean_nN"] - contact)
    assert np.all(contact < params["F_mean_nN"])  # softening lowers the <F> truth
    # stated conditions: the conditioning reads the stated velocity, within the prior's range
    stated = fx.NuisancePrior().only("stated_conditions", p=1.0)
    _, C, ref = _batch(lines, LineTrainConfig(families=stated, family_fraction=1.0))
    ratio = np.exp(C[:, 1].numpy() - plain[1][:, 1].numpy())
    assert np.all(np.abs(ratio - 1.0) <= 0.15 + 1e-6) and np.any(np.abs(ratio - 1.0) > 0.01)
    assert np.allclose(ref, params["F_mean_nN"])  # nothing else applied: the clean line


def test_pristine_lines_get_no_family(lines):
    force, _, params = lines
    keep = np.arange(force.shape[0]) < 10
    prior = fx.NuisancePrior().only("stated_conditions", "crosstalk", p=1.0)
    X, C, ref = _batch(lines, LineTrainConfig(families=prior, family_fraction=1.0), keep)
    plain = _batch(lines, LineTrainConfig(), keep)
    assert np.allclose(ref[keep], params["F_mean_nN"][keep])
    assert np.allclose(C[keep].numpy(), plain[1][keep].numpy())
    assert not np.allclose(C[~keep].numpy(), plain[1][~keep].numpy())


def test_training_runs_with_families_and_records_them(lines):
    force, x, params = lines
    prior = fx.NuisancePrior()
    cfg = LineTrainConfig(members=1, epochs=1, batch_size=16, val_fraction=0.25, mse_epochs=1,
                          calibration_draws=1, families=prior)  # fmt: skip
    ens, report = train_line_ensemble(force, x, params, cfg, LineSpec(crop=200), progress=False)
    assert len(ens.members) == 1 and np.isfinite(report["val_rmse_F_mean_nN"])
    assert training_families(cfg.to_dict())[0] == prior
