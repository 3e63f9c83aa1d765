"""Metrics and evaluation outputs."""

from __future__ import annotations

import json

import numpy as np
import pytest

from stickslip.diagnostics.metrics import (
    PAPER_MD_MD_RMSE,
    TARGET_RMSE,
    format_table,
    metrics_csv,
    regression_metrics,
    write_metrics,
)
from stickslip.diagnostics.plots import loss_curve, parity_plot, point_density, window_panels


def test_regression_metrics_values():
    t = np.array([1.0, 2.0, 4.0, np.nan])
    p = np.array([1.5, 2.0, 3.0, 7.0])
    m = regression_metrics(t, p)
    assert m["n"] == 3
    assert m["rmse"] == pytest.approx(np.sqrt((0.25 + 0 + 1) / 3))
    assert m["bias"] == pytest.approx((0.5 - 1) / 3)
    assert m["rel_mean_abs"] == pytest.approx((0.5 + 0 + 0.25) / 3)
    assert m["rel_median_abs"] == pytest.approx(0.25)
    assert regression_metrics(t, t)["r2"] == pytest.approx(1.0)
    assert np.isnan(regression_metrics([], [])["rmse"])


def test_targets_are_half_the_paper_row():
    assert TARGET_RMSE == {k: v / 2 for k, v in PAPER_MD_MD_RMSE.items()}
    assert TARGET_RMSE["K_N_m"] == pytest.approx(0.42)


def test_write_metrics_and_plots(tmp_path):
    rng = np.random.default_rng(0)
    t = {"U0_eV": rng.uniform(0.3, 6, 200), "K_N_m": rng.uniform(1, 50, 200)}
    p = {k: v * (1 + 0.05 * rng.normal(size=v.size)) for k, v in t.items()}
    table = {k: regression_metrics(t[k], p[k]) for k in t}
    write_metrics(table, tmp_path / "m.json", tmp_path / "m.csv", {"model": "x"})
    doc = json.loads((tmp_path / "m.json").read_text())
    assert doc["model"] == "x" and doc["metrics"]["K_N_m"]["n"] == 200
    assert metrics_csv(table).splitlines()[0].startswith("target,n,rmse")
    assert "U0_eV" in format_table(table)
    assert point_density(t["U0_eV"], p["U0_eV"]).shape == (200,)
    for path in (
        parity_plot(t, p, table, tmp_path / "parity.png"),
        loss_curve([1.0, 0.5, 0.2], [1.1, 0.6, 0.3], tmp_path / "loss.png"),
        window_panels(np.arange(100) * 0.02, np.sin(np.arange(100)), np.array([0.5, 1.5]),
                      {"U0_eV": np.array([1.0, 1.1]), "K_N_m": np.array([5.0, 5.5])},
                      {"U0_eV": 1.05, "K_N_m": 5.25}, tmp_path / "panels.png",
                      reference={"U0_eV": 1.0, "K_N_m": np.nan}),
    ):  # fmt: skip
        assert path.stat().st_size > 1000 and path.read_bytes()[:4] == b"\x89PNG"


def test_interval_score_is_least_for_the_true_quantiles():
    from stickslip.diagnostics.metrics import interval_score

    rng = np.random.default_rng(0)
    y = rng.normal(0.0, 1.0, 200000)
    scores = {h: interval_score(y, -h, h, 0.05).mean() for h in (1.5, 1.96, 2.5)}
    assert scores[1.96] < scores[1.5] and scores[1.96] < scores[2.5]
    # a truth outside pays the width plus 2/alpha times the miss
    miss = interval_score(np.array([3.0]), np.array([-1.0]), np.array([1.0]), 0.05)[0]
    assert miss == 2.0 + 40.0 * 2.0


def test_target_metrics_report_score_width_and_sharpness():
    from stickslip.diagnostics.metrics import target_metrics

    rng = np.random.default_rng(1)
    t = np.exp(rng.uniform(0, 1, 20000))
    p = t * np.exp(rng.normal(0.0, 0.05, t.size))
    wide = target_metrics(t, p, {"95": (p * np.exp(-0.2), p * np.exp(0.2))})
    sharp = target_metrics(t, p, {"95": (p * np.exp(-0.098), p * np.exp(0.098))})
    assert wide["coverage95"] > 0.999 and abs(sharp["coverage95"] - 0.95) < 0.01
    assert sharp["interval_score95"] < wide["interval_score95"]
    # a calibrated Gaussian interval has a sharpness ratio near 1, one twice as wide near 2
    assert 0.9 < sharp["sharpness95"] < 1.1 and 1.8 < wide["sharpness95"] < 2.3
