"""Compiled order statistics: the same values as numpy's, on the inputs that trouble a
selection (ties, sorted runs, digitised lines, NaN)."""

import numpy as np
import pytest
from numba import njit

from stickslip.robust import mad_sigma, median, percentile, select, select_tails, white_sigma


def _cases():
    rng = np.random.default_rng(11)
    out = [rng.normal(size=n) for n in (1, 2, 3, 4, 5, 10, 510, 511, 2000)]
    out += [np.round(rng.normal(size=510) * 2.0) for _ in range(3)]  # digitised: many ties
    out += [np.zeros(510), np.arange(510.0), np.arange(510.0)[::-1].copy(),
            np.r_[np.ones(300), np.zeros(211)], np.tile([1.0, 2.0], 256),
            np.array([np.inf, -np.inf, 1.0, 2.0, 3.0])]  # fmt: skip
    return out


@pytest.mark.parametrize("v", _cases(), ids=lambda v: f"n{v.size}")
def test_median_and_select_are_numpy_s(v):
    before = v.copy()
    assert median(v) == np.median(v)
    for k in {0, v.size // 3, v.size // 2, v.size - 1}:
        assert select(v, k) == np.partition(v, k)[k]
    np.testing.assert_array_equal(v, before)  # the input is not reordered


@njit
def _numba_percentile(v, q):
    return np.percentile(v, q)


@pytest.mark.parametrize("v", _cases(), ids=lambda v: f"n{v.size}")
def test_tails_and_percentiles_are_those_they_replace(v):
    before = v.copy()
    n = v.size
    for lo, hi in {(0, n - 1), (int(0.02 * (n - 1)), int(0.98 * (n - 1))), (n // 3, n // 2)}:
        # both short buffers and, for long tails, the fallback to two selections
        assert select_tails(v, lo, hi) == (select(v, lo), select(v, hi))
    for q in (0.0, 5.0, 25.0, 50.0, 75.0, 95.0, 100.0):
        if np.all(np.isfinite(v)):  # numba's percentile has its own rules for infinities
            assert percentile(v, q) == _numba_percentile(v, q)
    np.testing.assert_array_equal(v, before)


def test_nan_and_empty_inputs():
    assert np.isnan(median(np.array([1.0, np.nan, 2.0])))
    assert np.isnan(median(np.empty(0)))
    assert mad_sigma(np.empty(0)) == 0.0
    assert np.isnan(mad_sigma(np.array([1.0, np.nan, 2.0])))
    assert np.isnan(percentile(np.array([1.0, np.nan, 2.0]), 25.0))
    assert np.isnan(percentile(np.empty(0), 25.0))


def test_mad_sigma_is_the_gaussian_std_and_survives_digitisation():
    rng = np.random.default_rng(5)
    v = rng.normal(0.0, 2.0, 200_000)
    assert mad_sigma(v) == pytest.approx(2.0, rel=0.01)
    # more than half the values equal: the MAD is 0, the mean deviation is not
    d = np.r_[np.zeros(600), rng.normal(0.0, 1.0, 400)]
    assert mad_sigma(d) > 0.0
    assert mad_sigma(d) == pytest.approx(1.2533 * np.mean(np.abs(d - np.median(d))))


def test_white_sigma_is_the_noise_of_a_line_from_its_second_differences():
    rng = np.random.default_rng(8)
    x = np.linspace(0.0, 10.0, 20_000)
    F = 3.0 * x + rng.normal(0.0, 0.5, x.size)  # a straight rise has no second difference
    assert white_sigma(F) == pytest.approx(0.5, rel=0.02)
    assert white_sigma(F) == mad_sigma(np.diff(F, 2)) / np.sqrt(6.0)
    assert white_sigma(F[:2]) == 0.0


def test_selection_with_many_equal_values_keeps_the_partition():
    """Past 64 rounds (many equal values) the selection finishes by three-way partitions:
    the same order statistic as numpy's, with every value left of ``k`` no larger and
    every value right of it no smaller."""
    from stickslip.robust import _select_inplace

    rng = np.random.default_rng(5)
    lines = [np.repeat([2.0, -1.0, 0.5], 300), np.r_[np.zeros(700), rng.normal(size=9)],
             rng.integers(0, 3, 1001).astype(float)]  # fmt: skip
    for v in lines:
        for k in (0, 1, v.size // 3, v.size // 2, v.size - 2, v.size - 1):
            a = v.copy()
            x = _select_inplace(a, k)
            assert x == np.partition(v, k)[k] == a[k]
            assert a[:k].max(initial=-np.inf) <= x <= a[k + 1 :].min(initial=np.inf)
            np.testing.assert_array_equal(np.sort(a), np.sort(v))  # a permutation
