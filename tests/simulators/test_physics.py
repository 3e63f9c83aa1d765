"""Physics of the simulator: analytic limits, equipartition, regimes, convergence."""

import numpy as np

from stickslip.simulators import PhysicalSettings, simulate
from stickslip.simulators.kernel import integrate_numba
from stickslip.simulators.lanes import prepare_lanes
from stickslip.units import KB_NN_NM_PER_K, fmax_nN


def test_equipartition_fixed_support_flat_substrate():
    # U0 = 0, support held still: <(x - X)^2> = kB T / K
    n, T, K = 64, 296.0, 10.0
    pixels, per_pixel, steps_between = 40, 25, 200
    dt = 1e-8
    pixel_nm = 1.0
    # a nominal velocity fixes the step layout (per_pixel * steps_between steps per
    # pixel); the support increment is then set to zero
    v = pixel_nm / (per_pixel * steps_between * dt)
    lanes = prepare_lanes(
        U0_eV=np.zeros(n), K_N_m=np.full(n, K), lattice_nm=np.full(n, 0.246),
        velocity_nm_per_s=np.full(n, v), temperature_K=np.full(n, T),
        damping_per_s=np.full(n, 1e7), mass_kg=np.full(n, 1e-12),
        warmup_nm=np.full(n, 20 * v * dt * steps_between), pixel_nm=pixel_nm, pixels=pixels,
        dt_s=dt, seed=11, indices=np.arange(n), samples_per_pixel=per_pixel,
    )  # fmt: skip
    lanes.dX[:] = 0.0
    _, fine_x, fine_F = integrate_numba(lanes, record_fine=True)
    ext2 = (fine_F / K) ** 2  # (X - x)^2 with X = 0
    expected = KB_NN_NM_PER_K * T / K
    assert abs(ext2.mean() / expected - 1) < 0.01
    assert abs(fine_x.mean()) < 0.05 * np.sqrt(expected)


def _fine_trace(U0, K, T=0.0, gamma=1e7, length=1.0, pixels=2000, v=60.0):
    s = PhysicalSettings(temperature_K=T, damping_per_s=gamma, length_nm=length,
                         pixels=pixels, velocity_nm_per_s=v)  # fmt: skip
    return simulate([U0], [K], s, samples_per_pixel=1)


def test_quasistatic_peak_force_and_stick_slope():
    U0, K, a = 1.5, 8.0, 0.246
    r = _fine_trace(U0, K)
    F = r.force_nN[0]
    X = r.support_nm[0]
    fmax = fmax_nN(U0, a)
    eta = r.eta[0]
    dF = np.diff(F)
    drops = np.flatnonzero(dF < -0.2 * fmax)
    # a slip inside a pixel gives two falling pixels: keep the first of each run
    slips = drops[np.r_[True, np.diff(drops) > 1]]
    assert slips.size >= 3
    # each stick phase (between two slips) peaks at F_max
    for s0, s1 in zip(slips[:-1], slips[1:], strict=True):
        assert abs(F[s0 + 2 : s1 + 1].max() / fmax - 1) < 0.02
    # stick slope along the rising branch: K eta c / (1 + eta c), c = sqrt(1 - (F/Fmax)^2)
    slope = dF / np.diff(X)
    Fm = 0.5 * (F[1:] + F[:-1])
    rising = (slope > 0) & (Fm > 0.1 * fmax) & (Fm < 0.85 * fmax)
    c = np.sqrt(1 - (Fm[rising] / fmax) ** 2)
    expected = K * eta * c / (1 + eta * c)
    assert rising.sum() > 100
    assert np.max(np.abs(slope[rising] / expected - 1)) < 0.02
    # past the peak the force falls slightly before the slip (F_slip < F_max)
    s0, s1 = slips[0], slips[1]
    assert F[s1 - 1] < F[s0 + 2 : s1 + 1].max()


def test_smooth_sliding_below_eta_one():
    U0, K = 0.1, 10.0  # eta = 0.52
    r = _fine_trace(U0, K, length=2.0, pixels=1000)
    assert r.eta[0] < 1
    F = r.force_nN[0]
    fmax = fmax_nN(U0, 0.246)
    # no slips: the slope stays within the smooth branch's bound K eta / (1 - eta)
    slope = np.diff(F) / np.diff(r.support_nm[0])
    eta = r.eta[0]
    assert np.max(np.abs(slope)) < 1.05 * K * eta / (1 - eta)
    assert abs(F.mean()) < 0.02 * fmax  # no friction without hysteresis


def test_thermolubricity_friction_falls_with_temperature():
    U0, K = 0.6, 10.0
    # 100 nm/s: a fifth of the steps of 20 nm/s, and the fall is still 600 K: 0.13x of 0 K
    s = PhysicalSettings(length_nm=3.0, pixels=128, velocity_nm_per_s=100.0)
    n = 16
    means = []
    for T in (0.0, 100.0, 296.0, 600.0):
        r = simulate(np.full(n, U0), np.full(n, K), s.replace(temperature_K=T), seed=5)
        means.append(r.force_nN.mean())
    assert all(b < a for a, b in zip(means, means[1:], strict=False))
    assert means[-1] < 0.8 * means[0]


def _slip_sizes(U0, K, gamma):
    r = _fine_trace(U0, K, gamma=gamma, length=3.0, pixels=600)
    x = r.fine_x_nm[0]
    # tip jumps between successive samples, in units of a
    jumps = np.diff(x) / 0.246
    return np.round(jumps[jumps > 0.5])


def test_multiple_slips_at_large_eta_with_low_damping():
    U0, K = 4.0, 10.0  # eta ~ 21
    low = _slip_sizes(U0, K, gamma=2e5)
    high = _slip_sizes(U0, K, gamma=5e7)
    assert low.size > 0 and high.size > 0
    assert np.max(low) >= 2
    assert np.mean(low) > np.mean(high)
    assert np.all(high == 1)


def test_dt_convergence_of_mean_friction():
    # mean friction at dt = 10 ns and 5 ns across the default range (independent noise:
    # compare within the statistical error, and the pooled mean within 0.5 %)
    U0 = np.array([0.8, 1.5, 3.0, 5.0, 2.0])
    K = np.array([8.0, 10.0, 20.0, 40.0, 3.5])
    n = 48
    s = PhysicalSettings(length_nm=3.0, pixels=64)
    Uu, Kk = np.repeat(U0, n), np.repeat(K, n)
    f10 = simulate(Uu, Kk, s, seed=1).force_nN.mean(axis=1).reshape(5, n)
    f5 = simulate(Uu, Kk, s.replace(dt_s=5e-9), seed=2).force_nN.mean(axis=1).reshape(5, n)
    rel = f5.mean(axis=1) / f10.mean(axis=1) - 1
    se = np.sqrt(f10.var(axis=1) / n + f5.var(axis=1) / n) / f10.mean(axis=1)
    assert np.all(np.abs(rel) < np.maximum(0.005, 4 * se)), (rel, se)
    pooled = f5.sum() / f10.sum() - 1
    assert abs(pooled) < 0.005, pooled
