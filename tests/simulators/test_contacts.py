"""Contacts that are not one point (issue 40): simulators and the effective-PT truth."""

import numpy as np
import pytest

from stickslip.simulators.config import PhysicalSettings
from stickslip.simulators.contacts import (
    MISFIT_LIMIT,
    Contact,
    cached_contact_set,
    contact_set,
    described_dataset,
    fit_effective_pt,
    point_contact,
    pt_quasistatic_force,
    quasistatic_contacts,
    simulate_contacts,
    tip_change,
)
from stickslip.units import eta_from

PAPER = PhysicalSettings()
A = PAPER.lattice_nm
#: Short lines for the Langevin runs: one pixel is a/8, 8 lattice periods.
SHORT = PhysicalSettings(length_nm=8 * A, pixels=64)


def _fit(F, s=PAPER):
    return fit_effective_pt(F, s.pixel_nm, s.lattice_nm)


def _series(*k):
    return 1.0 / sum(1.0 / x for x in k)


def test_effective_fit_recovers_pt_at_any_phase():
    rng = np.random.default_rng(5)
    U0, K, ph = rng.uniform(0.3, 6, 6), rng.uniform(1, 50, 6), rng.uniform(0, A, 6)
    F = np.array([pt_quasistatic_force(U0[i], K[i], ph[i], PAPER.pixel_nm, PAPER.pixels, A)
                  for i in range(6)])  # fmt: skip
    fit = _fit(F)
    np.testing.assert_allclose(fit.U0_eV, U0, rtol=1e-6)
    np.testing.assert_allclose(fit.K_N_m, K, rtol=1e-6)
    np.testing.assert_allclose(fit.eta, eta_from(U0, K, A), rtol=1e-5)
    assert np.all(fit.misfit_fraction < 1e-8)


def test_point_contact_waveform_is_exact_quasistatic_pt():
    """The general solver, one asperity on the support, against the closed form."""
    lines = [point_contact(1.0, 10.0), point_contact(3.0, 4.0), point_contact(0.3, 40.0)]
    qs = quasistatic_contacts(lines, PAPER)
    for i, (U0, K) in enumerate([(1.0, 10.0), (3.0, 4.0), (0.3, 40.0)]):
        X0 = qs.support_nm[i, 0] - 0.5 * PAPER.pixel_nm
        ref = pt_quasistatic_force(U0, K, X0, PAPER.pixel_nm, PAPER.pixels, A)
        assert np.abs(qs.force_nN[i] - ref).max() < 2e-3 * np.ptp(ref)
        # F_max = pi U0 / a, F = 0 at the well bottom: the recorded range spans them
        assert ref.max() <= np.pi * U0 * 0.1602176634 / A * (1 + 1e-9)


@pytest.mark.parametrize("k1", [1e4, 100.0])
def test_one_asperity_on_a_cantilever_is_pt_with_the_series_stiffness(k1):
    kc, U0 = 10.0, 1.2
    contact = Contact((U0,), (k1,), (0.4,), cantilever_N_m=kc)
    fit = _fit(quasistatic_contacts([contact], PAPER).force_nN)
    assert fit.U0_eV[0] == pytest.approx(U0, rel=0.02)
    assert fit.K_N_m[0] == pytest.approx(_series(kc, k1), rel=0.02)
    assert fit.misfit_fraction[0] < 1e-3
    if k1 > 1e3:  # stiff contact: K -> k_c
        assert fit.K_N_m[0] == pytest.approx(kc, rel=0.02)
    else:  # a compliant contact is not the cantilever alone
        assert abs(fit.K_N_m[0] / kc - 1) > 0.05


@pytest.mark.parametrize(
    ("n", "U0_i", "k_i", "kc", "phase"),
    [(3, 0.5, 30.0, 10.0, 1.0), (6, 0.4, 200.0, 20.0, 4.0), (2, 1.5, 8.0, 30.0, 0.0)],
)
def test_coherent_identical_asperities_sum_their_barriers(n, U0_i, k_i, kc, phase):
    contact = Contact((U0_i,) * n, (k_i,) * n, (phase,) * n, cantilever_N_m=kc)
    fit = _fit(quasistatic_contacts([contact], PAPER).force_nN)
    assert fit.U0_eV[0] == pytest.approx(n * U0_i, rel=0.03)
    assert fit.K_N_m[0] == pytest.approx(_series(kc, n * k_i), rel=0.03)
    assert fit.described[0]


def test_random_registry_fits_worse_than_coherent():
    """Compliant asperities (eta_i = 10 each): coherent is one PT, random often is not."""
    rng = np.random.default_rng(0)
    coherent = Contact((1.0,) * 4, (5.0,) * 4, (0.7,) * 4, cantilever_N_m=20.0)
    random = [Contact((1.0,) * 4, (5.0,) * 4, tuple(rng.uniform(0, 2 * np.pi, 4)), 20.0)
              for _ in range(8)]  # fmt: skip
    fit = _fit(quasistatic_contacts([coherent, *random], PAPER).force_nN)
    m_coh, m_rand = fit.misfit_fraction[0], fit.misfit_fraction[1:]
    assert m_coh < 1e-3
    assert np.mean(m_rand > 10 * m_coh) >= 0.75
    assert np.mean(m_rand > MISFIT_LIMIT) >= 0.5
    # stiff contacts in random registry are one PT of barrier |sum U0_i exp(i phi_i)|
    phases = tuple(rng.uniform(0, 2 * np.pi, 4))
    stiff = Contact((1.0,) * 4, (500.0,) * 4, phases, cantilever_N_m=20.0)
    fit = _fit(quasistatic_contacts([stiff], PAPER).force_nN)
    amp = abs(np.exp(1j * np.array(phases)).sum())
    assert fit.U0_eV[0] == pytest.approx(amp, rel=0.05)


def test_tip_change_position_and_halves():
    L, change = PAPER.length_nm, 0.43 * PAPER.length_nm
    line = tip_change(1.0, 10.0, change, U0_factor=1.6, K_factor=1.0 / 1.3)
    qs = quasistatic_contacts([line], PAPER)
    F, x = qs.force_nN[0], qs.x_nm
    X0 = qs.support_nm[0, 0] - 0.5 * PAPER.pixel_nm
    before = pt_quasistatic_force(1.0, 10.0, X0, PAPER.pixel_nm, PAPER.pixels, A)
    after = pt_quasistatic_force(1.6, 10.0 / 1.3, X0, PAPER.pixel_nm, PAPER.pixels, A)
    tol = 2e-3 * np.ptp(F)
    pre, post = x + PAPER.pixel_nm <= change, x >= change + A
    assert np.abs(F - before)[pre].max() < tol
    assert np.abs(F - after)[post].max() < tol
    # the line leaves the old contact's waveform within one period of the change
    off = np.flatnonzero(np.abs(F - before) > 10 * tol)
    assert change - PAPER.pixel_nm <= x[off[0]] <= change + A
    # each half is one PT, the two differ, the whole line is two regimes
    p = int(change / PAPER.pixel_nm)
    first, second = _fit(F[: p - 4]), _fit(F[p + 16 :])
    assert first.U0_eV[0] == pytest.approx(1.0, rel=0.01)
    assert first.K_N_m[0] == pytest.approx(10.0, rel=0.01)
    assert second.U0_eV[0] == pytest.approx(1.6, rel=0.01)
    assert second.K_N_m[0] == pytest.approx(10.0 / 1.3, rel=0.01)
    assert _fit(F).misfit_fraction[0] > MISFIT_LIMIT
    assert L > change


def test_tip_change_set_truth():
    cs = contact_set(4, "tip_change", seed=3, settings=PAPER, langevin=False)
    t = cs.truth
    L = PAPER.length_nm
    assert np.all((t["change_nm"] >= 0.25 * L) & (t["change_nm"] <= 0.75 * L))
    for i, ln in enumerate(cs.lines):
        assert ln.change_nm == t["change_nm"][i]
        fu, fk = t["U0_factor"][i], t["K_factor"][i]
        assert fu != 1.0 or fk != 1.0
        for f in (fu, fk):
            assert f == 1.0 or 1.3 <= max(f, 1 / f) <= 2.0
        assert t["U0_after_eV"][i] == pytest.approx(t["U0_before_eV"][i] * fu)
        assert t["K_after_N_m"][i] == pytest.approx(t["K_before_N_m"][i] * fk)
        # the halves of the T = 0 waveform differ in peak force or in slope
        p = int(t["change_nm"][i] / PAPER.pixel_nm)
        F = cs.force_T0_nN[i]
        a_, b_ = _fit(F[: p - 4]), _fit(F[p + 16 :])
        assert a_.U0_eV[0] == pytest.approx(t["U0_before_eV"][i], rel=0.02)
        assert b_.U0_eV[0] == pytest.approx(t["U0_after_eV"][i], rel=0.02)
        assert b_.K_N_m[0] == pytest.approx(t["K_after_N_m"][i], rel=0.02)
    assert not t["described"].any()
    assert np.all(t["misfit_fraction"] > 0.02)


def test_waveforms_are_periodic_in_the_support_position():
    rng = np.random.default_rng(2)
    contacts = [
        Contact((1.0,) * 3, (40.0,) * 3, tuple(rng.uniform(0, 2 * np.pi, 3)), 15.0),
        Contact(
            (0.8, 1.5, 0.4, 1.0), (5.0, 9.0, 3.0, 6.0), tuple(rng.uniform(0, 2 * np.pi, 4)), 25.0
        ),  # fmt: skip
        point_contact(2.0, 20.0),
    ]
    for F in (
        quasistatic_contacts(contacts, SHORT).force_nN,
        simulate_contacts(contacts, SHORT, temperature_K=0.0).force_nN,
    ):
        for row in F:  # one lattice period is 8 pixels
            assert np.abs(row[8:] - row[:-8]).max() < 1e-6 * np.ptp(row)
    # a registry phi shifts the potential by -phi a / (2 pi): the waveform moves with it
    shift = 2 * SHORT.pixel_nm  # = a / 4
    c0 = Contact((1.0,), (1e3,), (0.0,), 10.0)
    c1 = Contact((1.0,), (1e3,), (-2 * np.pi * shift / A,), 10.0)
    F0, F1 = quasistatic_contacts([c0, c1], SHORT).force_nN
    assert np.abs(F1[2:] - F0[:-2]).max() < 1e-6 * np.ptp(F0)
    assert np.abs(F1 - F0).max() > 0.1 * np.ptp(F0)


def test_langevin_at_zero_temperature_follows_the_quasistatic_waveform():
    contacts = [
        point_contact(1.0, 10.0),
        Contact((0.5,) * 3, (30.0,) * 3, (0.3,) * 3, 10.0),
        tip_change(1.0, 10.0, 4 * A + 0.01, U0_factor=1.5),
    ]
    lv = simulate_contacts(contacts, SHORT, temperature_K=0.0).force_nN
    qs = quasistatic_contacts(contacts, SHORT).force_nN
    for a_, b_ in zip(lv, qs, strict=True):
        d = np.abs(a_ - b_) / np.ptp(b_)
        assert np.median(d) < 1e-3  # away from the slips (which take time)
        assert np.mean(d > 0.01) < 0.25
    # tip change in the dynamics: the second half has the higher barrier
    assert lv[2, 40:].max() > 1.3 * lv[2, :30].max()


def test_thermal_lines_slip_early():
    c = [point_contact(1.0, 10.0), Contact((0.5,) * 3, (30.0,) * 3, (0.3,) * 3, 10.0)]
    hot = simulate_contacts(c, SHORT, seed=4).force_nN
    hot_again = simulate_contacts(c, SHORT, seed=4).force_nN
    cold = quasistatic_contacts(c, SHORT).force_nN
    np.testing.assert_array_equal(hot, hot_again)  # streams from (seed, index)
    ratio = hot.mean(axis=1) / cold.mean(axis=1)
    assert np.all((ratio > 0.5) & (ratio < 0.97))
    assert not np.array_equal(simulate_contacts(c, SHORT, seed=5).force_nN, hot)


def test_multi_contact_set():
    cs = contact_set(3, "multi", seed=1, settings=SHORT)
    t = cs.truth
    assert cs.force_nN.shape == cs.force_T0_nN.shape == (3, SHORT.pixels)
    assert cs.x_nm.shape == (SHORT.pixels,)
    assert np.all((t["n_asperities"] >= 2) & (t["n_asperities"] <= 6))
    assert np.all(np.isnan(t["change_nm"]))
    np.testing.assert_allclose(t["mean_force_nN"], cs.force_nN.mean(axis=1))
    np.testing.assert_allclose(t["eta"], eta_from(t["U0_eV"], t["K_N_m"], A))
    fit = _fit(cs.force_T0_nN, SHORT)
    np.testing.assert_allclose(fit.U0_eV, t["U0_eV"], rtol=1e-6)
    np.testing.assert_array_equal(t["described"], fit.misfit_fraction <= MISFIT_LIMIT)
    d = t["described"]
    assert np.all((t["eta"][d] >= 1.5) & (t["eta"][d] <= 40))
    assert not np.allclose(cs.force_nN, cs.force_T0_nN)  # 296 K
    again = contact_set(3, "multi", seed=1, settings=SHORT, langevin=False)
    np.testing.assert_array_equal(again.force_T0_nN, cs.force_T0_nN)
    np.testing.assert_array_equal(again.force_nN, cs.force_T0_nN)


def test_described_lines_as_a_dataset_and_cached(tmp_path):
    x, F, t = cached_contact_set(6, "multi", 2, tmp_path)
    assert (tmp_path / "multi_6_2.npz").exists()
    x2, F2, _ = cached_contact_set(6, "multi", 2, tmp_path)  # read back, not simulated
    np.testing.assert_array_equal(F2, F)
    d = described_dataset(x, F, t)
    keep = t["described"].astype(bool)
    assert d.n == keep.sum() and d.force_nN.shape == (d.n, PAPER.pixels)
    np.testing.assert_array_equal(d.params["K_N_m"], t["K_N_m"][keep])
    np.testing.assert_allclose(d.params["F_mean_nN"], F[keep].mean(axis=1))
    assert np.all(d.params["lattice_nm"] == PAPER.lattice_nm)
    assert np.all(d.params["temperature_K"] == PAPER.temperature_K)


@pytest.mark.slow  # compiles the project's PT kernel
def test_langevin_point_contact_equals_the_project_simulator():
    from stickslip.simulators import simulate

    s = SHORT.replace(temperature_K=0.0)
    ref = simulate([1.0, 3.0], [10.0, 30.0], s)
    lv = simulate_contacts([point_contact(1.0, 10.0), point_contact(3.0, 30.0)], s)
    np.testing.assert_allclose(lv.support_nm, ref.support_nm, rtol=0, atol=1e-9)
    np.testing.assert_allclose(lv.force_nN, ref.force_nN, rtol=0, atol=1e-8)
