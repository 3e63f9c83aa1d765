"""Windows and the raw / physics-informed input recipes, exactly as specified."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from stickslip.estimators.mapping import resample_mean
from stickslip.estimators.window.features import (
    FeatureError,
    FeatureSpec,
    n_windows,
    processed_slopes,
    window_features,
    windows,
)


def test_windows_are_strided_views():
    f = np.arange(2 * 20, dtype=float).reshape(2, 20)
    w = windows(f, 8, 4)
    assert w.shape == (2, n_windows(20, 8, 4), 8) == (2, 4, 8)
    np.testing.assert_array_equal(w[1, 2], f[1, 8:16])
    assert np.shares_memory(w, f)
    with pytest.raises(FeatureError):
        windows(f, 21, 1)


def test_raw_recipe_is_the_window():
    spec = FeatureSpec(recipe="raw", window=16)
    win = np.random.default_rng(0).normal(size=(3, 16))
    out = window_features(win, spec)
    assert out.shape == (3, 16) and spec.n_inputs == 16
    np.testing.assert_allclose(out, win.astype(np.float32))


def test_pi_recipe_matches_the_paper_definition():
    p, dx, sigma = 12, 0.02, 15.0
    spec = FeatureSpec(recipe="pi", window=p, pixel_nm=dx, sigma_nN_per_nm=sigma)
    win = np.random.default_rng(1).normal(size=(5, p))
    out = window_features(win, spec)
    assert out.shape == (5, 2 * p - 1) == (5, spec.n_inputs)
    np.testing.assert_allclose(out[:, :p], win, rtol=1e-6)
    for row, feats in zip(win, out, strict=True):
        s = np.diff(row) / dx  # finite-difference dF/dx in nN/nm
        r = np.where(s > 0, s, 0.0)  # negative slopes set to zero
        mu = r.mean()
        expected = np.sort(r / (1 + np.exp(-(r - mu) / sigma)))  # sigmoid-weighted, sorted
        np.testing.assert_allclose(feats[p:], expected, rtol=1e-5, atol=1e-6)


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(-50, 50), min_size=4, max_size=40))
def test_processed_slopes_properties(values):
    win = np.asarray(values)
    out = processed_slopes(win, 0.01, 15.0)
    assert out.shape == (win.size - 1,)
    assert np.all(out >= 0)  # rectified
    assert np.all(np.diff(out) >= 0)  # sorted
    # the sigmoid weight is in (0, 1]: never more than the rectified slope itself
    r = np.sort(np.maximum(np.diff(win) / 0.01, 0))
    assert np.all(out <= r + 1e-9)


def test_sigma_controls_the_weighting():
    win = np.array([0.0, 0.1, 0.5, 0.6, 1.6, 1.7])
    sharp = processed_slopes(win, 0.01, 1.0)
    smooth = processed_slopes(win, 0.01, 1e6)
    # a huge sigma weights every slope by 1/2; a small one keeps large slopes, drops small
    r = np.sort(np.maximum(np.diff(win) / 0.01, 0))
    np.testing.assert_allclose(smooth, r / 2, rtol=1e-4)
    assert sharp[-1] == pytest.approx(r[-1]) and sharp[0] < 1e-6


def test_spec_rejects_bad_settings_and_round_trips():
    with pytest.raises(FeatureError, match="recipe"):
        FeatureSpec(recipe="fft")
    with pytest.raises(FeatureError):
        FeatureSpec(window=2)
    spec = FeatureSpec(recipe="raw", window=32, stride=8)
    assert FeatureSpec.from_dict(spec.to_dict()) == spec


def test_resample_mean_is_a_pixel_mean():
    x = np.arange(500) * 0.02
    f = np.sin(x) + 0.1 * x
    # on its own grid: unchanged; on a grid of pixel pairs: the mean of each pair
    np.testing.assert_allclose(resample_mean(x, f, 0.02), f, atol=1e-12)
    np.testing.assert_allclose(resample_mean(x, f, 0.04), 0.5 * (f[0::2] + f[1::2]), atol=1e-12)
    # the integral of the line is kept whatever the new pixel (300 x 0.03 = 450 x 0.02)
    out = resample_mean(x, f, 0.03)
    assert out.size == 333
    np.testing.assert_allclose(out[:300].sum() * 0.03, f[:450].sum() * 0.02, rtol=1e-12)
    # a step between recorded pixels stays a step of the same height
    step = resample_mean(x, np.where(x < 5.0, 0.0, 2.0), 0.05)
    assert set(np.round(step, 9)) <= {0.0, 0.8, 2.0} and step[0] == 0
    assert step[-1] == pytest.approx(2.0)


def test_resample_mean_of_a_stack_is_that_of_each_row():
    rng = np.random.default_rng(3)
    x = np.cumsum(rng.uniform(0.015, 0.025, 400))  # a non-uniform axis (piezo creep)
    F = rng.normal(size=(2, 3, 400))
    out = resample_mean(x, F, 0.03)
    assert out.shape[:2] == (2, 3)
    for i in range(2):
        for j in range(3):
            one = resample_mean(x, F[i, j], 0.03)
            np.testing.assert_allclose(out[i, j], one, rtol=0, atol=1e-12)
            # and the one-line path is numpy's own interpolation of the running integral
            edges = np.append(x, 2 * x[-1] - x[-2])
            cum = np.concatenate([[0.0], np.cumsum(F[i, j] * np.diff(edges))])
            ref = np.diff(np.interp(x[0] + np.arange(one.size + 1) * 0.03, edges, cum)) / 0.03
            np.testing.assert_allclose(one, ref, rtol=0, atol=1e-12)
