"""Friction against velocity: the thermally activated PT law, on synthetic and simulated data.

The simulated series (``data/velocity_series_u1_k3.csv``) is the PT paper preset at
U0 = 1 eV, K = 3 N/m (eta = 17), 296 K: 32 lines of 2 nm at each of 13 velocities, a
quarter decade apart from 10 to 10^4 nm/s, labelled by the classical estimator. It is
cached because the slow velocities cost minutes; ``test_cached_series_is_reproducible``
(slow) regenerates it.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest

from stickslip.diagnostics import velocity as vel
from stickslip.estimators.classical.estimator import U0, estimate_array
from stickslip.units import fmax_nN

DATA = Path(__file__).parent / "data" / "velocity_series_u1_k3.csv"
U0_TRUE, K_TRUE, A = 1.0, 3.0, 0.246
F_MAX = float(fmax_nN(U0_TRUE, A))  # 2.046 nN
VELOCITIES = np.round(10 ** (1 + np.arange(13) / 4), 2)


def _series() -> dict[str, np.ndarray]:
    lines = [ln for ln in DATA.read_text().splitlines() if not ln.startswith("#")]
    rows = list(csv.DictReader(lines))
    return {k: np.array([float(r[k]) if r[k] else np.nan for r in rows]) for k in rows[0]}


def _groups(s: dict[str, np.ndarray]) -> vel.VelocityGroups:
    return vel.group_by_velocity(s["velocity_nm_per_s"], s["F_peak_nN"],
                                 vel.line_sem(s["F_peak_nN_std"], s["n_slips"]))


def _window(g: vel.VelocityGroups, lo: float, hi: float) -> vel.VelocityFit:
    m = (g.velocity_nm_per_s >= lo * 0.999) & (g.velocity_nm_per_s <= hi * 1.001)
    return vel.fit_thermal_law(g.velocity_nm_per_s[m], g.mean[m], g.sem[m], 296.0)


def test_law_shape_and_washboard_beta():
    v = np.array([1.0, 10.0, 100.0, 1e3])
    F = vel.thermal_law(v, 2.0, 0.2, 100.0)
    assert F[2] == F[3] == 2.0  # athermal above v_c
    assert F[0] == pytest.approx(2.0 - 0.2 * math.log(100.0) ** (2 / 3))
    # beta = 3 pi sqrt(F_c) / (2 sqrt(2) a): 19.4 nN^0.5/nm for F_max of 1 eV on graphite
    assert vel.washboard_beta(F_MAX, A) == pytest.approx(19.376, rel=1e-3)


def test_fit_recovers_synthetic_parameters_within_uncertainties():
    rng = np.random.default_rng(3)
    Fc, B, vc, sem = 2.0, 0.15, 3e4, 0.006  # v_c beyond the data, as in a lab series
    v = VELOCITIES
    hits = {"F_c": 0, "F_c_profile": 0, "v_c": 0, "beta": 0}
    n = 150
    for _ in range(n):
        F = vel.thermal_law(v, Fc, B, vc) + rng.normal(0, sem, v.size)
        f = vel.fit_thermal_law(v, F, np.full(v.size, sem), 296.0)
        hits["F_c"] += abs(f.F_c_nN - Fc) <= f.F_c_std
        hits["F_c_profile"] += f.F_c_lo <= Fc <= f.F_c_hi
        hits["v_c"] += f.v_c_lo <= vc <= f.v_c_hi
        beta = B**1.5 / (vel.KB_NN_NM_PER_K * 296.0)
        hits["beta"] += abs(f.beta - beta) <= f.beta_std
    for k, h in hits.items():  # 68 % intervals: about two thirds, a little more by design
        assert 0.6 <= h / n <= 0.9, (k, h / n)


def test_cached_series_three_decades_recover_the_athermal_peak():
    s = _series()
    g = _groups(s)
    assert g.n_lines.min() >= 30 and g.velocity_nm_per_s.size == 13
    assert np.all(np.diff(g.mean) > -0.01)  # friction grows with velocity
    f = _window(g, 10, 1e4)
    # F_c is the athermal peak pi U0/a of the simulated substrate, within its uncertainty
    assert f.F_c_lo <= F_MAX <= f.F_c_hi
    assert abs(f.F_c_nN - F_MAX) <= 2 * f.F_c_std
    assert f.chi2_red < 3
    # the classical estimator's thermal correction gives the same barrier at every v
    u = vel.group_by_velocity(s["velocity_nm_per_s"], s["U0_eV"])
    assert np.all(np.abs(u.mean - U0_TRUE) < 0.03)
    # at eta = 17 the barrier is steeper than the washboard form: beta below 3 pi ... / a
    assert 0.6 * vel.washboard_beta(F_MAX, A) < f.beta < vel.washboard_beta(F_MAX, A)
    f0, lo, hi = f.attempt_rate(float(np.nanmedian(s["k_exp_N_m"])), float(np.mean(g.mean)))
    assert lo < f0 < hi < 3 * lo and 1e5 < f0 < 3e6


def test_decades_needed_to_pin_the_attempt_rate(capsys):
    """Fit 1, 2 and 3 decades from 10 nm/s: only the series that reaches v_c bounds it."""
    s = _series()
    g = _groups(s)
    k = float(np.nanmedian(s["k_exp_N_m"]))
    rows = []
    for decades in (1, 2, 3):
        f = _window(g, 10, 10 ** (1 + decades))
        inside = g.velocity_nm_per_s <= 10 ** (1 + decades) * 1.001
        f0, lo, hi = f.attempt_rate(k, float(np.mean(g.mean[inside])))
        rows.append((decades, f, f0, lo, hi))
        print(f"{decades} decade(s) 10-{10 ** (1 + decades):g} nm/s: F_c {f.F_c_nN:.3f} "
              f"[{f.F_c_lo:.3f}, {f.F_c_hi:.3f}] nN, v_c {f.v_c_nm_per_s:.3g} "
              f"[{f.v_c_lo:.3g}, {f.v_c_hi:.3g}] nm/s, sd(ln v_c) {f.ln_v_c_std:.3g}, "
              f"f0 {f0:.3g} [{lo:.3g}, {hi:.3g}] 1/s")
    one, two, three = rows
    assert math.isinf(one[1].v_c_hi) and math.isinf(one[4])
    assert math.isinf(two[1].v_c_hi) and math.isinf(two[4])
    assert three[1].v_c_hi / three[1].v_c_lo < 3 and three[4] / three[3] < 3
    assert "do not bound v_c" in one[1].summary()


def test_group_by_velocity_and_errors():
    g = vel.group_by_velocity([10, 10.000001, 30, 30, 30, 100], [1.0, 1.2, 2.0, 2.2, 2.4, 3.0],
                              line_sem=[0.1, 0.1, 0.1, 0.1, 0.1, 0.05])
    assert list(g.n_lines) == [2, 3, 1]
    assert g.mean == pytest.approx([1.1, 2.2, 3.0])
    assert g.sem[1] == pytest.approx(0.2 / math.sqrt(3))
    assert g.sem[2] == pytest.approx(0.05)  # one line: its own error over slips
    assert vel.line_sem(np.array([0.2]), np.array([4]))[0] == pytest.approx(0.1)


def test_fit_refuses_too_few_velocities():
    with pytest.raises(ValueError, match="at least 4 distinct velocities"):
        vel.fit_thermal_law([10, 100, 1000, 1000], [1.0, 1.1, 1.2, 1.2])
    with pytest.raises(ValueError, match="> 0"):
        vel.fit_thermal_law([-1, 10, 100, 1000], [1.0, 1.1, 1.2, 1.3])


@pytest.mark.slow
def test_cached_series_is_reproducible():
    """The simulator gives the same lines (seeded); the estimator, which evolves, must
    still give the same per-velocity peak force within its standard error."""
    s = _series()
    new = vel.simulated_series(U0_TRUE, K_TRUE, VELOCITIES, lines=32, seed=2024)
    np.testing.assert_array_equal(new["velocity_nm_per_s"], s["velocity_nm_per_s"])
    old_g, new_g = _groups(s), _groups(new)
    assert np.all(new_g.n_lines >= 24)  # a few lines may be flagged (too noisy, ...)
    assert np.all(np.abs(new_g.mean - old_g.mean) <= 2 * old_g.sem), (new_g.mean, old_g.mean)


def test_a_more_damped_contact_slips_later_as_kramers_prefactor_says():
    """Kramers' prefactor falls as 1/Gamma once a contact is overdamped: at ten times the
    preset's damping the tip slips at a higher force, which the PT inversion told the
    preset's damping reads as a higher barrier, and told the true damping does not (the
    simulator and the inversion's rate theory agree). Same seed at both dampings."""
    peak, told_preset, told_truth = {}, {}, {}
    for gamma in (1e7, 1e8):
        s = vel.simulated_series(1.0, 10.0, [60.0], lines=32, seed=7605, damping_per_s=gamma)
        peak[gamma] = np.nanmean(s["F_peak_nN"])
        told_preset[gamma] = np.nanmedian(s["U0_eV"])  # the labels assume the preset
        told_truth[gamma] = np.nanmedian(estimate_array(
            s["x_nm"], s["force_nN"], A, 296.0, s["velocity_nm_per_s"],
            damping_per_s=gamma)[:, U0])  # fmt: skip
    assert peak[1e8] > 1.03 * peak[1e7], peak  # measured +5 %
    assert told_preset[1e8] > 1.04, told_preset  # measured 1.061 eV
    assert all(abs(u - 1.0) < 0.03 for u in told_truth.values()), told_truth
