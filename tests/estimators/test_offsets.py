"""The offset term of the single-line <F> interval: exact coverage of e + o."""

from __future__ import annotations

import numpy as np
import pytest

from stickslip.estimators.calibration import gaussian_z
from stickslip.estimators.offsets import OffsetPrior, coverage, offset_half_width
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
