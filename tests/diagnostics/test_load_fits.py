"""Friction against load: both laws recover known parameters within their uncertainties."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from stickslip.diagnostics import load_fits as lf

LOADS = np.linspace(-1.5, 20.0, 8)  # nN, a ramp that starts in the adhesive (negative) range


def _dmt(L: np.ndarray, c: float, L_adh: float) -> np.ndarray:
    return c * np.cbrt(L + L_adh) ** 2


def test_linear_fit_recovers_parameters_with_honest_uncertainties():
    rng = np.random.default_rng(0)
    mu, F0, sigma = 0.12, 0.8, 0.05
    inside = {"mu": 0, "F0": 0}
    n = 400
    for _ in range(n):
        F = mu * LOADS + F0 + rng.normal(0, sigma, LOADS.size)
        fit = lf.fit_linear(LOADS, F, np.full(LOADS.size, sigma))
        for name, true in (("mu", mu), ("F0", F0)):
            v, s = fit.param(name)
            inside[name] += abs(v - true) <= s
    # 68 % intervals cover about 68 % (a little more: the errors are widened where the
    # scatter exceeds them, never narrowed)
    for name in inside:
        assert 0.64 <= inside[name] / n <= 0.85, (name, inside[name] / n)


def test_dmt_fit_recovers_parameters_within_uncertainty():
    rng = np.random.default_rng(1)
    c, L_adh, sigma = 0.35, 4.0, 0.03
    hits = {"c": 0, "L_adh": 0}
    n = 200
    for _ in range(n):
        F = _dmt(LOADS, c, L_adh) + rng.normal(0, sigma, LOADS.size)
        fit = lf.fit_dmt(LOADS, F, np.full(LOADS.size, sigma))
        assert fit.note == ""
        for name, true in (("c", c), ("L_adh", L_adh)):
            v, s = fit.param(name)
            hits[name] += abs(v - true) <= 2 * s
    for name in hits:
        assert hits[name] / n >= 0.9, (name, hits[name] / n)


def test_both_laws_reported_and_goodness_tells_them_apart():
    rng = np.random.default_rng(2)
    sigma = np.full(LOADS.size, 0.01)
    F = _dmt(LOADS, 0.35, 4.0) + rng.normal(0, 0.01, LOADS.size)
    linear, dmt = lf.fit_load_laws(LOADS, F, sigma)
    assert (linear.law, dmt.law) == ("linear", "dmt")
    assert dmt.chi2_red < 3 < linear.chi2_red  # curved data: the straight line misfits
    # straight data with a large offset: the 2/3 law far from its origin is straight too
    # (F0/mu = 1.5 L_adh), both describe them
    F = 0.01 * LOADS + 2.0 + rng.normal(0, 0.01, LOADS.size)
    linear, dmt = lf.fit_load_laws(LOADS, F, sigma)
    assert linear.chi2_red < 3 and dmt.chi2_red < 3
    assert dmt.param("L_adh")[0] == pytest.approx(200 / 1.5, rel=0.5)
    # data curving upwards: the 2/3 law runs to its limit and says so
    F = 0.01 * (LOADS + 2.0) ** 2 + rng.normal(0, 0.01, LOADS.size)
    linear, dmt = lf.fit_load_laws(LOADS, F, sigma)
    assert "curve the other way" in dmt.note
    line = linear.summary("nN", "nN")
    assert line.startswith("linear: F = mu L + F0: mu = 0.2252 +- 0.025 nN/nN")
    assert "chi2/dof" in line


def test_unweighted_fit_uses_residual_scatter():
    F = 0.2 * LOADS + 1.0 + np.array([0.02, -0.01, 0.0, 0.015, -0.02, 0.01, -0.005, 0.0])
    fit = lf.fit_linear(LOADS, F)
    assert math.isnan(fit.chi2_red)
    mu, s = fit.param("mu")
    assert mu == pytest.approx(0.2, abs=3 * s) and 0 < s < 0.01
    assert fit.predict(np.array([0.0]))[0] == pytest.approx(fit.param("F0")[0])


def test_too_few_points_is_a_clear_error():
    with pytest.raises(ValueError, match="at least 3 loads"):
        lf.fit_linear([1.0, 2.0], [0.1, 0.2])
    fits, reason = lf.fit_or_reason([{"load": 1.0, "friction_mean": 0.1, "n": 1}])
    assert fits == [] and "at least 3" in reason


def test_estimates_by_load_uses_line_intervals_or_spread():
    rows = [
        {"load": "10", "load_unit": "nN", "quality": "ok", "U0_eV": "1.0", "U0_eV_lo68": "0.9",
         "U0_eV_hi68": "1.1", "K_N_m": "10", "K_N_m_lo68": "9", "K_N_m_hi68": "11"},
        {"load": "10", "load_unit": "nN", "quality": "ok", "U0_eV": "1.2", "U0_eV_lo68": "1.1",
         "U0_eV_hi68": "1.3", "K_N_m": "12", "K_N_m_lo68": "11", "K_N_m_hi68": "13"},
        {"load": "20", "load_unit": "nN", "quality": "too noisy", "U0_eV": "", "K_N_m": ""},
        {"load": "20", "load_unit": "nN", "quality": "ok", "U0_eV": "1.5", "K_N_m": "14"},
        {"load": "20", "load_unit": "nN", "quality": "ok", "U0_eV": "1.7", "K_N_m": "16"},
    ]
    s = lf.estimates_by_load(rows)
    assert [r["load"] for r in s] == [10.0, 20.0]
    assert s[0]["U0_eV_mean"] == pytest.approx(1.1)
    assert (s[0]["U0_eV_lo"], s[0]["U0_eV_hi"]) == pytest.approx((1.0, 1.2))  # median interval
    assert s[1]["U0_eV_n"] == 2  # the flagged line is left out
    half = np.std([1.5, 1.7], ddof=1)
    assert (s[1]["U0_eV_lo"], s[1]["U0_eV_hi"]) == pytest.approx((1.6 - half, 1.6 + half))
    assert s[1]["U0_eV_interval"] == "spread over lines"


def test_read_estimate_rows_errors_are_one_line(tmp_path):
    bad = tmp_path / "x.csv"
    bad.write_text("trace,U0_eV\na,1\n")
    with pytest.raises(ValueError, match="no load column"):
        lf.read_estimate_rows(bad)
    with pytest.raises(ValueError, match="cannot read"):
        lf.read_estimate_rows(tmp_path / "missing.csv")
    with pytest.raises(ValueError, match=r"\.csv or \.json"):
        lf.read_estimate_rows(tmp_path / "x.txt")


# ---------------------------------------------------------------- the command on real files

RAMP = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "bruker-friction-ramp"
needs_ramp = pytest.mark.skipif(not RAMP.is_dir(), reason="shared/data (real files) missing")


def _cli(args: list) -> object:
    from typer.testing import CliRunner

    from stickslip.cli.main import app

    return CliRunner().invoke(app, [str(a) for a in args])


@needs_ramp
def test_ramp_folder_skips_force_curve_with_a_note():
    found = lf.collect_friction_rows([RAMP])
    assert found.errors == []
    assert len(found.rows) == 5 * 32
    assert len(found.notes) == 2
    assert any("si.0_00143.spm" in n and "force curve" in n for n in found.notes)
    assert any("exampleFrictionProfileFull.txt" in n and "no load" in n for n in found.notes)
    # named explicitly, the force curve stays an error
    named = lf.collect_friction_rows([RAMP / "si.0_00143.spm", RAMP / "si.0_00150.spm"])
    assert len(named.errors) == 1 and "si.0_00143.spm" in str(named.errors[0])


@needs_ramp
def test_friction_load_folder_fits_both_laws(tmp_path):
    est = tmp_path / "est.csv"
    est.write_text("trace,quality,load,load_unit,U0_eV,U0_eV_lo68,U0_eV_hi68,K_N_m\n"
                   "a,ok,-1.4,V,1.0,0.9,1.1,10\nb,ok,-1.4,V,1.2,1.1,1.3,12\n"
                   "c,ok,1.7,V,1.5,1.4,1.6,14\n")  # fmt: skip
    fits, plot = tmp_path / "fits.json", tmp_path / "fl.png"
    r = _cli(["friction-load", RAMP, "--out", plot, "--fits", fits, "--estimates", est])
    assert r.exit_code == 0, r.output
    notes = [ln for ln in r.stderr.splitlines() if "note:" in ln]
    assert len(notes) == 2 and not [ln for ln in r.stderr.splitlines() if "error" in ln]
    assert len(r.stdout.strip().splitlines()) == 6  # the per-load table: header + 5 loads
    assert "linear: F = mu L + F0: mu = 0.007963 +- 0.00095 V/V" in r.stderr
    assert "dmt: F = c (L + L_adh)^(2/3)" in r.stderr
    rows = json.loads(fits.read_text())
    assert [(x["law"], x["parameter"]) for x in rows] == [
        ("linear", "mu"), ("linear", "F0"), ("dmt", "c"), ("dmt", "L_adh")]
    assert all(x["std"] > 0 and x["chi2_red"] > 0 for x in rows)
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # a bad estimates table is one error line; the maps are still processed
    r = _cli(["friction-load", RAMP / "si.0_00150.spm", "--out", plot, "--estimates",
              tmp_path / "none.csv"])  # fmt: skip
    assert r.exit_code == 1 and "none.csv: cannot read" in r.stderr
    assert len(r.stdout.strip().splitlines()) == 2  # header + its load
    assert "no law fitted: need at least 3 loads" in r.stderr
