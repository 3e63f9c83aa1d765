"""Posterior predictive check: right estimates pass, wrong ones and odd traces are flagged."""

import numpy as np

from stickslip.diagnostics.ppc import posterior_predictive_check
from stickslip.estimators.noise import noise_nN
from stickslip.simulators import simulate


def test_noise_level_is_recovered_on_stick_slip():
    r = simulate([2.0], [15.0], seed=1)
    rng = np.random.default_rng(0)
    noisy = r.force_nN + rng.normal(0, 0.05, r.force_nN.shape)
    # the clean trace has its own thermal jitter; the added noise adds in quadrature
    extra = np.sqrt(noise_nN(noisy)[0] ** 2 - noise_nN(r.force_nN)[0] ** 2)
    assert abs(extra / 0.05 - 1) < 0.25


def test_ppc_passes_truth_and_flags_wrong_or_odd_traces():
    U0 = np.array([1.0, 2.0, 3.0, 2.0])
    K = np.array([10.0, 15.0, 20.0, 15.0])
    r = simulate(U0, K, seed=5)
    F = r.force_nN.copy()
    F[3, 200:] += 1.5  # a domain crossing: the friction level jumps mid-line
    at_truth = posterior_predictive_check(r.x_nm, F, U0, K, seed=2)
    assert not at_truth.flagged[:3].any()
    assert at_truth.flagged[3]
    wrong = posterior_predictive_check(r.x_nm, F, 1.3 * U0, 0.7 * K, seed=2)
    assert wrong.flagged.all()
    assert wrong.replicate_nN.shape == F.shape
