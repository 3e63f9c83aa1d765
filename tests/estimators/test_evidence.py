"""The evidence of visible effects read off a line (stickslip.estimators.evidence)."""

import numpy as np

from stickslip.estimators.evidence import EVIDENCE, line_evidence, line_evidence_batch
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


def test_the_batch_reads_the_same_evidence_as_line_by_line():
    rng = np.random.default_rng(4249)
    F = _clean_line()
    x = np.arange(F.size)
    lines = np.stack([F, F + 0.3 * x / x[-1], F + rng.normal(0, 0.05, F.size),
                      rng.normal(0, 1.0, F.size), np.full(F.size, 2.0)])  # fmt: skip
    lines[2, 100] += 3.0
    for period in (PERIOD_PX, 7.3, 20.0):
        want = line_evidence(list(lines), period)
        assert np.allclose(line_evidence_batch(lines, period), want, rtol=1e-9, atol=1e-9)
    # lines too short to read: zeros, as line by line
    assert (line_evidence_batch(lines[:, :20], PERIOD_PX) == 0).all()
    assert line_evidence_batch(np.empty((0, 300)), PERIOD_PX).shape == (0, len(EVIDENCE))
