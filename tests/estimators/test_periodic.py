"""Means over exactly one lattice period."""

from __future__ import annotations

import numpy as np

from stickslip.estimators.periodic import period_means, sliding_period_mean


def test_a_pattern_of_the_lattice_period_averages_to_its_mean_wherever_the_window_starts():
    # pixel means of a sawtooth of 11.4 samples per period: exact cells
    P, n, fine = 11.4, 200, 1000
    t = (np.arange(n * fine) + 0.5) / fine  # fine grid in sample units
    saw = ((t / P) % 1.0) - 0.5 + 0.3
    F = saw.reshape(n, fine).mean(axis=1)
    m = period_means(F, P, np.arange(0.0, n - P - 1))
    # what is left comes from the pixels that hold a slip (range 1): a fraction of the
    # ripple a window of a whole number of samples leaves
    rms = float(np.sqrt(np.mean((m - 0.3) ** 2)))
    whole11 = np.convolve(F, np.ones(11) / 11, mode="valid")
    assert rms < 0.006 and np.abs(m - 0.3).max() < 0.03
    assert rms < 0.5 * float(np.sqrt(np.mean((whole11 - 0.3) ** 2)))
    # a smooth periodic pattern of pixel means (range 2) is averaged out to 0.5 %
    smooth = np.sin(2 * np.pi * t / P).reshape(n, fine).mean(axis=1) + 0.3
    assert np.allclose(period_means(smooth, P, np.linspace(0.0, n - P, 97)), 0.3, atol=0.01)
    # a whole number of samples in the window is a plain moving average
    whole = sliding_period_mean(F[None], 12.0)[0]
    assert np.allclose(whole, np.convolve(F, np.ones(12) / 12, mode="valid"))


def test_means_of_many_series_are_those_of_each():
    rng = np.random.default_rng(1)
    F = rng.normal(size=(4, 50))
    starts = np.array([0.0, 3.3, 10.75, 50 - 7.5])
    both = period_means(F, 7.5, starts)
    for b in range(4):
        assert np.allclose(both[b], period_means(F[b], 7.5, starts))
    # against a brute-force integral of the cells
    cells = np.repeat(F[2], 1000)
    for s, m in zip(starts, both[2], strict=True):
        lo, hi = int(round(s * 1000)), int(round((s + 7.5) * 1000))
        assert m == np.float64(cells[lo:hi].mean()) or abs(m - cells[lo:hi].mean()) < 1e-12
