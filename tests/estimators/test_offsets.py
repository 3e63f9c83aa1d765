"""The offset and compression terms of the single-line <F> interval: exact coverage of
e + o (+ d)."""

from __future__ import annotations

import numpy as np
import pytest

from stickslip.estimators.calibration import gaussian_z
from stickslip.estimators.offsets import (
    CompressionPrior,
    OffsetPrior,
    compression_moment,
    coverage,
    fit_friction_factor,
    friction_bounds,
    friction_coverage,
    offset_half_width,
)
from stickslip.simulators import effects as fx


def sample(prior: OffsetPrior, sigma: float, n: int, rng: np.random.Generator) -> np.ndarray:
    """Draws of e + o by brute force, independently of the closed form."""
    has = rng.random(n) < prior.p
    o = rng.uniform(*prior.mean_nN, n) * rng.choice([-1.0, 1.0], n) * has
    return rng.normal(0.0, sigma, n) + o


@pytest.mark.parametrize("level", [0.68, 0.95])
@pytest.mark.parametrize("h", [0.005, 0.1, 0.4, 2.0])
def test_the_widened_interval_covers_its_level_of_model_error_plus_offset(h, level):
    prior = OffsetPrior()
    t = offset_half_width(np.array([h]), level, prior)[0]
    assert h <= t <= h + prior.mean_nN[1]
    draws = sample(prior, h / gaussian_z(level), 400_000, np.random.default_rng(5))
    assert np.mean(np.abs(draws) <= t) == pytest.approx(level, abs=0.003)
    assert coverage(np.array([t]), np.array([h / gaussian_z(level)]), prior)[0] == \
        pytest.approx(level, abs=1e-9)


def test_no_prior_or_no_offsets_leave_the_interval_as_it_is():
    h = np.array([0.01, 0.2, 1.0])
    np.testing.assert_array_equal(offset_half_width(h, 0.95, None), h)
    np.testing.assert_array_equal(offset_half_width(h, 0.95, OffsetPrior(p=0.0)), h)


def test_a_narrow_model_interval_becomes_the_offsets_own_quantile():
    # with a negligible model error the 95 % half-width is where P(|o| > t) = 5 %:
    # 0.5 (b - t) / (b - a) = 0.05 for the default prior
    prior = OffsetPrior(p=0.5, mean_nN=(0.02, 0.5))
    t = offset_half_width(np.array([1e-6]), 0.95, prior)[0]
    assert t == pytest.approx(0.5 - 0.1 * 0.48, abs=1e-4)


def test_the_default_prior_is_the_crosstalk_familys_documented_range():
    c = fx.Crosstalk()
    prior = OffsetPrior.from_family(c)
    assert (prior.p, prior.mean_nN) == (c.p, tuple(c.mean_nN))
    assert OffsetPrior.from_dict(prior.to_dict()) == prior
    assert OffsetPrior.from_family(fx.NuisancePrior().without("crosstalk").crosstalk).p == 0.0


# ------------------------------------------------------------------ compression term
def sample_compression(prior: CompressionPrior, m3: float, n: int, rng: np.random.Generator):
    """Draws of d = c m3 by brute force."""
    has = rng.random(n) < prior.p
    return rng.uniform(*prior.compression, n) * m3 * has


@pytest.mark.parametrize("level", [0.68, 0.95])
@pytest.mark.parametrize(("h", "m3"), [(0.05, 2.0), (0.4, 1.0), (1e-4, 3.0), (0.3, -2.0),
                                       (0.2, 1e-7), (2.0, 0.5)])  # fmt: skip
def test_the_compression_term_gives_an_equal_tailed_interval_of_error_offset_and_loss(h, m3,
                                                                                      level):
    off, comp = OffsetPrior(), CompressionPrior()
    lo, hi = friction_bounds(np.array([h]), level, off, comp, np.array([m3]))
    rng = np.random.default_rng(11)
    n = 400_000
    x = sample(off, h / gaussian_z(level), n, rng) + sample_compression(comp, m3, n, rng)
    tail = (1.0 - level) / 2
    assert np.mean(x < lo[0]) == pytest.approx(tail, abs=0.003)
    assert np.mean(x > hi[0]) == pytest.approx(tail, abs=0.003)
    # a loss of the mean (m3 > 0) moves the interval up: the truth is above the estimate
    if abs(m3) > 0.1:
        assert np.sign(hi[0] + lo[0]) == np.sign(m3)


def test_without_a_compression_term_the_bounds_are_the_offset_interval():
    h = np.array([0.01, 0.2, 1.0])
    t = offset_half_width(h, 0.95, OffsetPrior())
    for comp in (None, CompressionPrior(p=0.0)):
        lo, hi = friction_bounds(h, 0.95, OffsetPrior(), comp, np.ones(3))
        np.testing.assert_allclose(hi, t)
        np.testing.assert_allclose(lo, -t)
    # and with no offsets either, the model's own interval
    lo, hi = friction_bounds(h, 0.95, None, CompressionPrior(), np.zeros(3))
    np.testing.assert_allclose(hi, h, rtol=1e-6)


def test_the_compression_moment_is_the_mean_loss_of_a_cubic_compression():
    f = np.linspace(-0.5, 2.0, 301) + 0.3 * np.sin(np.arange(301))
    M, c = np.abs(f).max(), 0.12
    out = f - c * M * (f / M) ** 3
    assert f.mean() - out.mean() == pytest.approx(c * compression_moment(f), rel=1e-12)
    assert compression_moment(np.zeros(5)) == 0.0
    # a stack of lines gives one moment per line
    rows = np.stack([f, -f, np.zeros_like(f)])
    np.testing.assert_allclose(compression_moment(rows),
                               [compression_moment(f), -compression_moment(f), 0.0])  # fmt: skip


def test_the_default_compression_prior_is_the_saturation_familys_documented_range():
    s = fx.Saturation()
    prior = CompressionPrior.from_family(s)
    assert (prior.p, prior.compression) == (s.p, tuple(s.compression))
    assert CompressionPrior.from_dict(prior.to_dict()) == prior
    assert CompressionPrior.from_family(fx.NuisancePrior().without("saturation").saturation).p == 0


# ------------------------------------------------------------------ the model part's factor
def test_the_coverage_of_a_line_with_a_known_error_is_that_of_the_priors_draws():
    off, comp = OffsetPrior(), CompressionPrior()
    r = np.array([-0.3, 0.0, 0.05, 0.4])
    m3 = np.array([1.0, 2.0, 0.0, -1.5])
    lo, hi = np.array([-0.4, -0.1, -0.5, -0.2]), np.array([0.3, 0.45, 0.5, 0.6])
    got = friction_coverage(r, lo, hi, off, comp, m3)
    rng = np.random.default_rng(3)
    n = 400_000
    for i in range(r.size):
        x = r[i] + sample(off, 0.0, n, rng) + sample_compression(comp, m3[i], n, rng)
        assert got[i] == pytest.approx(np.mean((x >= lo[i]) & (x <= hi[i])), abs=0.003)


def test_gaussian_errors_need_no_factor_and_heavy_tailed_ones_a_narrower_core():
    off = OffsetPrior()
    rng = np.random.default_rng(8)
    n = 40_000
    s = rng.uniform(0.05, 0.4, n)  # each line's own error scale
    gauss = rng.normal(0.0, s)
    f = fit_friction_factor(gauss, lambda q: gaussian_z(q) * s, off, levels=(0.68, 0.95))
    np.testing.assert_allclose(f, 1.0, atol=0.03)

    # heavy tails: 15 % of the errors four times wider; the half-widths are the errors'
    # own quantiles, so the Gaussian of the 95 % one has too wide a core
    def errors(k: int) -> np.ndarray:
        return np.where(rng.random(k) < 0.85, 1.0, 4.0) * rng.standard_normal(k)

    ref = np.abs(errors(400_000))

    def half_width(q: float) -> np.ndarray:
        return np.quantile(ref, q) * s

    (f95,) = fit_friction_factor(errors(n) * s, half_width, off, levels=(0.95,))
    assert f95 < 0.98
    # and it holds on fresh lines: new errors, new offsets drawn from the prior
    fresh = errors(n) * s + sample(off, 0.0, n, rng)

    def covered(factor: float) -> float:
        lo, hi = friction_bounds(factor * half_width(0.95), 0.95, off)
        return float(np.mean((fresh >= lo) & (fresh <= hi)))

    assert covered(f95) == pytest.approx(0.95, abs=0.004)
    assert covered(1.0) > covered(f95)  # without the factor: wider than it needs
