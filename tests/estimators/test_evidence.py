"""The evidence of visible effects read off a line (stickslip.estimators.evidence)."""

import numpy as np

from stickslip.estimators.evidence import (
    EVIDENCE,
    _edge_kernels,
    line_evidence,
    line_evidence_batch,
    local_evidence,
    local_kernel,
)
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


# ---------------------------------------------------------------------------- local anomaly


def _defect_lines() -> tuple[np.ndarray, np.ndarray]:
    """Two T = 0 lines (U0 1.5 eV, K 5 N/m) without and with a Gaussian defect (barrier
    +100 % of U0, 0.6 nm wide) at 6.5 nm and at 9 nm of the substrate."""
    s = PhysicalSettings(temperature_K=0.0)
    clean = simulate([1.5] * 2, [5.0] * 2, s, seed=1).force_nN
    defects = (np.array([[6.5, 0.0], [9.0, 0.0]]), np.array([[1.0, 0.0]] * 2),
               np.array([[0.6, 0.6]] * 2))  # fmt: skip
    return clean, simulate([1.5] * 2, [5.0] * 2, s, seed=1, defects=defects).force_nN


def test_a_defect_shows_as_a_local_anomaly_and_a_drift_does_not():
    clean, defect = _defect_lines()
    F = clean[0]
    x = np.arange(F.size) / (F.size - 1)
    ptp = np.ptp(F)
    walk = np.cumsum(np.random.default_rng(3).normal(size=F.size))
    walk = (walk - walk.mean()) / walk.std()
    e = local_evidence([F, defect[0], defect[1], F + ptp * (0.3 * (x - 0.5) ** 2 + 0.2 * x),
                        F + 0.05 * ptp * walk], PERIOD_PX)  # fmt: skip
    assert e.shape == (5,)
    # the same line with a defect, wherever it lies, stands far above the line without
    assert e[1] > e[0] + 4.0 and e[2] > e[0] + 4.0
    # a drift of offset, slope and curvature (30 % of the stick-slip amplitude) adds
    # nothing; a random-walk crosstalk of 5 % of it adds less than a defect
    assert abs(e[3] - e[0]) < 0.1
    assert e[4] < min(e[1], e[2]) - 1.0
    # the slow evidence alone does not tell the defect from that crosstalk
    slow = line_evidence([defect[0], F + 0.05 * ptp * walk], PERIOD_PX)[:, 0]
    assert slow[0] - slow[1] < e[1] - e[4]


def test_local_evidence_has_no_force_scale_and_reads_lines_of_any_length():
    _, defect = _defect_lines()
    G = defect[0] + np.random.default_rng(2).normal(0, 0.01, defect.shape[1])
    assert np.allclose(local_evidence([G], PERIOD_PX), local_evidence([10.0 * G + 3.0],
                                                                      PERIOD_PX), atol=1e-6)
    # lines of several lengths, one at a time or together; shorter than the filter
    # (about 2 x 3 x 3 periods) or than two periods
    lines = [G, G[:300], G[50:150], G[:20], defect[1]]
    together = local_evidence(lines, PERIOD_PX)
    alone = np.array([local_evidence([f], PERIOD_PX)[0] for f in lines])
    assert np.allclose(together, alone, rtol=1e-9, atol=1e-9)
    assert together[3] == 0.0 and np.isfinite(together).all()
    # the filter is blind to an offset, a slope and a curvature, also cut at the ends
    k = local_kernel(3 * PERIOD_PX)
    t = np.arange(k.size) - k.size // 2
    assert abs(np.sum(k * k) - 1.0) < 1e-9
    assert max(abs(np.sum(k)), abs(np.sum(k * t)), abs(np.sum(k * t * t))) < 1e-6
    edges = _edge_kernels(3 * PERIOD_PX, 500, 1.0)
    r = np.arange(edges.shape[0])
    for p in (0, 1, 2):
        assert np.abs((r ** p) @ edges).max() < 1e-6 * max(1, r.max() ** p)
