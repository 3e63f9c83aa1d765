"""The in/out-of-domain verdict: trace checks, reasons, widened intervals, embeddings."""

from __future__ import annotations

import json
from importlib import resources

import numpy as np
import pytest

from stickslip.estimators import domain as D
from stickslip.estimators.classical.estimator import ClassicalEstimator
from stickslip.estimators.domain import (
    ContactProbe,
    EmbeddingReference,
    assess,
    trace_checks,
    widen_row,
    widen_rows,
)
from stickslip.traces.readers import collect_traces
from stickslip.traces.trace import Trace

A = 0.246
X = np.arange(512) * (11.0 / 512)
RNG = np.random.default_rng(11)


def sawtooth(period_nm: float = A, noise_nN: float = 0.01, reverse: bool = False) -> np.ndarray:
    """Stick-slip-like: rises over a period, drops within a pixel (or the reverse)."""
    phase = (X / period_nm + 0.3) % 1.0
    f = 2.0 * phase - 1.0 + 0.5
    f = f[::-1] if reverse else f
    return f + noise_nN * RNG.standard_normal(X.size)


def square_wave() -> np.ndarray:
    return 1.0 * ((X / 1.3) % 1.0 < 0.5) + 0.01 * RNG.standard_normal(X.size)


def row(eta: float = 5.0, lo: float | None = 4.0, hi: float | None = 6.0) -> dict:
    r = {"quality": "ok", "F_mean_nN": 1.0, "U0_eV": 1.0, "K_N_m": 10.0, "eta": eta}
    if lo is not None:
        r.update(eta_lo95=lo, eta_hi95=hi)
    return r


def judge(force: np.ndarray, r: dict | None = None, lattice_nm: float = A) -> dict:
    r = row() if r is None else r
    assess([r], [X], [force], [lattice_nm])
    return r


def test_trace_checks_count_slips_rises_and_their_spacing():
    c = trace_checks([X] * 5, [sawtooth(), sawtooth(reverse=True), square_wave(),
                               0.3 * RNG.standard_normal(X.size), np.full(X.size, 2.0)])
    n_periods = 11.0 / A
    assert c.n_drops[0] == pytest.approx(n_periods, abs=1.5)
    assert c.n_rises[0] == 0
    assert c.spacing_median_nm[0] == pytest.approx(A, rel=0.05)
    assert c.n_rises[1] == pytest.approx(n_periods, abs=1.5) and c.n_drops[1] == 0
    # a square wave's cycles: fast falls and sudden rises alike
    assert 3 <= c.n_drops[2] <= 11.0 / 1.3 + 1.5 and 3 <= c.n_rises[2] <= 11.0 / 1.3 + 1.5
    assert c.n_drops[3] == c.n_rises[3] == 0  # white noise: no jump stands out
    assert c.n_drops[4] == c.n_rises[4] == 0  # flat
    assert np.isnan(c.spacing_median_nm[3])


@pytest.mark.parametrize(("force", "reason"), [
    (lambda: sawtooth(reverse=True), "sawtooth reversed"),
    (square_wave, "jumps up as well as down"),
    (lambda: 0.3 * RNG.standard_normal(X.size), "no stick-slip: slips not found"),
    (lambda: np.cumsum(0.05 * RNG.standard_normal(X.size)), "stick-slip"),  # no, or not a
    (lambda: np.full(X.size, 1.5), "the force does not vary beyond its noise"),
    (lambda: sawtooth(period_nm=0.6 * A), "slips closer than one lattice spacing"),
])  # fmt: skip
def test_non_stick_slip_traces_are_out_of_domain_with_a_plain_reason(force, reason):
    r = judge(force())
    assert r["in_domain"] is False
    assert r["domain_score"] > 1.0
    assert reason in r["domain_reason"]


def test_a_stick_slip_trace_with_eta_in_the_window_is_in_domain():
    r = judge(sawtooth())
    assert r["in_domain"] is True
    assert 0.0 < r["domain_score"] <= 1.0
    assert r["domain_reason"] is None
    # two lattice spacings apart (multiple slip) is stick-slip too
    assert judge(sawtooth(period_nm=2 * A))["in_domain"] is True


def test_eta_outside_the_trained_window_is_judged_on_the_estimates_interval():
    low = judge(sawtooth(), row(eta=0.8, lo=0.7, hi=0.95))
    assert low["in_domain"] is False
    assert low["domain_reason"].startswith("eta below the trained window")
    assert low["domain_score"] == pytest.approx(D.ETA_WINDOW[0] / 0.95)
    # an interval that reaches into the window keeps the row in domain
    assert judge(sawtooth(), row(eta=1.1, lo=0.9, hi=1.4))["in_domain"] is True
    # without an interval: eta +- 2 std, else the value
    no_iv = row(eta=1.0, lo=None)
    assert judge(sawtooth(), {**no_iv, "eta_std": 0.05})["in_domain"] is False
    assert judge(sawtooth(), {**no_iv, "eta_std": 0.2})["in_domain"] is True
    assert judge(sawtooth(), no_iv)["in_domain"] is False
    high = judge(sawtooth(), row(eta=80.0, lo=60.0, hi=100.0))
    assert high["domain_reason"].startswith("eta above the trained window")


def test_an_eta_of_zero_is_out_of_domain_at_the_capped_score():
    for edge in (D.ETA_WINDOW[0], D.ETA_EDGE):
        r = row(eta=0.0, lo=None)
        assess([r], [X], [sawtooth()], [A], eta_edge=edge)
        assert r["in_domain"] is False
        assert r["domain_score"] == D.MAX_SCORE
        assert r["domain_reason"].startswith("eta below the trained window")


def test_the_embedding_distance_counts_when_a_row_has_one():
    r = judge(sawtooth(), {**row(), "domain_embedding": 2.5})
    assert r["in_domain"] is False
    assert r["domain_score"] == pytest.approx(2.5)
    assert "unlike the training lines" in r["domain_reason"]
    assert judge(sawtooth(), {**row(), "domain_embedding": 0.7})["in_domain"] is True


def test_failed_checks_are_listed_worst_first():
    r = judge(sawtooth(reverse=True), {**row(eta=0.5, lo=0.4, hi=0.6), "domain_embedding": 900.0})
    reasons = r["domain_reason"].split("; ")
    assert reasons[0].startswith("line unlike the training lines")
    assert any(s.startswith("sawtooth reversed") for s in reasons)
    assert any(s.startswith("eta below") for s in reasons)


def test_rows_without_an_estimate_are_out_of_domain():
    r = {"quality": "too few slips"}
    assess([r], [X], [sawtooth()], [A])
    assert r["in_domain"] is False
    assert r["domain_score"] is None
    assert r["domain_reason"] == "no estimate: too few slips"


def lognormal_row(m: float, e: float) -> dict:
    z68, z95 = D.Z68, 1.959963984540054
    return {"eta": m, "eta_lo68": m * np.exp(-z68 * e), "eta_hi68": m * np.exp(z68 * e),
            "eta_lo95": m * np.exp(-z95 * e), "eta_hi95": m * np.exp(z95 * e),
            "eta_std": m * np.sqrt(np.expm1(e**2) * np.exp(e**2))}  # fmt: skip


def test_widening_scales_half_widths_linearly_for_friction_and_in_log_space_for_the_rest():
    r = {"F_mean_nN": 1.0, "F_mean_nN_lo95": 0.8, "F_mean_nN_hi95": 1.3, "F_mean_nN_std": 0.1,
         **lognormal_row(5.0, 0.1)}  # fmt: skip
    widen_row(r, 3.0)
    assert (r["F_mean_nN_lo95"], r["F_mean_nN_hi95"]) == pytest.approx((0.4, 1.9))
    assert r["F_mean_nN_std"] == pytest.approx(0.3)
    wide = lognormal_row(5.0, 0.3)  # the log-normal of three times the log-width
    for k in ("eta_lo68", "eta_hi68", "eta_lo95", "eta_hi95", "eta_std"):
        assert r[k] == pytest.approx(wide[k], rel=1e-9)


def test_widening_a_table_widens_each_row_on_its_own_columns():
    nN = {"F_mean_nN": 1.0, "F_mean_nN_lo95": 0.8, "F_mean_nN_hi95": 1.3, **lognormal_row(5.0, 0.1)}
    volts = {"F_mean_V": 0.2, "F_mean_V_lo95": 0.1, "F_mean_V_hi95": 0.25, "F_mean_V_std": 0.05}
    odd = {"K_N_m": 2.0, "K_N_m_lo95": -1.0, "K_N_m_hi95": 4.0, "U0_eV": float("nan")}
    rows = [dict(nN), dict(volts), dict(odd), {"quality": "too few slips"}]
    widen_rows(rows, 2.0)
    assert (rows[0]["F_mean_nN_lo95"], rows[0]["F_mean_nN_hi95"]) == pytest.approx((0.6, 1.6))
    assert rows[0]["eta_hi95"] == pytest.approx(lognormal_row(5.0, 0.2)["eta_hi95"])
    assert "F_mean_V" not in rows[0] and "F_mean_nN" not in rows[1]
    assert (rows[1]["F_mean_V_lo95"], rows[1]["F_mean_V_hi95"]) == pytest.approx((0.0, 0.3))
    assert rows[1]["F_mean_V_std"] == pytest.approx(0.1)
    # a log-normal bound at or below zero is left as it is, the other one widens
    assert rows[2]["K_N_m_lo95"] == -1.0 and rows[2]["K_N_m_hi95"] == pytest.approx(8.0)
    assert rows[3] == {"quality": "too few slips"}


def test_trace_checks_on_several_threads_match_one_thread():
    lines = [sawtooth(period_nm=A * (1 + k % 3)) for k in range(600)]
    one = trace_checks([X] * 600, lines, threads=1)
    two = trace_checks([X] * 600, lines, threads=2)
    for field in ("n_drops", "n_rises", "spacing_median_nm", "spacing_q25_nm", "noise_nN"):
        np.testing.assert_array_equal(getattr(one, field), getattr(two, field))


def test_only_rows_out_of_domain_are_widened():
    inside = {**row(), "eta_lo95": 4.0, "eta_hi95": 6.0}
    outside = dict(inside)
    assess([inside, outside], [X, X], [sawtooth(), sawtooth(reverse=True)], [A, A])
    assert (inside["eta_lo95"], inside["eta_hi95"]) == (4.0, 6.0)
    assert outside["eta_lo95"] == pytest.approx(5.0 * (4.0 / 5.0) ** D.WIDEN_FACTOR)
    assert outside["eta_hi95"] == pytest.approx(5.0 * (6.0 / 5.0) ** D.WIDEN_FACTOR)
    assert outside["eta"] == 5.0  # the estimate itself stays


def test_a_misstated_lattice_widens_by_its_own_factor():
    """Slips closer than the stated lattice bias U0 by the lattice ratio: those rows take
    the spacing check's larger factor, the others the common one."""
    reversed_row, close = {**row(), "eta_lo95": 4.0}, {**row(), "eta_lo95": 4.0}
    assess([reversed_row, close], [X, X], [sawtooth(reverse=True), sawtooth(period_nm=0.6 * A)],
           [A, A])  # fmt: skip
    assert "lattice spacing" in close["domain_reason"]
    assert "lattice spacing" not in reversed_row["domain_reason"]
    f = D.CHECK_WIDEN_FACTORS["spacing"]
    assert f > D.WIDEN_FACTOR
    assert close["eta_lo95"] == pytest.approx(5.0 * (4.0 / 5.0) ** f)
    assert reversed_row["eta_lo95"] == pytest.approx(5.0 * (4.0 / 5.0) ** D.WIDEN_FACTOR)


def test_embedding_reference_flags_lines_far_from_its_reference(tmp_path):
    rng = np.random.default_rng(0)
    scales = np.linspace(3.0, 0.1, 40)
    ref_feats = rng.standard_normal((2, 4000, 40)) * scales
    ref = EmbeddingReference.fit(ref_feats, "abc", level=0.99)
    new = rng.standard_normal((2, 2000, 40)) * scales
    assert np.mean(ref.distance(new) > 1.0) == pytest.approx(0.01, abs=0.01)
    # off in a direction of small variance: far, though small in absolute terms
    off = new.copy()
    off[..., -1] += 1.0
    assert np.mean(ref.distance(off) > 1.0) > 0.9
    path = ref.save(tmp_path / "ref.npz")
    back = EmbeddingReference.load(path)
    assert back.fingerprint == "abc"
    assert np.allclose(back.distance(new[:, :50]), ref.distance(new[:, :50]), rtol=1e-5)


def test_contact_probe_learns_a_direction_and_flags_at_its_level(tmp_path):
    # two members whose features differ by a rotation; the classes differ along one
    # direction of small variance, buried in large nuisance variation
    rng = np.random.default_rng(5)
    n, D_ = 3000, 12
    y = (rng.random(n) < 0.3).astype(float)
    base = rng.standard_normal((n, D_)) * np.linspace(5.0, 0.5, D_)
    base[:, -1] += 1.5 * y
    rot = np.linalg.qr(rng.standard_normal((D_, D_)))[0]
    feats = np.stack([base, base @ rot])
    val = rng.random(n) < 0.3
    w = np.where(y == 1, 1.0 / y.sum(), 1.0 / (n - y.sum()))
    probe = ContactProbe.fit(feats, y, w, val)
    assert probe.penalty in D.PROBE_PENALTIES
    z = probe.log_odds(feats[:, val])
    # the fitted log-odds rank the held-out lines as the true likelihood ratio does
    from scipy.stats import spearmanr

    assert spearmanr(z, base[val, -1]).statistic > 0.95
    neg = feats[:, val & (y == 0)]
    probe.set_limit(neg, 0.99)
    assert np.mean(probe.ratio(neg) > 1.0) == pytest.approx(0.01, abs=0.005)
    assert np.mean(probe.ratio(feats[:, val & (y == 1)]) > 1.0) > 0.3
    # saved with the reference it belongs to, and read back the same
    ref = EmbeddingReference.fit(feats[:, ~val], "abc")
    ref.probe = probe
    back = EmbeddingReference.load(ref.save(tmp_path / "ref.npz"))
    np.testing.assert_allclose(back.probe.log_odds(feats[:, :50]), probe.log_odds(feats[:, :50]),
                               rtol=1e-4, atol=1e-4)
    assert back.probe.limit == probe.limit and back.probe.level == 0.99
    # a reference written without a probe reads back without one
    ref.probe = None
    assert EmbeddingReference.load(ref.save(tmp_path / "bare.npz")).probe is None


def test_the_contact_probe_counts_when_a_row_has_one():
    r = judge(sawtooth(), {**row(), "domain_contacts": 3.0})
    assert r["in_domain"] is False
    assert r["domain_score"] == pytest.approx(3.0)
    assert r["domain_reason"].endswith("more than one contact")
    assert "3x the limit" in r["domain_reason"]
    assert judge(sawtooth(), {**row(), "domain_contacts": 0.2})["in_domain"] is True


def test_embedding_distance_is_the_projection_and_residual_it_documents():
    rng = np.random.default_rng(3)
    # fewer lines than features: a residual outside the components
    ref = EmbeddingReference.fit(rng.standard_normal((2, 30, 40)) * np.linspace(2, 0.1, 40),
                                 "abc")  # fmt: skip
    f = rng.standard_normal((2, 100, 40))
    d2 = np.zeros((2, 100))
    for m in range(2):
        X = f[m] - ref.mean[m]
        P = X @ ref.components[m].T
        d2[m] = (P**2 / ref.variance[m]).sum(1) + ((X**2).sum(1) - (P**2).sum(1)) \
            / ref.residual_variance[m]
    expected = np.sqrt(d2 / 40).mean(axis=0) / ref.limit
    np.testing.assert_allclose(ref.distance(f), expected, rtol=1e-5)


def examples() -> list[Trace]:
    folder = resources.files("stickslip") / "resources" / "examples"
    manifest = {m["file"]: m for m in json.loads((folder / "manifest.json").read_text())}
    traces, errors = collect_traces([str(folder / f) for f in sorted(manifest)])
    assert not errors
    for t in traces:
        t.meta.update(lattice_nm=manifest[t.name + ".csv"]["lattice_nm"],
                      velocity_nm_per_s=manifest[t.name + ".csv"]["velocity_nm_per_s"])
    return traces


def reversed_copies(traces: list[Trace]) -> list[Trace]:
    return [Trace(t.x_nm, t.force_nN[::-1].copy(), t.name + "-reversed", t.source, dict(t.meta))
            for t in traces]  # fmt: skip


def test_learned_models_keep_eta_a_little_inside_the_window_edge():
    # the interval reaches into the window, but the estimate sits at its edge: with the
    # learned models' edge the row is out, with the window's (classical) it stays in
    r = judge(sawtooth(), row(eta=1.3, lo=1.1, hi=1.6))
    assert r["in_domain"] is True
    edge = row(eta=1.3, lo=1.1, hi=1.6)
    assess([edge], [X], [sawtooth()], [A], eta_edge=D.ETA_EDGE)
    assert edge["in_domain"] is False
    assert edge["domain_reason"].startswith("eta at the edge of the trained window")
    assert edge["domain_score"] == pytest.approx(D.ETA_EDGE / 1.3)
    assert D.ETA_WINDOW[0] < D.ETA_EDGE < 1.5
    from stickslip.estimators.line.estimator import LineEstimator

    assert LineEstimator.eta_edge == D.ETA_EDGE and ClassicalEstimator.eta_edge == D.ETA_WINDOW[0]


def test_a_low_eta_whose_slips_do_not_invert_is_out_of_domain():
    # the estimator found no stick-slip in the line (stick_slip_check): out below
    # ETA_CONFIRM, with the classical refusal in the reason; above it the check is moot
    low = {**row(eta=1.8, lo=1.5, hi=2.2), "stick_slip_check": "smooth sliding"}
    assess([low], [X], [sawtooth()], [A], eta_edge=D.ETA_EDGE)
    assert low["in_domain"] is False
    assert low["domain_score"] == pytest.approx(D.ETA_CONFIRM / 1.8)
    assert "do not invert to stick-slip (classical: smooth sliding)" in low["domain_reason"]
    high = {**row(eta=3.0, lo=2.5, hi=3.6), "stick_slip_check": "too noisy"}
    assert judge(sawtooth(), high)["in_domain"] is True


def test_the_line_model_asks_the_slips_only_below_eta_confirm():
    from stickslip.estimators.load import load_estimator

    line = load_estimator(None)
    # a sinusoidal force (smooth sliding) the model reads as eta near 2
    smooth = Trace(X, 2.0 * np.sin(2 * np.pi * X / A) + 0.5, "smooth", "s.csv",
                   {"lattice_nm": A})  # fmt: skip
    r = line.predict([smooth]).rows[0]
    assert r["eta"] < D.ETA_CONFIRM and r["stick_slip_check"] == "smooth sliding"
    assert r["in_domain"] is False and "do not invert to stick-slip" in r["domain_reason"]
    # stick-slip lines are answered by the classical estimator: nothing to report
    for t in examples():
        assert "stick_slip_check" not in line.predict([t]).rows[0], t.name
    line.domain_verdict = False  # no verdict: no check either
    assert "stick_slip_check" not in line.predict([smooth]).rows[0]


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason=(
    "known shortfall: 15 of these 40 smooth lines (eta 0.5-0.95, U0 0.1-0.6 eV) stay in "
    "domain; the bundled line model reads them as eta 1.5-2.5 and the classical "
    "estimator inverts their steep continuous falls as slips (eta 1.1-2.5), so neither "
    "check 5 nor 6 refuses them (benchmarks/domain.py --seed 2: 0.360 of smooth lines)"))
def test_smooth_sliding_comes_out_of_domain_and_clean_stick_slip_stays_in():
    """Held-out simulations (seed 41, not the tuning seed): paper-preset lines with eta
    0.2-0.95 (smooth sliding) and, in the training box, 1.5-40 (stick-slip), 296 K,
    graphite lattice."""
    from stickslip.estimators.load import load_estimator
    from stickslip.simulators.config import ParameterRange, PhysicalSettings
    from stickslip.simulators.sampling import sample_parameters
    from stickslip.simulators.simulate import simulate
    from stickslip.units import eta_from

    rng = np.random.default_rng(41)
    K_smooth = rng.uniform(5.0, 60.0, 40)
    U0_smooth = rng.uniform(0.2, 0.95, 40) * K_smooth / eta_from(1.0, 1.0, A)
    U0_ss, K_ss = sample_parameters(ParameterRange(eta=(1.5, 40.0)), 40, 41, A)
    U0, K = np.concatenate([U0_smooth, U0_ss]), np.concatenate([K_smooth, K_ss])
    f = simulate(U0, K, PhysicalSettings(), seed=41, lattice_nm=np.full(80, A)).force_nN
    x = np.arange(f.shape[1]) * (11.0 / f.shape[1])
    traces = [Trace(x, row, f"sim{i}", "sim", {"lattice_nm": A, "velocity_nm_per_s": 60.0})
              for i, row in enumerate(f)]  # fmt: skip
    flags = np.array([r["in_domain"] for r in load_estimator(None).predict(traces).rows])
    # the benchmark's target is 0.25 on 200 lines (seed 2: 0.185); 40 lines carry a
    # binomial se of 0.07, and the few smooth lines kept are thermally noisy ones with
    # U0 ~ 0.1-0.3 eV, whose thermal force noise exceeds their corrugation
    assert flags[:40].mean() <= 0.3
    assert flags[40:].mean() >= 0.9


def test_every_estimator_gives_the_verdict_the_classical_one_too():
    traces = examples()
    table = ClassicalEstimator().predict(traces + reversed_copies(traces))
    n = len(traces)
    assert all(r["in_domain"] for r in table.rows[:n])
    assert not any(r["in_domain"] for r in table.rows[n:])
    est = ClassicalEstimator()
    est.domain_verdict = False
    assert "in_domain" not in est.predict(traces).rows[0]


def test_the_line_model_keeps_example_traces_in_domain_and_reversed_ones_out():
    from stickslip.estimators.load import load_estimator

    line = load_estimator(None)
    assert line.embedding_reference is not None, "bundled reference missing or stale"
    traces = examples()
    table = line.predict(traces + reversed_copies(traces))
    n = len(traces)
    for r in table.rows[:n]:
        assert r["in_domain"], (r["trace"], r["domain_reason"])
        assert 0.0 < r["domain_embedding"] <= 1.0
    for r in table.rows[n:]:
        assert not r["in_domain"]
        assert "sawtooth reversed" in r["domain_reason"]
    # the embedding alone sees most of them too (the reference spans the effect families,
    # so a reversed clean multiple-slip line can sit inside its limit: 2 of 6 with the
    # model trained with the families, 1 of 6 with the one before)
    emb = np.array([r["domain_embedding"] for r in table.rows])
    assert np.mean(emb[n:] > 1.0) >= 0.6, emb[n:]
    assert np.median(emb[n:]) > 2 * np.median(emb[:n]), emb


def test_embedding_reason_shows_how_far_past_the_limit():
    # a line just past the limit must not read as "1x the limit"
    checks = trace_checks([X], [sawtooth()])
    text = D.reason("embedding", checks, 0, A, {"domain_embedding": 1.0126})
    assert "1.01x the limit" in text


def tip_change_sawtooth(change_nm: float = 5.0) -> np.ndarray:
    """A sawtooth whose drop (the tip's stiffness times a lattice spacing) grows 1.6x at
    ``change_nm``, with the period kept."""
    phase = (X / A + 0.3) % 1.0
    amp = np.where(X < change_nm, 1.0, 1.6)
    return amp * (2.0 * phase - 1.0) + 0.01 * RNG.standard_normal(X.size)


def test_a_line_that_changes_part_way_is_out_of_domain_with_where():
    r = judge(tip_change_sawtooth(5.0))
    assert r["in_domain"] is False
    assert "the line changes part-way (at x = " in r["domain_reason"]
    assert r["change_nm"] == pytest.approx(5.0, abs=0.5)
    plain = judge(sawtooth())
    assert plain["in_domain"] is True and plain["change_nm"] is None



@pytest.mark.parametrize("change_nm", [3.0, 7.5])
def test_a_change_off_the_middle_is_located_where_it_is(change_nm):
    # the levels' clipping once drew every change towards the line's middle
    r = judge(tip_change_sawtooth(change_nm))
    assert r["in_domain"] is False
    assert r["change_nm"] == pytest.approx(change_nm, abs=0.5)


def test_a_step_of_the_force_level_is_a_change_and_a_smooth_drift_is_not():
    # a barrier that grows 1.5x at high eta moves the peaks and valleys, not the drops
    base = sawtooth()
    step = judge(base + np.where(X < 7.0, 0.0, 0.8))
    assert step["in_domain"] is False
    assert step["change_nm"] == pytest.approx(7.0, abs=0.5)
    # a drift that moves the level by as much, smoothly (a parabola), is no regime
    u = X / X[-1]
    drift = judge(base + 0.8 * (3.0 * u**2 - 2.0 * u**3))
    assert drift["change_nm"] is None, drift["domain_reason"]


@pytest.mark.slow
def test_the_bundled_contact_probe_flags_contacts_no_single_pt_describes():
    # multi-asperity lines at the paper preset (seed 4471, used by nothing else): the
    # bundled probe puts out most of those whose T = 0 waveform no single PT describes,
    # and none of those one describes within 1 %
    from stickslip.estimators.load import load_estimator
    from stickslip.simulators.contacts import contact_set

    line = load_estimator(None)
    assert line.embedding_reference.probe is not None, "bundled reference without its probe"
    cs = contact_set(40, "multi", seed=4471)
    traces = [Trace(cs.x_nm, f, f"multi:{i}", "contacts", {"lattice_nm": A})
              for i, f in enumerate(cs.force_nN)]  # fmt: skip
    rows = line.predict(traces).rows
    probe = np.array([r.get("domain_contacts", np.nan) for r in rows])
    misfit = np.asarray(cs.truth["misfit_fraction"])
    several, described = misfit > 0.05, misfit <= 0.01
    assert several.sum() >= 8 and described.sum() >= 15
    # 10 of 16 and 0 of 22 when written (2026-11-30)
    assert np.mean(probe[several] > 1.0) >= 0.4, probe[several]
    assert np.mean(probe[described] > 1.0) <= 0.05, probe[described]
    for r, p in zip(rows, probe, strict=True):
        if p > 1.0:
            assert r["in_domain"] is False and "more than one contact" in r["domain_reason"]
