"""Calibration of the line model on the nuisance prior (estimators.line.families)."""

from __future__ import annotations

import copy

import numpy as np
import pytest
import torch

from stickslip.estimators.line.families import (
    FamilyCalibration,
    calibrate_on_families,
    draw_family_lines,
    restate_offsets,
)
from stickslip.estimators.line.modelfile import load_line_model
from stickslip.estimators.offsets import FRICTION_LEVELS, OffsetPrior
from stickslip.simulators import PhysicalSettings, simulate
from stickslip.simulators import effects as fx
from stickslip.simulators.config import ParameterRange
from stickslip.simulators.sampling import sample_parameters
from stickslip.traces.dataset import Dataset
from stickslip.units import eta_from


@pytest.fixture(scope="module")
def clean():
    """Clean paper-preset lines (graphite, 60 nm/s) with their truths; the seed is apart
    from every training, calibration and benchmark pool."""
    n, a, v = 40, 0.246, 60.0
    U0, K = sample_parameters(ParameterRange(eta=(1.5, 20.0)), n, 9071, a)
    res = simulate(U0, K, PhysicalSettings(), seed=9071)
    params = {"U0_eV": U0, "K_N_m": K, "eta": eta_from(U0, K, a),
              "F_mean_nN": res.force_nN.mean(axis=1), "lattice_nm": np.full(n, a),
              "velocity_nm_per_s": np.full(n, v), "temperature_K": np.full(n, 296.0)}  # fmt: skip
    return Dataset(res.force_nN, np.arange(res.force_nN.shape[1]) * PhysicalSettings().pixel_nm,
                   params, {})  # fmt: skip


def test_lines_carry_truths_and_stated_conditions(clean):
    prior = fx.NuisancePrior().replace("stated_conditions", p=1.0).replace("precursor", p=1.0)
    lines = draw_family_lines(clean, prior, seed=3, draws=2)
    d = lines.data
    assert d.n == 2 * clean.n and lines.applied.shape == (d.n, len(fx.FAMILIES))
    np.testing.assert_array_equal(lines.rows, np.tile(np.arange(clean.n), 2))
    # the truths stay the trajectory's; the stated velocity is off by the drawn error
    np.testing.assert_array_equal(d.params["U0_eV"], clean.params["U0_eV"][lines.rows])
    v_true = clean.params["velocity_nm_per_s"][lines.rows]
    err = d.params["velocity_nm_per_s"] / v_true - 1.0
    assert np.all(np.abs(err) <= 0.15 + 1e-12) and np.mean(np.abs(err) > 1e-3) > 0.9
    # <F> truth is the contact force's mean: precursor softening lowers it
    assert np.all(d.params["F_mean_nN"] <= clean.params["F_mean_nN"][lines.rows] + 1e-9)
    assert np.mean(d.params["F_mean_nN"] < clean.params["F_mean_nN"][lines.rows] - 1e-6) > 0.5
    # a family left out of the prior is never applied
    j = fx.FAMILIES.index("crosstalk")
    assert not draw_family_lines(clean, prior.without("crosstalk"), 3).applied[:, j].any()


def test_offsets_are_restated_from_the_documented_prior(clean):
    prior = fx.NuisancePrior().replace("crosstalk", p=1.0)
    lines = draw_family_lines(clean, prior, seed=4, draws=5)
    off = OffsetPrior(p=0.5, mean_nN=(0.1, 0.3))
    out = restate_offsets(lines, off, seed=9)
    new, old = out.data.params["offset_nN"], lines.data.params["offset_nN"]
    # each line moves by exactly the change of its constant offset: the crosstalk's
    # variation along the line and everything else stay
    shift = out.data.force_nN - lines.data.force_nN
    np.testing.assert_allclose(shift, np.broadcast_to((new - old)[:, None], shift.shape),
                               atol=1e-12)  # fmt: skip
    # the new offsets follow the prior: none on about half the lines, else |o| in range
    some = new != 0.0
    assert 0.35 < some.mean() < 0.65
    assert np.all((np.abs(new[some]) >= 0.1) & (np.abs(new[some]) <= 0.3))
    assert 0.3 < np.mean(new[some] > 0) < 0.7
    # the truths are untouched; lines without crosstalk get offsets as well
    np.testing.assert_array_equal(out.data.params["F_mean_nN"], lines.data.params["F_mean_nN"])
    plain = draw_family_lines(clean, prior.without("crosstalk"), seed=4)
    assert np.all(plain.data.params["offset_nN"] == 0.0)
    assert np.any(restate_offsets(plain, off, seed=9).data.params["offset_nN"] != 0.0)


def test_calibration_on_families_refits_only_the_spread(clean):
    shipped = load_line_model(None)
    mild, ens = copy.deepcopy(shipped), copy.deepcopy(shipped)
    calibrate_on_families(mild, clean, FamilyCalibration(
        prior=fx.NuisancePrior().only("gain", p=1.0), seed=11, draws=3))  # fmt: skip
    settings = FamilyCalibration(prior=fx.NuisancePrior().without("mains"), seed=11, draws=3)
    report = calibrate_on_families(ens, clean, settings)
    # the members are untouched, only the spread is refitted
    for a, b in zip(ens.members, shipped.members, strict=True):
        for (k, va), vb in zip(a.state_dict().items(), b.state_dict().values(), strict=True):
            assert np.array_equal(va.numpy(), vb.numpy()), k
    # the broad prior corrupts more than a mild gain variation: wider intervals
    # (the spread's power law makes them compare at the members' typical spread)
    sd = np.array([0.1, 0.2, 0.2, 0.2])
    assert np.median(ens.scale * sd**ens.exponent / (mild.scale * sd**mild.exponent)) > 1.0
    # on its own calibration lines the 95 % intervals hold (a quantile fit)
    cov = report["val_coverage95"]
    assert all(0.85 <= cov[k] <= 1.0 for k in cov), cov
    # per family: the calibration lines that carry it, and only those (mains left out)
    groups = report["val_per_group"]
    assert "mains" not in groups and "gain" in groups
    n_lines = report["n_calibration"]
    assert all(0 < g["n"] < n_lines for g in groups.values())
    assert groups["detector"]["n"] > groups["telegraph"]["n"]  # p 0.8 against 0.2
    assert all(0.5 <= c <= 1.0 for g in groups.values() for c in g["coverage95"].values())
    fc = report["family_calibration"]
    assert "mains" not in fc["families"] and fc["seed"] == 11 and fc["draws"] == 3
    assert fc["n_trajectories"] == clean.n
    # the offset term comes from the documented crosstalk range even where the prior
    # leaves crosstalk out (leave-one-family-out): it is not fitted
    no_xt = copy.deepcopy(shipped)
    calibrate_on_families(no_xt, clean, FamilyCalibration(
        prior=fx.NuisancePrior().without("crosstalk"), seed=11, draws=1))  # fmt: skip
    assert no_xt.offset == ens.offset == OffsetPrior.from_family(fx.Crosstalk())
    assert fc["offset"] == ens.offset.to_dict()
    # the factor on the model's own <F> part is fitted against that same prior, whether
    # or not the lines carry crosstalk (inside the bisection's range: a real fit)
    for e in (ens, no_xt):
        levels, factors = e.friction_factor
        np.testing.assert_allclose(levels, FRICTION_LEVELS)
        assert np.all((factors > 0.21) & (factors < 4.9)), factors


def test_contact_lines_come_in_seeded_chunks_and_join_the_calibration(monkeypatch, tmp_path, clean):
    import stickslip.estimators.line.families as fam

    monkeypatch.setattr(fam, "CONTACT_CHUNK", 2)
    settings = FamilyCalibration(contacts=3, contacts_seed=77, draws=1, training_draws=0)
    lines = fam.contact_lines(settings, tmp_path)
    assert sorted(p.name for p in tmp_path.glob("*.npz")) == ["multi_1_78.npz", "multi_2_77.npz"]
    assert 1 <= lines.n <= 3  # those one PT describes
    assert np.all(lines.params["lattice_nm"] == 0.246)
    ens = copy.deepcopy(load_line_model(None))
    report = calibrate_on_families(ens, clean, settings, lines)
    fc = report["family_calibration"]
    assert fc["contacts"] == 3 and fc["contacts_seed"] == 77
    assert fc["n_contact_lines"] == lines.n
    assert fc["n_trajectories"] == clean.n + lines.n


def test_an_ideal_contact_is_calibrated_on_plain_single_point_lines_only(clean, tmp_path):
    import stickslip.estimators.line.families as fam
    from stickslip.estimators.line.modelfile import save_line_model

    # a third of the trajectories on a modulated substrate, a fifth with defects
    n = clean.n
    params = {**clean.params, "mod_amplitude": np.where(np.arange(n) % 3 == 0, 0.2, 0.0),
              "defect_count": np.where(np.arange(n) % 5 == 1, 2, 0)}  # fmt: skip
    pool = Dataset(clean.force_nN, clean.x_nm, params, {})
    plain = fam.contact_rows("ideal", pool, n_contacts=4)
    assert plain.size == n + 4 and not plain[n:].any()  # contact lines are not ideal
    np.testing.assert_array_equal(plain[:n], (np.arange(n) % 3 != 0) & (np.arange(n) % 5 != 1))
    ens = copy.deepcopy(load_line_model(None))
    settings = FamilyCalibration(seed=12, draws=6, training_draws=6)
    report = calibrate_on_families(ens, pool, settings)
    # every draw of every plain trajectory, and nothing else
    assert report["family_calibration"]["n_lines_ideal"] == plain[:n].sum() * (6 + 6)
    any_state, ideal = ens.calibration_state(), ens.contact_calibrations["ideal"]
    assert set(ideal) == set(any_state)
    assert not np.array_equal(ideal["scale"], any_state["scale"])
    stated = ens.for_contact("ideal")
    assert stated.members is ens.members and np.array_equal(stated.scale, ideal["scale"])
    assert ens.for_contact("any") is ens
    with pytest.raises(ValueError, match="no calibration for the contact 'tip'"):
        ens.for_contact("tip")
    # the model file keeps it
    channels = tuple(m.out_channels for m in ens.members[0].body
                     if isinstance(m, torch.nn.Conv1d))  # fmt: skip
    path = save_line_model(ens, tmp_path / "m.pt", channels, {}, {}, {})
    back = load_line_model(path).contact_calibrations["ideal"]
    for k, v in ideal.items():
        assert (v is None and back[k] is None) or np.array_equal(v, back[k]), k
    # too few lines for a stated contact: none fitted, the count still reported
    few = copy.deepcopy(load_line_model(None))
    rep = calibrate_on_families(few, pool, FamilyCalibration(seed=12, draws=1, training_draws=0))
    assert few.contact_calibrations == {} and rep["family_calibration"]["n_lines_ideal"] > 0
