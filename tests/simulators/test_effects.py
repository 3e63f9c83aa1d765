"""Nuisance families: each changes what it should and nothing else, reproducibly, and the
train and eval implementations differ in form but share the documented ranges."""

import json

import numpy as np
import pytest

from stickslip.simulators import effects as E
from stickslip.simulators.instrument import digitise, lowpass, offset_drift

P = 512
X_NM = np.arange(P) * (11.0 / P)
V = 60.0  # nm/s
PIXEL_S = (X_NM[1] - X_NM[0]) / V


def sawtooth(n: int, period_px: float = 11.45, top: float = 2.0) -> np.ndarray:
    """Stick-slip-like lines: linear rises of ``top`` nN, then a slip, phase per line."""
    phase = np.linspace(0.0, 1.0, n, endpoint=False)[:, None]
    return top * (((np.arange(P)[None, :] / period_px) + phase) % 1.0) - 0.4 * top


def run(prior, n=64, impl="train", seed=0, force=None, **kw):
    d = E.draw(prior, n, np.random.default_rng(seed), impl)
    F = sawtooth(n) if force is None else force
    rec: dict = {}
    out, st = E.apply(d, X_NM, F, V, np.random.default_rng(seed + 1), record=rec, **kw)
    return d, F, out, st, rec


def only(family, **changes):
    return E.NuisancePrior().only(family, p=1.0).replace(family, **changes)


# ------------------------------------------------------------------------------ prior
def test_prior_round_trips_and_without_never_applies():
    prior = E.NuisancePrior().replace("mains", amplitude_nN=(0.01, 0.2))
    d = json.loads(json.dumps(prior.to_dict()))
    assert E.NuisancePrior.from_dict(d) == prior
    del d["telegraph"]  # written before the family existed: it was never trained on
    assert E.NuisancePrior.from_dict(d).telegraph.enabled is False
    with pytest.raises(ValueError):
        E.NuisancePrior.from_dict({**prior.to_dict(), "bogus": {}})
    for f in E.FAMILIES:
        for impl in E.IMPLEMENTATIONS:
            dr = E.draw(prior.without(f), 300, np.random.default_rng(1), impl)
            assert not dr.mask(f).any()
    assert set(E.NuisancePrior().only("mains", "piezo").enabled()) == {"mains", "piezo"}


def test_coverage_follows_p_and_the_record_is_per_line():
    d = E.draw(E.NuisancePrior(), 4000, np.random.default_rng(2))
    cov = d.coverage()
    for f in E.FAMILIES:
        assert abs(cov[f] - E.NuisancePrior().family(f).p) < 0.03, f
    i = int(np.flatnonzero(d.mask("mains"))[0])
    assert "mains" in d.families_of(i)
    sub = d.take(np.array([i, i + 1]))
    assert sub.n == 2 and sub.mask("mains")[0]
    assert d.table()["mains.amplitude_nN"].shape == (4000,)


@pytest.mark.parametrize("impl", E.IMPLEMENTATIONS)
def test_reproducible_and_families_do_not_share_random_streams(impl):
    prior = E.NuisancePrior()
    _, F, a, sa, _ = run(prior, 200, impl, seed=3)
    _, _, b, sb, _ = run(prior, 200, impl, seed=3)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(sa.velocity_nm_per_s, sb.velocity_nm_per_s)
    # disabling one family leaves every other family's draws and realisations unchanged
    d_all = E.draw(prior, 200, np.random.default_rng(3), impl)
    d_wo = E.draw(prior.without("mains"), 200, np.random.default_rng(3), impl)
    for f in E.FAMILIES:
        if f != "mains":
            np.testing.assert_array_equal(d_all.mask(f), d_wo.mask(f))
    _, _, c, _, _ = run(prior.without("mains"), 200, impl, seed=3)
    untouched = ~d_all.mask("mains")
    assert untouched.sum() > 50
    np.testing.assert_array_equal(a[untouched], c[untouched])
    assert not np.array_equal(a[~untouched], c[~untouched])


def test_train_and_eval_share_sizes_but_not_forms():
    prior = E.NuisancePrior()
    t = E.draw(prior, 500, np.random.default_rng(4), "train")
    e = E.draw(prior, 500, np.random.default_rng(4), "eval")
    np.testing.assert_array_equal(t.applied, e.applied)
    shared = {"crosstalk": ("mean_nN", "rms_nN"), "mains": ("amplitude_nN", "frequency_Hz"),
              "spikes": ("count", "height_nN"), "piezo": ("warp",), "precursor": ("drop",),
              "cantilever": ("resonance_kHz", "quality"), "gain": ("variation",),
              "saturation": ("compression",), "telegraph": ("amplitude_nN", "switches"),
              "detector": ("white_nN", "pink_nN", "lowpass_px", "drift_nN")}  # fmt: skip
    for f, keys in shared.items():
        for k in keys:
            np.testing.assert_array_equal(t.params[f][k], e.params[f][k], err_msg=f"{f}.{k}")
    F = sawtooth(500)
    a, _ = E.apply(t, X_NM, F, V, np.random.default_rng(5))
    b, _ = E.apply(e, X_NM, F, V, np.random.default_rng(5))
    assert np.all(np.isfinite(a)) and np.all(np.isfinite(b))
    assert np.mean(np.abs(a - b) > 1e-9) > 0.5


# ------------------------------------------------------------------------------ additive
@pytest.mark.parametrize("impl", E.IMPLEMENTATIONS)
@pytest.mark.parametrize("family", ["crosstalk", "mains", "telegraph", "spikes", "detector"])
def test_additive_families_only_add_their_term(family, impl):
    prior = only(family)
    if family == "detector":  # its low-pass and ADC are not additive
        prior = prior.replace("detector", lowpass_px=(0.0, 0.0), bits=0)
    d, F, out, st, rec = run(prior, 64, impl)
    assert d.mask(family).all()
    np.testing.assert_allclose(out - rec[family], F, atol=1e-12)
    assert np.all(np.abs(rec[family]).max(axis=1) > 0)
    np.testing.assert_array_equal(st.velocity_nm_per_s, V)  # conditions untouched


@pytest.mark.parametrize("impl", E.IMPLEMENTATIONS)
def test_crosstalk_has_the_drawn_nonzero_mean_and_does_not_reverse(impl):
    prior = only("crosstalk")
    d = E.draw(prior, 50, np.random.default_rng(6), impl)
    term = E.crosstalk_term(d, X_NM, np.random.default_rng(7))
    m = term.mean(axis=1)
    np.testing.assert_allclose(m, d.params["crosstalk"]["mean_nN"], atol=1e-12)
    assert np.all(np.abs(m) >= prior.crosstalk.mean_nN[0] - 1e-12)
    np.testing.assert_allclose(term.std(axis=1), d.params["crosstalk"]["rms_nN"], rtol=1e-9)
    F = sawtooth(50)  # friction reverses with the scan direction, crosstalk does not
    trace, _ = E.apply(d, X_NM, F, V, np.random.default_rng(8), crosstalk_nN=term)
    retrace, _ = E.apply(d, X_NM, -F, V, np.random.default_rng(9), crosstalk_nN=term)
    np.testing.assert_allclose((trace + retrace) / 2, term, atol=1e-12)
    np.testing.assert_allclose((trace - retrace) / 2, F, atol=1e-12)


@pytest.mark.parametrize("impl", E.IMPLEMENTATIONS)
def test_mains_is_at_the_grid_frequency_in_time_with_the_drawn_rms(impl):
    d, F, out, _, rec = run(only("mains"), 200, impl, seed=10)
    prm = d.params["mains"]
    rms = rec["mains"].std(axis=1)
    # realised rms over a finite line (and, in eval, pixel averaging) within a few per cent
    assert np.median(np.abs(rms / prm["amplitude_nN"] - 1)) < 0.1
    spec = np.abs(np.fft.rfft(rec["mains"], n=8 * P, axis=1))
    f_peak = np.fft.rfftfreq(8 * P, PIXEL_S)[spec.argmax(axis=1)]
    assert np.all(np.abs(f_peak - prm["frequency_Hz"]) < 1.5)
    assert set(np.unique(prm["frequency_Hz"])) == {50.0, 60.0}


def test_spikes_are_isolated_and_eval_heights_have_heavier_tails():
    heights = {}
    for impl in E.IMPLEMENTATIONS:
        d, F, out, _, rec = run(only("spikes", height_nN=(0.5, 0.5)), 1500, impl, seed=11)
        hit = np.abs(rec["spikes"]) > 0
        c = d.params["spikes"]["count"]
        assert np.all(hit.sum(axis=1) <= c * 3) and np.all(hit.sum(axis=1) >= 1)
        # first pixel of each spike: its height
        first = hit & ~np.roll(hit, 1, axis=1)
        heights[impl] = rec["spikes"][first]
    sd = {k: v.std() for k, v in heights.items()}
    assert abs(sd["eval"] / sd["train"] - 1) < 0.15  # same scale (overlaps aside)...
    kurt = {k: np.mean(v**4) / np.mean(v**2) ** 2 for k, v in heights.items()}
    assert kurt["eval"] > kurt["train"] + 1.0  # ...different shape (Laplace vs Gauss)


@pytest.mark.parametrize("impl", E.IMPLEMENTATIONS)
def test_telegraph_jumps_by_the_drawn_amplitude(impl):
    d, F, out, _, rec = run(only("telegraph"), 40, impl, seed=12)
    A = d.params["telegraph"]["amplitude_nN"]
    span = rec["telegraph"].max(axis=1) - rec["telegraph"].min(axis=1)
    has_jump = span > 1e-12
    assert has_jump.mean() > 0.9
    np.testing.assert_allclose(span[has_jump], A[has_jump], rtol=0.05)


# ------------------------------------------------------------------------------ others
@pytest.mark.parametrize("impl", E.IMPLEMENTATIONS)
def test_piezo_warps_x_with_the_drawn_peak_and_keeps_the_values(impl):
    ramp = np.tile(np.arange(P, dtype=float), (100, 1))  # force = support position (px)
    d, _, out, _, _ = run(only("piezo"), 100, impl, seed=13, force=ramp)
    warp = d.params["piezo"]["warp"]
    assert out[:, 0] == pytest.approx(0.0) and out[:, -1] == pytest.approx(P - 1)
    assert np.all(np.diff(out, axis=1) > 0)  # the support still moves forward
    peak = np.abs(out - ramp).max(axis=1) / (P - 1)
    np.testing.assert_allclose(peak, np.abs(warp), atol=2e-3)
    assert np.abs(warp).max() > 0.04
    # on a stick-slip line: the x axis is warped, the force values' distribution kept
    d, F, out, _, _ = run(only("piezo"), 100, impl, seed=14)
    q = np.linspace(5, 95, 19)
    assert np.abs(np.percentile(out, q) - np.percentile(F, q)).max() < 0.05 * np.ptp(F)
    assert np.abs(out - F).max() > 0.5


def test_piezo_numba_warp_is_the_documented_power_law():
    d = E.draw(only("piezo"), 20, np.random.default_rng(15), "train")
    prm = d.params["piezo"]
    pos = E._power_warp(prm["warp"], prm["exponent"], P)
    np.testing.assert_allclose(pos, E.piezo_positions(prm, P, "train"), atol=1e-9)


@pytest.mark.parametrize("impl", E.IMPLEMENTATIONS)
def test_precursor_lowers_each_stick_top_by_the_drawn_drop_only(impl):
    d, F, out, _, _ = run(only("precursor"), 200, impl, seed=16, force=sawtooth(200, 40.0))
    drop = d.params["precursor"]["drop"]
    assert drop.max() > 0.4  # up to strong softening
    np.testing.assert_array_equal(out, E.contact_force(d, F))  # a contact effect: the truth
    rise = F.max(axis=1) - F.min(axis=1)
    # a complete stick segment in the middle of each line: top lowered by drop * rise
    seg = slice(200, 240)
    i = np.arange(200)
    j0 = 200 + np.argmin(F[:, seg], axis=1)  # start of a segment (first pixel after a slip)
    top_out = np.array([out[k, j0[k] : j0[k] + 40].max() for k in i])
    top_in = np.array([F[k, j0[k] : j0[k] + 40].max() for k in i])
    np.testing.assert_allclose(top_in - top_out, drop * rise, rtol=1e-6, atol=1e-12)
    # the slope at the bottom of a stick (small deflection: K) is unchanged
    slope_in = F[i, j0 + 1] - F[i, j0]
    slope_out = out[i, j0 + 1] - out[i, j0]
    np.testing.assert_allclose(slope_out, slope_in, rtol=0.03)


@pytest.mark.parametrize("impl", E.IMPLEMENTATIONS)
def test_cantilever_rings_with_the_drawn_quality_and_keeps_dc(impl):
    n, q, f0T = 3, np.array([10.0, 20.0, 40.0]), 0.05  # 20 px per period
    prior = only("cantilever")
    d = E.draw(prior, n, np.random.default_rng(17), impl)
    prm = d.params["cantilever"]
    prm["quality"][:] = q
    prm["resonance_kHz"][:] = f0T / PIXEL_S / 1e3
    if impl == "eval":
        prm["second_weight"][:] = 0.0
    step = np.tile(np.r_[np.zeros(50), np.ones(P - 50)], (n, 1))
    out, _ = E.apply(d, X_NM, step + 3.0, V, np.random.default_rng(0))
    y = out - 3.0
    assert np.all(np.abs(y[:, :50]) < 1e-12)  # causal, unit DC gain before the step
    assert np.all(y.max(axis=1) > 1.3)  # overshoot: ringing
    for k in range(n):
        r = y[k, 50:] - 1.0
        ext = [j for j in range(1, r.size - 1) if r[j] > r[j - 1] and r[j] >= r[j + 1]]
        a0, a3 = r[ext[0]], r[ext[3]]
        q_est = np.pi * 3 / np.log(a0 / a3)
        assert q_est == pytest.approx(q[k], rel=0.05)
    assert abs(y[:, -20:].mean() - 1.0) < 0.02  # settles to the quasi-static force


def test_cantilever_implementations_agree_where_their_forms_coincide():
    """Exact IIR (train) and quadrature + FFT convolution (eval, second mode off): their
    damping laws differ by the frequency pull sqrt(1 - 1/4Q^2), negligible at high Q, and
    both are near identity when the ringing is far above the pixel rate."""
    q = np.array([3.0, 10.0, 50.0, 100.0])
    step = np.tile(np.r_[np.zeros(50), np.ones(P - 50)], (4, 1))
    for f0T, tol in ((0.05, [0.05, 0.015, 0.003, 0.002]), (0.5, [0.03, 0.01, 0.002, 0.001]),
                     (3.0, [1e-3] * 4), (30.0, [1e-4] * 4)):  # fmt: skip
        out = {}
        for impl in E.IMPLEMENTATIONS:
            d = E.draw(only("cantilever"), 4, np.random.default_rng(0), impl)
            prm = d.params["cantilever"]
            prm["quality"][:] = q
            prm["resonance_kHz"][:] = f0T / PIXEL_S / 1e3
            if impl == "eval":
                prm["second_weight"][:] = 0.0
            out[impl] = E.apply(d, X_NM, step, V, np.random.default_rng(0))[0]
        diff = np.abs(out["train"] - out["eval"]).max(axis=1)
        assert np.all(diff < tol), (f0T, diff)


@pytest.mark.parametrize("impl", E.IMPLEMENTATIONS)
def test_cantilever_resonance_follows_the_series_split(impl):
    d = E.draw(only("cantilever"), 500, np.random.default_rng(18), impl)
    prm = d.params["cantilever"]
    np.testing.assert_allclose(
        prm["resonance_kHz"], prm["free_resonance_kHz"] / np.sqrt(1 - prm["lever_share"])
    )
    F = sawtooth(500) + 1.0
    out, _ = E.apply(d, X_NM, F, V, np.random.default_rng(0))
    # mean of the line (the <F> truth) kept up to the edge of the ringing
    assert np.median(np.abs(out.mean(axis=1) - F.mean(axis=1))) < 0.02


@pytest.mark.parametrize("impl", E.IMPLEMENTATIONS)
def test_saturation_compresses_the_top_by_the_drawn_amount(impl):
    d, F, out, _, rec = run(only("saturation"), 100, impl, seed=19)
    c = d.params["saturation"]["compression"]
    np.testing.assert_allclose(out.max(axis=1), (1 - c) * F.max(axis=1), rtol=1e-6)
    np.testing.assert_allclose(rec["saturation"], out - F, atol=1e-12)  # what it took off
    # the loss of the mean is c m3 (m3 = mean(F^3) / max F^2) to leading order, which
    # sizes the <F> interval's compression term (estimators.offsets)
    m3 = (F**3).mean(axis=1) / (F**2).max(axis=1)
    loss = -rec["saturation"].mean(axis=1)
    k = c > 0.02
    assert np.median(loss[k] / (c[k] * m3[k])) == pytest.approx(1.0, abs=0.35)
    order_in, order_out = np.argsort(F, axis=1), np.argsort(out, axis=1)
    np.testing.assert_array_equal(np.take_along_axis(F, order_in, 1) <= 0,
                                  np.take_along_axis(out, order_out, 1) <= 0)  # fmt: skip
    assert np.all(np.diff(np.take_along_axis(out, order_in, 1), axis=1) >= -1e-12)  # monotone


@pytest.mark.parametrize("impl", E.IMPLEMENTATIONS)
def test_gain_is_multiplicative_with_mean_one(impl):
    d, F, out, _, rec = run(only("gain"), 100, impl, seed=20)
    g = rec["gain"]
    np.testing.assert_allclose(out / g, F, rtol=1e-12)
    np.testing.assert_allclose(np.abs(g - 1).max(axis=1), d.params["gain"]["variation"])
    assert np.all(np.abs(g.mean(axis=1) - 1) < 0.01)


@pytest.mark.parametrize("impl", E.IMPLEMENTATIONS)
def test_stated_conditions_change_only_what_is_told(impl):
    d = E.draw(E.NuisancePrior().only("stated_conditions"), 2000, np.random.default_rng(21), impl)
    F = sawtooth(2000)
    out, st = E.apply(d, X_NM, F, V, np.random.default_rng(0), temperature_K=296.0)
    np.testing.assert_array_equal(out, F)
    on = d.mask("stated_conditions")
    assert 0.4 < on.mean() < 0.6
    rv, rt = st.velocity_nm_per_s / V - 1, st.temperature_K / 296.0 - 1
    assert np.all(rv[~on] == 0) and np.all(rt[~on] == 0)
    for r in (rv[on], rt[on]):
        assert np.abs(r).max() <= 0.15 + 1e-12 and np.abs(r).max() > 0.12
    assert rv[on].min() < -0.1 and rv[on].max() > 0.1


# ------------------------------------------------------------------------------ detector
def test_detector_train_reuses_the_instrument_forms():
    rng = np.random.default_rng(22)
    F = rng.standard_normal((30, P))
    tau = rng.uniform(0, 3, 30)
    tau[0] = 0.0
    np.testing.assert_allclose(E.lowpass_px(F, tau), lowpass(F, tau), atol=1e-12)
    amp = rng.uniform(0, 0.2, 30)
    ref = offset_drift((30, P), amp, np.random.default_rng(1))
    r = np.random.default_rng(1)
    c1, c2 = r.uniform(-1, 1, (2, 30))
    mine = np.zeros((30, P))
    E._add_drift(mine, np.arange(30), c1, c2, r.uniform(-0.5, 0.5, 30), amp)
    np.testing.assert_allclose(mine, ref, atol=1e-12)
    fs = np.full(30, 4.0)
    q = F.copy()
    E._digitise_rows(q, np.arange(30), np.full(30, 8), fs)
    np.testing.assert_array_equal(q, digitise(F, 8, fs))
    pink = E.pink_spectrum_noise((200, P), rng)
    spec = np.abs(np.fft.rfft(pink, axis=1)) ** 2
    assert spec[:, 1:10].mean() > 20 * spec[:, 200:250].mean()


def test_detector_eval_noise_has_the_drawn_levels_in_another_form():
    prior = only("detector", white_nN=(0.05, 0.05), pink_nN=(0.0, 0.0), drift_nN=(0.0, 0.0),
                 lowpass_px=(0.0, 0.0), bits=0)  # fmt: skip
    w = {}
    for impl in E.IMPLEMENTATIONS:
        w[impl] = run(prior, 200, impl, seed=23)[4]["detector"]
        assert w[impl].std() == pytest.approx(0.05, rel=0.03)
    kurt = {k: np.mean(v**4) / np.mean(v**2) ** 2 for k, v in w.items()}
    assert kurt["train"] == pytest.approx(3.0, abs=0.2) and kurt["eval"] > 5.0
    prior = prior.replace("detector", white_nN=(0.0, 0.0), pink_nN=(0.05, 0.05))
    for impl in E.IMPLEMENTATIONS:
        pink = run(prior, 200, impl, seed=24)[4]["detector"]
        np.testing.assert_allclose(pink.std(axis=1), 0.05, rtol=1e-6)
        spec = np.abs(np.fft.rfft(pink, axis=1)) ** 2
        assert spec[:, 1:10].mean() > 20 * spec[:, 200:250].mean(), impl


@pytest.mark.parametrize("impl", E.IMPLEMENTATIONS)
def test_whole_prior_runs_on_a_batch_with_per_line_conditions(impl):
    n = 300
    v = np.random.default_rng(0).choice([30.0, 45.0, 60.0, 90.0], n)
    d = E.draw(E.NuisancePrior(), n, np.random.default_rng(25), impl)
    F = sawtooth(n)
    out, st = E.apply(d, X_NM, F, v, np.random.default_rng(26), temperature_K=300.0)
    assert out.shape == F.shape and np.all(np.isfinite(out))
    assert st.velocity_nm_per_s.shape == (n,) and np.all(st.temperature_K > 250)
    with pytest.raises(ValueError):
        E.apply(d, X_NM[:-1], F, v, np.random.default_rng(0))
    with pytest.raises(ValueError):
        E.draw(E.NuisancePrior(), 3, np.random.default_rng(0), "test")
