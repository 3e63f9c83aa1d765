"""Instrument effects: each does what it says, and only that."""

import numpy as np
import pytest

from stickslip.simulators import simulate
from stickslip.simulators.instrument import (
    LAB,
    EffectsMixture,
    InstrumentEffects,
    apply_instrument,
    digitise,
    draw_instrument,
    lowpass,
    offset_drift,
    pink_noise,
    precursor_softening,
    white_noise,
)


def test_noises_have_requested_level_and_colour():
    rng = np.random.default_rng(0)
    w = white_noise((200, 512), np.full(200, 0.05), rng)
    p = pink_noise((200, 512), np.full(200, 0.05), rng)
    assert abs(w.std() / 0.05 - 1) < 0.02 and abs(p.std() / 0.05 - 1) < 0.02
    spec = np.abs(np.fft.rfft(p, axis=1)) ** 2
    low, high = spec[:, 1:10].mean(), spec[:, 200:250].mean()
    assert low > 20 * high  # 1/f: power concentrated at low frequency
    spec_w = np.abs(np.fft.rfft(w, axis=1)) ** 2
    assert 0.5 < spec_w[:, 1:10].mean() / spec_w[:, 200:250].mean() < 2


def test_lowpass_smears_a_step_over_tau_pixels():
    step = np.r_[np.zeros(50), np.ones(50)][None, :]
    out = lowpass(step, np.array([4.0]))
    # first-order response: 1 - exp(-k/tau) after k pixels
    assert abs(out[0, 53] - (1 - np.exp(-4 / 4.0))) < 1e-9
    assert np.array_equal(lowpass(step, np.array([0.0])), step)


def test_drift_digitise_and_softening():
    rng = np.random.default_rng(1)
    d = offset_drift((100, 512), np.full(100, 0.1), rng)
    assert np.abs(d).max() <= 0.15 + 1e-12 and np.abs(np.diff(d, axis=1)).max() < 0.002
    q = digitise(np.linspace(-1, 1, 1000)[None, :], 4, np.array([1.0]))
    assert np.unique(q).size == 16 and np.abs(q).max() < 1
    r = simulate([2.0], [10.0], seed=3)
    soft = precursor_softening(r.force_nN, np.array([0.5]))
    assert soft.max() < r.force_nN.max() and soft.min() >= r.force_nN.min() - 1e-9
    assert np.array_equal(precursor_softening(r.force_nN, np.array([0.0])), r.force_nN)


def test_lab_chain_is_reproducible_and_keeps_the_mean_near():
    r = simulate([2.0, 4.0], [10.0, 25.0], seed=4)
    a, va = apply_instrument(r.force_nN, LAB, np.random.default_rng(9))
    b, _ = apply_instrument(r.force_nN, LAB, np.random.default_rng(9))
    np.testing.assert_array_equal(a, b)
    assert set(va) == {"white_nN", "pink_nN", "lowpass_px", "drift_nN", "softening"}
    assert np.all(np.abs(a.mean(axis=1) - r.force_nN.mean(axis=1)) < 0.5)


def test_mixture_draws_each_trace_from_one_component_in_proportion():
    broad = InstrumentEffects(white_nN=(0.1, 0.2), lowpass_px=(2.0, 3.0), bits=16)
    mix = EffectsMixture((LAB, broad), (0.3, 0.7))
    v = draw_instrument(mix, 20000, np.random.default_rng(3))
    in_lab = (v["white_nN"] <= LAB.white_nN[1]) & (v["white_nN"] >= LAB.white_nN[0])
    in_broad = v["white_nN"] >= 0.1
    assert np.all(in_lab ^ in_broad)  # the two white ranges do not overlap
    # every effect of a trace comes from the component its white noise came from
    assert np.all(v["lowpass_px"][in_lab] <= LAB.lowpass_px[1])
    assert np.all(v["lowpass_px"][in_broad] >= 2.0)
    assert np.all(v["pink_nN"][in_broad] == 0.0) and np.any(v["pink_nN"][in_lab] > 0)
    assert abs(in_lab.mean() - 0.3) < 0.015
    F, _ = apply_instrument(np.zeros((4, 64)), mix, np.random.default_rng(0))
    assert F.shape == (4, 64) and np.all(np.isfinite(F))


def test_mixture_rejects_bad_weights_and_mixed_resolutions():
    for comps, w in (((LAB,), (0.5, 0.5)), ((LAB, LAB), (0.7, 0.7)),
                     ((LAB, LAB.replace(bits=12)), (0.5, 0.5))):  # fmt: skip
        with pytest.raises(ValueError):
            EffectsMixture(comps, w)
