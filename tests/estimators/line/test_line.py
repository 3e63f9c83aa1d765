"""Whole-line models: lattice mapping, inputs, uncertainty outputs, files, training."""

import json

import numpy as np
import pytest
import torch

from stickslip.estimators.calibration import Z68, Z95
from stickslip.estimators.line.ensemble import (
    N_EXPERT,
    LineCNN,
    LineEnsemble,
    LineSpec,
    SpreadClasses,
    expert_inputs,
    gaussian_nll,
    line_inputs,
    map_line,
    predict_lines,
    predict_raw_lines,
)
from stickslip.estimators.line.modelfile import load_line_model, save_line_model
from stickslip.estimators.line.training import (
    TRAIN_EFFECTS,
    TYPICAL_FRACTION,
    LineTrainConfig,
    balanced_scale,
    calibration_set,
    class_fit,
    flat_substrate,
    power_fit,
    train_line_ensemble,
    training_effects,
    validation_set,
)
from stickslip.estimators.offsets import CompressionPrior, OffsetPrior
from stickslip.estimators.window.modelfile import ModelFileError, load_model
from stickslip.simulators import PhysicalSettings, simulate
from stickslip.simulators.instrument import LAB, EffectsMixture
from stickslip.simulators.randomised import RandomisedConfig, make_randomised_set
from stickslip.traces.dataset import load_dataset


def test_lattice_mapping_is_exact_in_the_athermal_limit():
    # (U0, K) on lattice a reads as (U0 a0/a, K a/a0) on a0 once positions are divided
    # by s = a / a0: same forces, same eta
    a0, a, U0, K = 0.246, 0.316, 2.0, 12.0
    s = a / a0
    cold = PhysicalSettings(temperature_K=0.0)
    on_a = simulate([U0], [K], cold.replace(lattice_nm=a, warmup_nm=2.0 * s))
    on_a0 = simulate([U0 / s], [K * s], cold.replace(warmup_nm=2.0))
    spec = LineSpec()
    mapped = map_line(on_a.x_nm, on_a.force_nN[0], a, spec)
    ref = on_a0.force_nN[0, : mapped.size]
    assert mapped.size == pytest.approx(512 / s, abs=2)
    assert np.allclose(on_a.eta, on_a0.eta)
    fmax = np.pi * U0 * 0.1602176634 / a
    diff = np.abs(mapped[2:-2] - ref[2:-2])
    # equal stick branches; a slip may land one pixel apart, so compare robustly
    assert np.median(diff) < 0.01 * fmax
    assert abs(mapped.mean() / ref.mean() - 1) < 0.01
    assert abs(mapped.max() / ref.max() - 1) < 0.01


def test_line_inputs_crop_and_periodic_padding():
    spec = LineSpec(crop=100)
    lines = [np.arange(150.0), np.arange(60.0)]
    X = line_inputs(lines, spec, length=100, rng=np.random.default_rng(0))
    assert X.shape == (2, 2, 100)
    assert torch.allclose(X[1, 0, 60:70] * spec.force_scale_nN, torch.arange(10.0))
    centred = line_inputs([np.arange(150.0)], spec, length=100)
    assert centred[0, 0, 0] * spec.force_scale_nN == 25.0


def _untrained(members=2):
    torch.manual_seed(0)
    return LineEnsemble(members=[LineCNN() for _ in range(members)], spec=LineSpec(),
                        y_mean=np.array([0.0, 0.5, 2.0, 1.5]),
                        y_std=np.array([0.05, 0.8, 0.9, 0.9]))  # fmt: skip


def test_predictions_carry_ordered_intervals_and_map_back():
    ens = _untrained()
    lines = [np.sin(np.linspace(0, 60, 400)) + 2.0 for _ in range(3)]
    p1 = predict_lines(ens, lines, np.full(3, 0.246), np.full(3, 60.0), np.full(3, 2.0))
    p2 = predict_lines(ens, lines, np.full(3, 0.316), np.full(3, 60.0), np.full(3, 2.0))
    for k in ("F_mean_nN", "U0_eV", "K_N_m", "eta"):
        assert np.all(p1.lo95[k] < p1.lo68[k]) and np.all(p1.lo68[k] < p1.values[k])
        assert np.all(p1.values[k] < p1.hi68[k]) and np.all(p1.hi68[k] < p1.hi95[k])
        assert np.all(p1.std[k] > 0)
    # same mapped input: U0 scales with s, K with 1/s (conditioning differs slightly)
    s = 0.316 / 0.246
    assert np.median(p2.values["U0_eV"] / p1.values["U0_eV"]) == pytest.approx(s, rel=0.5)


def test_packed_inference_body_gives_the_plain_body_s_features():
    # the oneDNN-packed body must be the same network as the folded nn.Sequential
    torch.manual_seed(4)
    net = LineCNN()
    net.train()
    net(torch.randn(64, 2, 300), torch.randn(64, 2))  # move the batch-norm statistics
    X, C = torch.randn(40, 2, 333), torch.randn(40, 2)
    plain, packed = net.fused(pack=False), net.fused()
    if not torch.backends.mkldnn.is_available():
        pytest.skip("this torch build has no oneDNN")
    assert packed.packed is not None and plain.packed is None
    with torch.inference_mode():
        a, b = plain.features(X, C), packed.features(X, C)
    torch.testing.assert_close(a, b, rtol=1e-5, atol=1e-5)
    # with gradients on, the copy runs its plain layers (the packed ones have none)
    c = packed.features(X, C)
    assert c.requires_grad
    torch.testing.assert_close(c.detach(), a, rtol=1e-5, atol=1e-5)


def test_raw_lines_on_shared_and_own_axes_predict_as_one_by_one():
    # traces are grouped by axis and lattice and mapped as stacks: same answer as alone
    ens = _untrained()
    rng = np.random.default_rng(8)
    x1 = np.arange(512) * 0.0215
    x2 = np.cumsum(rng.uniform(0.015, 0.03, 450))
    xs = [x1, x1.copy(), x2, x1, x2]
    fs = [np.sin(x / 0.05) + rng.normal(0.0, 0.1, x.size) + 1.0 for x in xs]
    a = np.array([0.246, 0.246, 0.246, 0.3, 0.246])
    together = predict_raw_lines(ens, xs, fs, a, np.full(5, 60.0))
    for i in range(5):
        alone = predict_raw_lines(ens, [xs[i]], [fs[i]], a[i : i + 1], np.full(1, 60.0))
        for k in ("F_mean_nN", "U0_eV", "K_N_m", "eta"):
            np.testing.assert_allclose(together.values[k][i], alone.values[k][0], rtol=1e-5)
            np.testing.assert_allclose(together.hi95[k][i], alone.hi95[k][0], rtol=1e-5)


def test_line_model_file_round_trip_and_damage(tmp_path):
    ens = _untrained()
    path = save_line_model(ens, tmp_path / "m.pt", (16, 32, 48, 64), {}, {}, {"x": 1})
    back = load_line_model(path)
    X = line_inputs([np.linspace(0, 3, 300)], ens.spec)
    C = torch.zeros(1, 2)
    np.testing.assert_allclose(back.predict(X, C)[0], ens.predict(X, C)[0], rtol=1e-6)
    assert back.offset is None
    ens.offset = OffsetPrior(p=0.3, mean_nN=(0.01, 0.4))
    assert load_line_model(save_line_model(ens, tmp_path / "o.pt", (16, 32, 48, 64), {}, {},
                                           {})).offset == ens.offset  # fmt: skip
    # the offset term widens the <F> interval only, and keeps the model's own std apart
    lines = [np.linspace(0, 3, 300)]
    with_off = predict_lines(ens, lines, np.full(1, 0.246), np.full(1, 60.0), np.full(1, 1.5))
    ens.offset = None
    without = predict_lines(ens, lines, np.full(1, 0.246), np.full(1, 60.0), np.full(1, 1.5))
    wide = with_off.hi95["F_mean_nN"] - with_off.lo95["F_mean_nN"]
    narrow = without.hi95["F_mean_nN"] - without.lo95["F_mean_nN"]
    assert np.all(wide > narrow)
    np.testing.assert_allclose(with_off.F_model_std, without.std["F_mean_nN"])
    np.testing.assert_allclose(with_off.hi95["K_N_m"], without.hi95["K_N_m"])
    # the compression term round-trips and moves a positive line's <F> interval up
    ens.compression = CompressionPrior(p=0.3, compression=(0.0, 0.2))
    assert load_line_model(save_line_model(ens, tmp_path / "c.pt", (16, 32, 48, 64), {}, {},
                                           {})).compression == ens.compression  # fmt: skip
    comp = predict_lines(ens, lines, np.full(1, 0.246), np.full(1, 60.0), np.full(1, 1.5),
                         trace_m3_nN=np.full(1, 2.0))  # fmt: skip
    up = comp.hi95["F_mean_nN"] - comp.values["F_mean_nN"]
    down = comp.values["F_mean_nN"] - comp.lo95["F_mean_nN"]
    assert up > down and up > narrow / 2
    np.testing.assert_allclose(comp.F_model_std, without.std["F_mean_nN"])
    # the factor on the model part round-trips and narrows that part only: the model's
    # own std (a trace/retrace pair's) stays
    ens.offset = OffsetPrior()
    full = predict_lines(ens, lines, np.full(1, 0.246), np.full(1, 60.0), np.full(1, 1.5))
    ens.friction_factor = np.array([[0.68, 0.95], [0.5, 0.5]])
    back = load_line_model(save_line_model(ens, tmp_path / "f.pt", (16, 32, 48, 64), {}, {}, {}))
    np.testing.assert_array_equal(back.friction_factor, ens.friction_factor)
    half = predict_lines(ens, lines, np.full(1, 0.246), np.full(1, 60.0), np.full(1, 1.5))
    assert half.hi95["F_mean_nN"] - half.lo95["F_mean_nN"] < \
        full.hi95["F_mean_nN"] - full.lo95["F_mean_nN"]
    np.testing.assert_allclose(half.F_model_std, full.F_model_std)
    np.testing.assert_allclose(half.hi95["U0_eV"], full.hi95["U0_eV"])
    bad = tmp_path / "bad.pt"
    bad.write_bytes(path.read_bytes()[:500])
    with pytest.raises(ModelFileError, match="bad.pt"):
        load_line_model(bad)


@pytest.mark.slow
def test_training_learns_from_randomised_simulations(tmp_path):
    cfg = RandomisedConfig(n=320, seed=5, length_nm=5.0, pixels=232, chunk=320)
    data = load_dataset(make_randomised_set(cfg, tmp_path / "r.h5", progress=False))
    spec = LineSpec(crop=160)
    tc = LineTrainConfig(members=1, epochs=8, batch_size=32, val_fraction=0.2)
    ens, report = train_line_ensemble(data.force_nN.astype(float), data.x_nm, data.params,
                                      tc, spec, progress=False)  # fmt: skip
    # predicting the training mean would give ~100 % relative error on U0 and K here
    assert report["val_rel_rmse"]["log_U0_ref"] < 0.45
    assert report["val_rel_rmse"]["log_K_ref"] < 0.45
    assert 0.85 <= report["val_coverage95"]["log_U0_ref"] <= 1.0


def test_split_beta_nll_weighs_mean_and_variance_gradients_separately():
    g = torch.Generator().manual_seed(0)
    y = torch.randn(64, 4, generator=g)
    mean0 = torch.randn(64, 4, generator=g)
    log_var0 = torch.randn(64, 4, generator=g)

    def grads(beta, beta_var):
        mean, log_var = mean0.clone().requires_grad_(), log_var0.clone().requires_grad_()
        gaussian_nll(mean, log_var, y, beta, beta_var).backward()
        return mean.grad, log_var.grad

    v, sq = log_var0.exp(), (y - mean0) ** 2
    gm, gv = grads(0.5, 0.0)
    # mean: the beta-NLL gradient, var^beta (mean - y) / var; log-variance: plain NLL
    assert torch.allclose(gm, v**0.5 * (mean0 - y) / v / 64, rtol=1e-5, atol=1e-7)
    assert torch.allclose(gv, 0.5 * (1 - sq / v) / 64, rtol=1e-5, atol=1e-7)
    # equal weights take the one-weight path: same gradients as beta-NLL
    gm_same, gv_same = grads(0.5, 0.5)
    assert torch.allclose(gm_same, gm) and not torch.allclose(gv_same, gv)
    assert torch.allclose(gv_same, v**0.5 * 0.5 * (1 - sq / v) / 64, rtol=1e-5, atol=1e-7)


def test_balanced_scale_weighs_strata_equally():
    rng = np.random.default_rng(0)
    # 900 rows of a wide stratum, 100 of a narrow one: an unweighted quantile would be
    # set by the wide rows alone
    z = np.abs(np.concatenate([rng.normal(0, 2.0, 900), rng.normal(0, 0.5, 100)]))[:, None]
    strata = np.repeat([0, 1], [900, 100])
    c = balanced_scale(z, strata)[0]
    cov = [np.mean(z[strata == g, 0] / c <= Z95) for g in (0, 1)]
    assert abs(0.5 * cov[0] + 0.5 * cov[1] - 0.95) < 0.01
    assert cov[1] > cov[0]
    # one stratum: the plain 95 % quantile
    assert np.isclose(balanced_scale(z, np.zeros(1000, int))[0] * Z95,
                      np.quantile(z, 0.95), rtol=0.02)  # fmt: skip


def test_flat_substrate_reads_the_substrate_columns():
    p = {"U0_eV": np.ones(4), "mod_amplitude": np.array([0.0, 0.1, 0.0, 0.0]),
         "defect_count": np.array([0, 0, 2, 0])}  # fmt: skip
    assert flat_substrate(p).tolist() == [True, False, False, True]
    assert flat_substrate({"U0_eV": np.ones(3)}).all()


def test_training_report_separates_pristine_and_corrupted_validation(sawtooth_lines):
    # hand-made sawtooth lines (no simulation): checks the plumbing, not the accuracy
    force, x, params = sawtooth_lines(120, 300, 1)
    cfg = LineTrainConfig(members=1, epochs=1, batch_size=32, val_fraction=0.25, mse_epochs=1,
                          spread_classes=None)  # one scale row: strata weigh equally
    _, report = train_line_ensemble(force, x, params, cfg, LineSpec(crop=200), progress=False)
    # the calibration reads every validation line under calibration_draws draws of effects
    draws = cfg.calibration_draws
    flat_val = report["val_pristine"]["n"] // draws
    assert report["val_corrupted"]["n"] == 30 * draws and 5 <= flat_val <= 25
    assert report["n_val"] == 30 + flat_val
    assert report["n_calibration"] == draws * report["n_val"]
    for stratum in ("val_pristine", "val_corrupted"):
        assert set(report[stratum]["coverage95"]) == {"F_mean_nN", "log_U0_ref", "log_K_ref",
                                                      "log_eta"}  # fmt: skip
    # the two strata weigh equally in the calibration: their coverages average to 95 %
    for t in ("log_U0_ref", "log_K_ref"):
        c = [report[s]["coverage95"][t] for s in ("val_pristine", "val_corrupted")]
        assert abs(np.mean(c) - 0.95) < 0.06



def test_gate_passes_the_expert_through_or_ignores_it():
    torch.manual_seed(0)
    net = LineCNN(n_expert=N_EXPERT).eval()
    X, C = torch.randn(3, 2, 128), torch.zeros(3, 2)
    E = torch.randn(3, N_EXPERT)
    last = net.head[-1]
    t = net.n_targets
    with torch.no_grad():
        last.bias[2 * t :] = 40.0  # gate open: the expert's U0', K', eta are the output
        m_open, _ = net(X, C, E)
        last.bias[2 * t :] = -40.0  # gate shut: the CNN's own estimate
        m_shut, _ = net(X, C, E)
        m_shut2, _ = net(X, C, E + 1.0)  # the expert moves only through the head's input
    torch.testing.assert_close(m_open[:, 1:], E[:, :3])
    torch.testing.assert_close(m_open[:, 0], m_shut[:, 0])  # friction is never gated
    assert not torch.allclose(m_shut[:, 1:], E[:, :3])
    assert not torch.allclose(m_shut, m_shut2)
    with pytest.raises(ValueError, match="expert"):
        net(X, C)


def test_expert_inputs_read_the_paper_mlp_estimate_of_a_clean_line():
    expert = load_model(None)  # the bundled window model (paper's pi MLP)
    U0, K = np.array([1.0, 3.0]), np.array([5.0, 20.0])
    r = simulate(U0, K, seed=3)
    spec = LineSpec()
    y_mean, y_std = np.array([0.0, 0.5, 2.0, 1.5]), np.array([0.05, 0.8, 0.9, 0.9])
    E = expert_inputs(expert, line_inputs(list(r.force_nN), spec), spec, y_mean, y_std).numpy()
    assert E.shape == (2, N_EXPERT)
    U0_e = np.exp(E[:, 0] * y_std[1] + y_mean[1])
    K_e = np.exp(E[:, 1] * y_std[2] + y_mean[2])
    # the expert's own held-out error on such lines is ~1 %
    np.testing.assert_allclose(U0_e, U0, rtol=0.05)
    np.testing.assert_allclose(K_e, K, rtol=0.08)
    # eta implied by the expert's U0', K' on the reference lattice
    eta_e = np.exp(E[:, 2] * y_std[3] + y_mean[3])
    np.testing.assert_allclose(eta_e, r.eta, rtol=0.12)


def test_line_model_with_expert_round_trips(tmp_path):
    torch.manual_seed(0)
    ens = _untrained()
    ens.members = [LineCNN(n_expert=N_EXPERT) for _ in range(2)]
    ens.expert = load_model(None)
    path = save_line_model(ens, tmp_path / "m.pt", (16, 32, 48, 64), {}, {}, {})
    back = load_line_model(path)
    assert back.expert is not None and back.members[0].n_expert == N_EXPERT
    X = line_inputs([np.linspace(0, 3, 300)], ens.spec)
    C = torch.zeros(1, 2)
    np.testing.assert_allclose(back.predict(X, C)[0], ens.predict(X, C)[0], rtol=1e-5)


def test_training_with_an_expert_fits_the_gate_and_the_own_mean():
    # plumbing on hand-made sawtooth lines: the members read the expert, and the model
    # file written afterwards predicts as the trained ensemble does
    rng = np.random.default_rng(2)
    n, x = 64, np.arange(300) * LineSpec().pixel_nm
    K, U0 = rng.uniform(2, 20, n), rng.uniform(0.5, 3, n)
    force = np.array([k * 0.246 * ((x / 0.246) % 1.0) for k in K])
    params = {"U0_eV": U0, "K_N_m": K, "F_mean_nN": force.mean(axis=1),
              "lattice_nm": np.full(n, 0.246), "velocity_nm_per_s": np.full(n, 60.0)}  # fmt: skip
    cfg = LineTrainConfig(members=1, epochs=2, batch_size=16, val_fraction=0.25, mse_epochs=1)
    ens, report = train_line_ensemble(force, x, params, cfg, LineSpec(crop=200), progress=False,
                                      expert=load_model(None))  # fmt: skip
    assert ens.members[0].n_expert == N_EXPERT and ens.expert is not None
    assert np.isfinite(report["history"][-1]["loss"])
    with pytest.raises(ValueError, match="lattice and pixel"):
        train_line_ensemble(force, x, params, cfg, LineSpec(crop=200, pixel_nm=0.03),
                            progress=False, expert=load_model(None))  # fmt: skip


def test_spread_classes_read_noise_level_and_resampling():
    r = simulate(np.array([1.0]), np.array([8.0]), seed=3)
    clean = r.force_nN[0]
    classes = SpreadClasses()
    assert classes.classify(clean[None], [1.0])[0] == 0  # quiet, on the reference lattice
    assert classes.classify(clean[None], [1.2])[0] == 1  # quiet, resampled
    rng = np.random.default_rng(0)
    levels = [classes.classify((clean + rng.normal(0, w, clean.size))[None], [1.0])[0]
              for w in (0.005, 0.05, 0.15)]  # fmt: skip
    # faint noise leaves a line quiet; more moves it to the noisy classes, by level
    # (white noise sigma: median |second difference| = 0.674 sqrt(6) sigma)
    assert levels == [0, 2, 4]


def test_class_fit_gives_each_class_its_coverage():
    rng = np.random.default_rng(2)
    cls = np.repeat([0, 1, 2], [400, 2000, 10])
    # class 0 errors 3x smaller than its predicted spread, class 1 as predicted
    sd = rng.uniform(0.5, 2.0, (cls.size, 2))
    err = np.abs(rng.normal(size=(cls.size, 2))) * sd * np.where(cls == 0, 1 / 3, 1.0)[:, None]
    S, g = class_fit(err, sd, cls, 3, np.zeros(cls.size, int), power=False)
    assert np.all(g == 1.0)
    for c in (0, 1):
        cov = np.mean(err[cls == c] / (S[c] * sd[cls == c]) <= Z95, axis=0)
        assert np.all(np.abs(cov - 0.95) < 0.01)
    assert np.allclose(S[0], 1 / 3, rtol=0.15) and np.allclose(S[1], 1.0, rtol=0.1)
    # a class with too few validation lines gets the pooled scale
    assert np.allclose(S[2], balanced_scale(err / sd, np.zeros(cls.size, int)))


def test_power_fit_finds_a_spread_that_under_reacts():
    rng = np.random.default_rng(4)
    # the networks' spread sd under-reacts: the true error scale is 0.5 sd**1.5
    sd = np.exp(rng.uniform(-3, 0, (20000, 1)))
    err = np.abs(rng.normal(size=sd.shape)) * 0.5 * sd**1.5
    scale, exponent = power_fit(err, sd, np.ones(sd.shape[0]))
    assert exponent[0] == pytest.approx(1.5, abs=0.05)
    assert scale[0] == pytest.approx(0.5, rel=0.15)
    # 95 % coverage at both ends of the spread's range, where a plain scale fails
    cal = scale * sd**exponent
    small, large = sd[:, 0] < np.exp(-2.5), sd[:, 0] > np.exp(-0.5)
    for m in (small, large):
        assert abs(np.mean(err[m] / cal[m] <= Z95) - 0.95) < 0.015
    plain = balanced_scale(err / sd, np.zeros(sd.shape[0], int)) * sd
    assert np.mean(err[small] / plain[small] <= Z95) > 0.99
    assert np.mean(err[large] / plain[large] <= Z95) < 0.90


def test_z_at_reads_the_calibrated_error_distribution():
    ens = _untrained()
    assert ens.z_at(0.68) == pytest.approx([Z68] * 4, rel=1e-5)
    assert ens.z_at(0.95) == pytest.approx([Z95] * 4, rel=1e-5)
    # heavy tails (Student t, 3 dof): the 68 % half-width is narrower than a Gaussian's
    # of the same 95 % width
    from stickslip.estimators.line.ensemble import SHAPE_LEVELS

    z = np.abs(np.random.default_rng(0).standard_t(3, 200000))
    z *= Z95 / np.quantile(z, 0.95)
    ens.shape = np.tile(np.quantile(z, SHAPE_LEVELS), (4, 1))
    assert ens.z_at(0.95) == pytest.approx([Z95] * 4, rel=1e-3)
    assert np.all(ens.z_at(0.68) < 0.85 * Z68)
    assert np.mean(z <= ens.z_at(0.5)[0]) == pytest.approx(0.5, abs=0.005)


def test_spread_head_and_class_calibration_round_trip(tmp_path):
    torch.manual_seed(1)
    ens = LineEnsemble(members=[LineCNN(spread_hidden=16) for _ in range(2)], spec=LineSpec(),
                       y_mean=np.zeros(4), y_std=np.ones(4), classes=SpreadClasses(),
                       scale=np.linspace(0.2, 1.0, 5)[:, None] * np.ones(4))  # fmt: skip
    quiet = np.tile(np.linspace(0, 1, 11), 30)  # a clean sawtooth: quiet
    noisy = quiet + np.random.default_rng(0).normal(0, 0.3, quiet.size)
    X, C = line_inputs([quiet, noisy], ens.spec), torch.zeros(2, 2)
    assert list(ens.line_classes(X, C)) == [0, 4]
    mu, sd = ens.predict_std(X, C)
    ens.scale = np.ones(4)
    _, raw = ens.predict_std(X, C)
    np.testing.assert_allclose(sd / raw, [[0.2] * 4, [1.0] * 4], rtol=1e-5)
    ens.scale = np.linspace(0.2, 1.0, 5)[:, None] * np.ones(4)
    back = load_line_model(save_line_model(ens, tmp_path / "m.pt", (16, 32, 48, 64), {}, {}, {}))
    assert back.classes == ens.classes and back.members[0].spread_hidden == 16
    np.testing.assert_allclose(back.predict_std(X, C)[1], sd, rtol=1e-5)
    assert back.exponent is None and back.shape is None  # a file without them: plain
    # with an exponent and a shape, the calibrated std is scale * raw ** exponent
    ens.exponent = np.full((5, 4), 1.5)
    ens.shape = np.tile(np.linspace(0.1, 3.0, 99), (4, 1))
    np.testing.assert_allclose(ens.predict_std(X, C)[1],
                               ens.scale[[0, 4]] * raw**1.5, rtol=1e-5)  # fmt: skip
    back = load_line_model(save_line_model(ens, tmp_path / "m.pt", (16, 32, 48, 64), {}, {}, {}))
    np.testing.assert_allclose(back.predict_std(X, C)[1], ens.predict_std(X, C)[1], rtol=1e-5)
    np.testing.assert_allclose(back.z_at(0.68), ens.z_at(0.68))


def test_training_prior_mixes_a_typical_instrument_with_the_broad_ranges():
    prior = LineTrainConfig().effects
    assert isinstance(prior, EffectsMixture)
    assert prior.components == (LAB, TRAIN_EFFECTS)
    assert prior.weights == pytest.approx((TYPICAL_FRACTION, 1 - TYPICAL_FRACTION))
    assert training_effects(0.0) is TRAIN_EFFECTS
    # the model file records the whole prior, so a run is reproducible from it
    saved = json.loads(json.dumps(LineTrainConfig().to_dict()))["effects"]
    assert saved["components"][0]["white_nN"] == list(LAB.white_nN)
    assert saved["weights"] == pytest.approx(list(prior.weights))


def test_calibration_set_draws_the_effects_afresh_on_the_validation_lines():
    rng = np.random.default_rng(3)
    n, x = 40, np.arange(300) * LineSpec().pixel_nm
    force = np.array([k * 0.246 * ((x / 0.246) % 1.0) for k in rng.uniform(2, 20, n)])
    params = {"U0_eV": np.ones(n), "lattice_nm": np.full(n, 0.246),
              "velocity_nm_per_s": np.full(n, 60.0), "mod_amplitude": np.full(n, 0.1)}  # fmt: skip
    cfg = LineTrainConfig(calibration_draws=3, clean_fraction=0.0)
    val = np.arange(10)
    first = validation_set(force, x, params, val, cfg, LineSpec())
    cs = calibration_set(first, force, x, params, cfg, LineSpec())
    assert len(cs.lines) == 30 and list(cs.rows) == list(val) * 3
    assert all(a is b for a, b in zip(cs.lines[:10], first.lines, strict=True))  # reused
    again = calibration_set(validation_set(force, x, params, val, cfg, LineSpec()), force, x,
                            params, cfg, LineSpec()).lines  # fmt: skip
    assert all(np.array_equal(a, b) for a, b in zip(cs.lines, again, strict=True))  # seeded
    # each draw corrupts the same clean line differently
    assert not np.allclose(cs.lines[0], cs.lines[10]) and not np.allclose(cs.lines[10],
                                                                           cs.lines[20])


def test_evidence_fit_finds_the_width_that_the_evidence_adds():
    from stickslip.estimators.line.training import evidence_fit

    rng = np.random.default_rng(3)
    n = 20000
    e = rng.uniform(-1.0, 1.0, (n, 2))
    # half-width grows as exp(0.6 e0) with the first evidence; the second says nothing
    err = np.abs(rng.normal(0.0, 1.0, n)) * np.exp(0.6 * e[:, 0])
    b = evidence_fit(np.log(err), e, np.ones(n))
    assert abs(b[1] - 0.6) <= 0.1 and b[2] <= 0.1
    half = np.exp(b[0] + e @ b[1:])
    inside = err <= half
    assert abs(inside.mean() - 0.95) < 0.01
    # coverage holds where the evidence is low and where it is high, not just on average
    assert abs(inside[e[:, 0] < -0.5].mean() - 0.95) < 0.02
    assert abs(inside[e[:, 0] > 0.5].mean() - 0.95) < 0.02


def test_temperature_conditioning_reads_the_temperature_and_round_trips(tmp_path):
    from stickslip.estimators.line.ensemble import conditioning, n_conditions

    spec = LineSpec(condition_temperature=True, temperature_range_K=(250.0, 350.0))
    C = conditioning([0.246, 0.246], [60.0, 60.0], spec, [296.0, 355.2])
    assert C.shape == (2, 3) and np.allclose(C[:, 2].numpy(), [0.0, 0.2], atol=1e-6)
    assert conditioning([0.246], [60.0], LineSpec()).shape == (1, 2)
    assert spec.trained_at(300.0) and not spec.trained_at(360.0)
    assert LineSpec().trained_at(296.5) and not LineSpec().trained_at(300.0)
    torch.manual_seed(0)
    net = LineCNN(channels=(4, 4), n_cond=n_conditions(spec)).eval()
    ens = LineEnsemble(members=[net], spec=spec, y_mean=np.zeros(4), y_std=np.ones(4))
    path = save_line_model(ens, tmp_path / "m.pt", (4, 4), {}, {}, {})
    back = load_line_model(path)
    assert back.spec == spec
    X = line_inputs([np.sin(np.arange(200) / 3.0)], spec)
    cold, hot = (back.predict(X, conditioning([0.246], [60.0], spec, [T]))[0] for T in (250, 350))
    assert not np.allclose(cold, hot)  # the temperature reaches the members


def test_coarse_repixelation_is_what_a_coarser_detector_records():
    from stickslip.estimators.line.training import coarse_factors, pixel_and_map

    cold = PhysicalSettings(temperature_K=0.0, warmup_nm=2.0)
    fine = simulate([1.5], [12.0], cold)
    coarse = simulate([1.5], [12.0], cold.replace(pixels=256))
    spec = LineSpec()
    # each pixel is the mean force over its travel: two fine pixels make one coarse one
    # (up to the time step, which each run adjusts to whole steps per pixel)
    assert np.allclose(pixel_and_map(fine.x_nm, fine.force_nN[0], 0.246, spec, 2.0),
                       map_line(coarse.x_nm, coarse.force_nN[0], 0.246, spec), atol=2e-4)
    rng = np.random.default_rng(0)
    a = np.full(4000, 0.246)
    f = coarse_factors(a, 0.3, rng, spec)
    assert abs(np.mean(f > 1.0) - 0.3) < 0.03 and f.max() <= 0.95 * 4.0 + 1e-9
    assert np.all(coarse_factors(a, 0.0, rng, spec) == 1.0)


def test_median_fit_finds_the_median_line_under_skewed_heavy_tails():
    from stickslip.estimators.line.training import median_fit

    rng = np.random.default_rng(4)
    n = 4000
    u = rng.uniform(-2.0, 2.0, (n, 2))
    # median 0.05 + 0.03 u0, nothing from u1; errors skewed (mean far from median)
    r = 0.05 + 0.03 * u[:, 0] + rng.exponential(0.05, n) - 0.05 * np.log(2.0)
    c = median_fit(r, u, np.ones(n))
    np.testing.assert_allclose(c, [0.05, 0.03, 0.0], atol=0.006)
    # weights count: lines given no weight do not move the fit
    r2, w = r.copy(), np.ones(n)
    r2[:1000], w[:1000] = 5.0, 0.0
    np.testing.assert_allclose(median_fit(r2, u, w), c, atol=0.01)


def test_location_calibration_takes_off_a_bias_that_grows_with_noise(tmp_path):
    from stickslip.estimators.line.training import ValidationSet, calibrate
    from stickslip.estimators.noise import log_noise_ratio

    torch.manual_seed(2)
    ens = LineEnsemble(members=[LineCNN() for _ in range(2)], spec=LineSpec(),
                       y_mean=np.zeros(4), y_std=np.ones(4))  # fmt: skip
    rng = np.random.default_rng(5)
    n, x = 240, np.arange(400) * LineSpec().pixel_nm
    sigma = rng.uniform(0.0, 0.5, n)
    lines = [3.0 * ((x / 0.246) % 1.0) + s * rng.standard_normal(x.size) for s in sigma]
    C = torch.zeros(n, 2)
    mu, sd = ens.predict_std(line_inputs(lines, ens.spec), C)
    noise = log_noise_ratio(np.stack(lines))
    # truths the members read 0.1 high, plus 0.05 per unit of the noise coordinate
    bias = 0.1 + 0.05 * (noise - noise.mean())
    Y = mu - bias[:, None] + rng.normal(0.0, 0.01, (n, 4))
    cs = ValidationSet(lines=lines, C=C, rows=np.arange(n), strata=np.zeros(n, int),
                       observed_mean=np.zeros(n))  # fmt: skip
    Y[:, 0] = mu[:, 0] + rng.normal(0.0, 0.01, n)  # <F>: relative to the line's mean
    fitted, _, _ = calibrate(ens, cs, Y, power=False, evidence=False)
    # K and eta are moved; <F> and U0 are not (LOCATED_TARGETS)
    assert ens.location.shape == (4, 4) and np.all(ens.location[:2] == 0.0)
    err = fitted - Y
    assert np.all(np.abs(np.median(err[:, 2:], axis=0)) < 0.01)
    assert np.all(np.abs(ens.location[2:, 1] - 0.05) < 0.01)  # the noise slope
    np.testing.assert_array_equal(fitted[:, :2], mu[:, :2])
    # predictions take the same shift, and the model file keeps it
    shifted, _ = ens.predict_std(line_inputs(lines, ens.spec), C)
    np.testing.assert_allclose(shifted, fitted, atol=1e-4)
    back = load_line_model(save_line_model(ens, tmp_path / "m.pt", (16, 32, 48, 64), {}, {}, {}))
    np.testing.assert_allclose(back.predict_std(line_inputs(lines, ens.spec), C)[0], shifted,
                               atol=1e-5)  # fmt: skip
    # kept, not refitted, where asked (a stated contact's calibration)
    before = ens.location.copy()
    calibrate(ens, cs, Y + 1.0, power=False, evidence=False, location=False)
    np.testing.assert_array_equal(ens.location, before)
