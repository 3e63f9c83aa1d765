"""Spring-block stick-slip simulator: exact sticks, analytic Coulomb slips, limits."""

import dataclasses
import math

import numpy as np
import pytest

from stickslip.simulators.spring_block import (
    Coulomb,
    RateState,
    SpringBlockConfig,
    VelocityWeakening,
    coulomb_slip_time_s,
    simulate_spring_block,
)

K, M = 1000.0, 0.03  # N/m, kg: w = 182.6 rad/s
COULOMB = Coulomb(mu_static=0.4, mu_dynamic=0.3, normal_force_N=0.3)  # F_s 0.12, F_d 0.09 N
DELTA = COULOMB.static_N - COULOMB.dynamic_N


def _cfg(law=COULOMB, v=1e-4, fs=20000.0, n=60000, **kw) -> SpringBlockConfig:
    return SpringBlockConfig(k_N_per_m=K, mass_kg=M, velocity_m_per_s=v, sample_rate_Hz=fs,
                             n_samples=n, law=law, **kw)  # fmt: skip


def _at_rest(line) -> np.ndarray:
    """Samples whose whole interval lies between the end of a slip and the next start."""
    dt = 1.0 / line.config.sample_rate_Hz
    ends = line.slip_starts_s + line.slip_durations_s
    lo, hi = line.t_s - 0.5 * dt, line.t_s + 0.5 * dt
    ok = np.zeros(line.t_s.size, bool)
    for e, s in zip(ends[:-1], line.slip_starts_s[1:], strict=True):
        ok |= (lo >= e) & (hi <= s)
    return ok


LAWS = [
    COULOMB,
    VelocityWeakening(0.4, 0.3, velocity_scale_m_per_s=2e-3, normal_force_N=0.3),
    RateState(mu0=0.3, a=0.01, b=0.03, velocity_cutoff_m_per_s=1e-6, state_cutoff_s=1e-3,
              length_m=1e-6, normal_force_N=0.3),  # fmt: skip
]


@pytest.mark.parametrize("law", LAWS, ids=["coulomb", "weakening", "rate-state"])
@pytest.mark.parametrize("oversample", [1, 4])
def test_stick_slope_is_k_exactly(law, oversample):
    line = simulate_spring_block(_cfg(law, v=3e-4, oversample=oversample))
    rest = _at_rest(line)
    pair = rest[:-1] & rest[1:]
    assert line.n_slips >= 3 and pair.sum() > 1000
    slope = np.diff(line.force_N)[pair] / np.diff(line.X_m)[pair]
    np.testing.assert_allclose(slope, K, rtol=1e-7)
    assert np.all(line.stuck[rest] == 1.0)
    # and nowhere steeper than k: the slider never moves backwards here
    assert np.max(np.diff(line.force_N) / np.diff(line.X_m)) <= K * (1 + 1e-7)


def test_coulomb_drop_and_duration_in_the_slow_limit():
    # v / (Delta w / k) = 0.002: the drive is negligible during a slip
    line = simulate_spring_block(_cfg(v=1e-5, fs=5000.0, n=100000, lead_s=1.0))
    assert line.n_slips >= 3
    drops = line.slip_drops_N[np.isfinite(line.slip_drops_N)]
    np.testing.assert_allclose(drops, 2 * DELTA, rtol=1e-9)
    dur = line.slip_durations_s[np.isfinite(line.slip_durations_s)]
    np.testing.assert_allclose(dur, math.pi * math.sqrt(M / K), rtol=2e-3)
    # the recorded extremes: the peak overshoots the static threshold only by the drive's
    # share of the oscillation's amplitude, the trough is at 2 F_d - F_s
    w = math.sqrt(K / M)
    amp = math.hypot(DELTA / K, line.config.velocity_m_per_s / w)
    assert line.force_N.max() <= (COULOMB.dynamic_N + K * amp) * (1 + 1e-12)
    assert line.force_N.max() > COULOMB.static_N * (1 - 1e-4)
    assert line.force_N.min() >= (2 * COULOMB.dynamic_N - COULOMB.static_N) * (1 - 1e-6)
    # energy: the spring's elastic energy released in a slip is the work of F_d over the
    # slip distance drop / k
    Fs, Fe = COULOMB.static_N, COULOMB.static_N - 2 * DELTA
    assert (Fs**2 - Fe**2) / (2 * K) == pytest.approx(COULOMB.dynamic_N * 2 * DELTA / K)


def test_coulomb_finite_velocity_matches_closed_form():
    cfg = _cfg(v=5e-3, n=100000)
    line = simulate_spring_block(cfg)
    dur = line.slip_durations_s[np.isfinite(line.slip_durations_s)]
    np.testing.assert_allclose(dur, coulomb_slip_time_s(cfg), rtol=1e-9)
    assert coulomb_slip_time_s(cfg) > 1.2 * math.pi * math.sqrt(M / K)
    # undamped: the drop is 2 (F_s - F_d) at any drive velocity
    np.testing.assert_allclose(line.slip_drops_N[np.isfinite(line.slip_drops_N)], 2 * DELTA,
                               rtol=1e-9)  # fmt: skip
    # time at rest: stick 2 Delta / (k v) per cycle
    t_stick = 2 * DELTA / (K * cfg.velocity_m_per_s)
    expect = t_stick / (t_stick + coulomb_slip_time_s(cfg))
    assert line.rest_fraction == pytest.approx(expect, abs=0.01)
    assert line.stuck_fraction >= line.rest_fraction


def test_damped_coulomb_drop():
    zeta = 0.1
    c = 2 * zeta * math.sqrt(K * M)
    line = simulate_spring_block(_cfg(v=1e-5, fs=5000.0, n=100000, lead_s=1.0,
                                      damping_N_s_per_m=c))
    decay = math.exp(-math.pi * zeta / math.sqrt(1 - zeta**2))
    drops = line.slip_drops_N[np.isfinite(line.slip_drops_N)]
    assert drops.size >= 3
    np.testing.assert_allclose(drops, DELTA * (1 + decay), rtol=2e-3)
    assert drops.max() < 2 * DELTA * 0.9


def test_regimes_from_drive_velocity():
    w = math.sqrt(K / M)
    v_star = DELTA * w / K  # slip velocity scale, 0.0055 m/s
    slow = simulate_spring_block(_cfg(v=0.01 * v_star, n=40000))
    fast = simulate_spring_block(_cfg(v=30 * v_star, n=40000))
    assert slow.stuck_fraction > 0.95
    assert fast.stuck_fraction < 0.1 and fast.n_slips > 30
    # per-sample flags agree with the time fraction
    assert abs(fast.stuck.mean() - fast.stuck_fraction) < 0.01


def test_weakening_tends_to_coulomb_and_never_drops_more():
    w = math.sqrt(K / M)
    v_star = DELTA * w / K
    sharp = VelocityWeakening(0.4, 0.3, velocity_scale_m_per_s=1e-3 * v_star, normal_force_N=0.3)
    soft = VelocityWeakening(0.4, 0.3, velocity_scale_m_per_s=0.3 * v_star, normal_force_N=0.3)
    d_sharp = simulate_spring_block(_cfg(sharp, v=1e-4, n=40000)).median_drop_N
    d_soft = simulate_spring_block(_cfg(soft, v=1e-4, n=40000)).median_drop_N
    assert d_sharp == pytest.approx(2 * DELTA, rel=0.02)
    # friction at least F_d during the slip: the spring cannot give back more than 2 Delta
    assert 0 < d_soft < d_sharp <= 2 * DELTA * (1 + 1e-6)


def test_rate_state_static_friction_ages():
    law = LAWS[2]
    peaks = []
    for v in (3e-5, 3e-4):
        line = simulate_spring_block(_cfg(law, v=v, fs=2000.0, n=30000))
        assert line.n_slips >= 3
        peaks.append(line.force_N.max())
    # longer sticks at the slower drive: a higher static threshold (log aging)
    assert peaks[0] > peaks[1] * 1.02


def test_strength_spread_scatters_drops_and_is_seeded():
    a = simulate_spring_block(_cfg(v=1e-3, n=60000, strength_spread=0.2, seed=5))
    b = simulate_spring_block(_cfg(v=1e-3, n=60000, strength_spread=0.2, seed=5))
    c = simulate_spring_block(_cfg(v=1e-3, n=60000, strength_spread=0.2, seed=6))
    np.testing.assert_array_equal(a.force_N, b.force_N)
    assert not np.array_equal(a.force_N, c.force_N)
    d = a.slip_drops_N[np.isfinite(a.slip_drops_N)]
    assert d.std() / d.mean() > 0.05


def test_config_round_trip_and_checks():
    for law in LAWS:
        cfg = _cfg(law, oversample=3, strength_spread=0.1, seed=9)
        assert SpringBlockConfig.from_dict(cfg.to_dict()) == cfg
    with pytest.raises(ValueError):
        simulate_spring_block(_cfg(Coulomb(0.3, 0.4, 1.0)))
    with pytest.raises(ValueError):
        simulate_spring_block(dataclasses.replace(_cfg(), damping_N_s_per_m=3 * math.sqrt(K * M)))
