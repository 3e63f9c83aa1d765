"""The numba kernel against the numpy reference, determinism and random streams."""

import numba
import numpy as np
import pytest

from stickslip.simulators import PhysicalSettings, simulate
from stickslip.simulators.kernel import neg2log_unit, sin_2pi

# short, fast lines: the comparison is between implementations, not of the preset
FAST = PhysicalSettings(velocity_nm_per_s=1500.0, dt_s=2e-8, length_nm=1.5, pixels=24)


def test_polynomial_sine_and_log_match_libm():
    t = np.linspace(-3.7, 4.2, 20001)
    assert np.max(np.abs(np.array([sin_2pi(v) for v in t]) - np.sin(2 * np.pi * t))) < 1e-10
    r = np.array([1, 2**11 + 5, 2**40 + 12345, 2**63 - 1, 2**64 - 1], dtype=np.uint64)
    u = (r | np.uint64(1)).astype(float) * 2.0**-64
    got = np.array([neg2log_unit(v) for v in r])
    assert np.allclose(got, -2 * np.log(u), rtol=1e-9, atol=1e-12)


def test_zero_temperature_kernel_equals_reference():
    # with no noise both integrators are deterministic: they must agree to round-off
    s = FAST.replace(temperature_K=0.0)
    U0, K = np.array([0.5, 2.0, 4.0]), np.array([5.0, 10.0, 30.0])
    a = simulate(U0, K, s, backend="numba").force_nN
    b = simulate(U0, K, s, backend="numpy").force_nN
    assert np.max(np.abs(a - b)) < 1e-6 * np.max(np.abs(b))


def test_augmented_substrate_kernel_equals_reference():
    s = FAST.replace(temperature_K=0.0)
    U0, K = np.array([1.0, 3.0]), np.array([8.0, 20.0])
    mod = (np.array([0.3, 0.2]), np.array([2.0, 3.5]), np.array([0.5, 2.0]))
    dfx = (np.array([[1.2, 2.0], [1.5, 0.0]]), np.array([[0.4, -0.3], [0.5, 0.0]]),
           np.array([[0.2, 0.3], [0.15, 0.2]]))  # fmt: skip
    a = simulate(U0, K, s, modulation=mod, defects=dfx).force_nN
    b = simulate(U0, K, s, modulation=mod, defects=dfx, backend="numpy").force_nN
    plain = simulate(U0, K, s).force_nN
    assert np.max(np.abs(a - b)) < 1e-6 * np.max(np.abs(b))
    assert np.max(np.abs(a - plain)) > 0.05  # the augmentation does change the trace


def test_finite_temperature_statistics_agree():
    # different random streams: compare mean and spread of the force over 96 trajectories
    n = 96
    U0, K = np.full(n, 1.0), np.full(n, 10.0)
    a = simulate(U0, K, FAST, seed=1).force_nN
    b = simulate(U0, K, FAST, seed=2, backend="numpy").force_nN
    ma, mb = a.mean(axis=1), b.mean(axis=1)
    se = np.sqrt(ma.var() / n + mb.var() / n)
    assert abs(ma.mean() - mb.mean()) < 4 * se + 1e-3
    assert abs(a.std() / b.std() - 1) < 0.03


def test_same_seed_same_traces_whatever_threads_or_batches():
    U0 = np.linspace(0.5, 5.0, 40)
    K = np.linspace(5.0, 45.0, 40)[::-1]
    full = simulate(U0, K, FAST, seed=7).force_nN
    numba.set_num_threads(1)
    try:
        one_thread = simulate(U0, K, FAST, seed=7).force_nN
    finally:
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    idx = np.arange(40)
    parts = [simulate(U0[i], K[i], FAST, seed=7, indices=i).force_nN for i in (idx[:13], idx[13:])]
    np.testing.assert_array_equal(full, one_thread)
    np.testing.assert_array_equal(full, np.vstack(parts))
    other_seed = simulate(U0, K, FAST, seed=8).force_nN
    assert np.max(np.abs(full - other_seed)) > 0.01


def test_every_trajectory_has_its_own_stream():
    # flat substrate: the force is pure thermal noise, uncorrelated between trajectories
    n = 32
    f = simulate(np.zeros(n), np.full(n, 10.0), FAST, seed=3).force_nN
    corr = np.corrcoef(f - f.mean(axis=0))
    off = corr[~np.eye(n, dtype=bool)]
    assert abs(off.mean()) < 0.05
    diffs = np.abs(f[:, None, :] - f[None, :, :]).max(axis=2)
    assert np.min(diffs[~np.eye(n, dtype=bool)]) > 0


@pytest.mark.parametrize("bad", [dict(K=-1.0), dict(U0=np.nan)])
def test_bad_parameters_raise(bad):
    from stickslip.simulators import SettingsError

    with pytest.raises(SettingsError):
        simulate([bad.get("U0", 1.0)], [bad.get("K", 10.0)], FAST)


def test_time_step_beyond_the_stability_limit_is_refused_and_one_inside_it_is_finite():
    # BAOAB is stable on a harmonic well only for omega dt < 2: the limit is the
    # integrator's, at the potential's stiffest point, and refusing beyond it loses nothing
    from stickslip.simulators import SettingsError
    from stickslip.simulators.config import STABLE_OMEGA_DT, omega_max_per_s

    U0, K = np.array([0.5, 4.0]), np.array([5.0, 30.0])
    s = FAST.replace(temperature_K=0.0)
    limit = STABLE_OMEGA_DT / float(np.max(omega_max_per_s(U0, K, s.lattice_nm, s.mass_kg)))
    inside = simulate(U0, K, s.replace(dt_s=0.9 * limit), backend="numpy").force_nN
    assert np.all(np.isfinite(inside))
    with pytest.raises(SettingsError, match="stability limit"):
        simulate(U0, K, s.replace(dt_s=1.1 * limit))
    # the barrier's modulation and defects stiffen the potential: the limit sees them
    mod = (np.array([0.0, 3.0]), np.array([2.0, 2.0]), np.array([0.0, 0.0]))
    with pytest.raises(SettingsError, match="stability limit"):
        simulate(U0, K, s.replace(dt_s=0.9 * limit), modulation=mod)


def test_a_sweep_config_beyond_the_stability_limit_is_refused_before_any_run():
    from stickslip.simulators import ParameterRange, SettingsError, SweepConfig

    with pytest.raises(SettingsError, match="stability limit"):
        SweepConfig(physics=PhysicalSettings(dt_s=1e-6), ranges=ParameterRange())
    SweepConfig()  # the default preset's step is well inside
    # narrow defects stiffen the potential the sweep would draw: refused at the preset step
    from stickslip.simulators import SubstrateAugmentation

    sharp = SubstrateAugmentation(defects_per_line=(0, 4), defect_width_nm=(0.002, 0.01))
    with pytest.raises(SettingsError, match="stability limit"):
        SweepConfig(augmentation=sharp)
