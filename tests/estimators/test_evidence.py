"""The evidence of visible effects read off a line (stickslip.estimators.evidence)."""

import numpy as np

from stickslip.estimators.evidence import EVIDENCE, line_evidence
from stickslip.simulators import PhysicalSettings, simulate

PERIOD_PX = 0.246 / (11.0 / 512)


def _clean_line() -> np.ndarray:
    return simulate([1.0], [10.0], PhysicalSettings(temperature_K=0.0), seed=1).force_nN[0]


def test_a_clean_stick_slip_line_shows_little_and_effects_show():
    F = _clean_line()
    rng = np.random.default_rng(0)
    x = np.arange(F.size)
    drift = F + 0.5 * np.ptp(F) * x / x[-1]
    spiked = F.copy()
    spiked[200] += 2.0 * np.ptp(F)
    noisy = F + rng.normal(0, 0.02 * np.ptp(F), F.size)
    e = line_evidence([F, drift, spiked, noisy], PERIOD_PX)
    assert e.shape == (4, len(EVIDENCE))
    slow, spikes = e[:, 0], e[:, 1]
    assert slow[1] > slow[0] + 1.5  # a drift is slow, non-periodic content
    assert spikes[2] > spikes[0] + 1.0  # a spike stands far out of the second differences
    # white noise averages out over a period: it is not slow content
    assert slow[3] < slow[1] - 1.0


def test_evidence_has_no_force_scale_of_its_own():
    F = _clean_line()
    rng = np.random.default_rng(1)
    G = F + 0.3 * np.sin(np.arange(F.size) / 40.0) + rng.normal(0, 0.01, F.size)
    e1 = line_evidence([G], PERIOD_PX)
    e2 = line_evidence([10.0 * G + 3.0], PERIOD_PX)
    assert np.allclose(e1, e2, atol=1e-6)
