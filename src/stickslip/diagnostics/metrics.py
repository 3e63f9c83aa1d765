"""Regression metrics per target: RMSE, MAE, bias, R^2 and relative errors."""

from __future__ import annotations

import csv
import io
import json
import os
from collections.abc import Mapping

import numpy as np

from stickslip.atomic import write_text_atomic

METRIC_KEYS = ("n", "rmse", "mae", "bias", "r2", "rel_rmse", "rel_mean_abs", "rel_median_abs")

# the reference paper's MD->MD row, and this project's target (half of it)
PAPER_MD_MD_RMSE = {"F_mean_nN": 0.16, "U0_eV": 0.18, "K_N_m": 0.84}
TARGET_RMSE = {k: v / 2 for k, v in PAPER_MD_MD_RMSE.items()}


def regression_metrics(true: np.ndarray, pred: np.ndarray) -> dict[str, float]:
    """Metrics of predictions against true values (non-finite pairs are skipped).

    ``rel_*`` are based on ``(pred - true) / true``: its root mean square, mean of the
    absolute value and median of the absolute value.
    """
    t = np.asarray(true, dtype=float)
    p = np.asarray(pred, dtype=float)
    ok = np.isfinite(t) & np.isfinite(p)
    t, p = t[ok], p[ok]
    if t.size == 0:
        return {k: (0.0 if k == "n" else float("nan")) for k in METRIC_KEYS}
    err = p - t
    var = float(np.var(t))
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = err / t
    rel = rel[np.isfinite(rel)]
    return {
        "n": float(t.size),
        "rmse": float(np.sqrt(np.mean(err**2))),
        "mae": float(np.mean(np.abs(err))),
        "bias": float(np.mean(err)),
        "r2": float(1.0 - np.mean(err**2) / var) if var > 0 else float("nan"),
        "rel_rmse": float(np.sqrt(np.mean(rel**2))) if rel.size else float("nan"),
        "rel_mean_abs": float(np.mean(np.abs(rel))) if rel.size else float("nan"),
        "rel_median_abs": float(np.median(np.abs(rel))) if rel.size else float("nan"),
    }


def metrics_table(
    true: Mapping[str, np.ndarray], pred: Mapping[str, np.ndarray]
) -> dict[str, dict[str, float]]:
    """:func:`regression_metrics` for every target present in both mappings."""
    return {k: regression_metrics(true[k], pred[k]) for k in pred if k in true}


def metrics_csv(table: Mapping[str, Mapping[str, float]]) -> str:
    """The table as CSV text: one row per target, one column per metric."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["target", *METRIC_KEYS])
    for target, m in table.items():
        w.writerow([target, *(f"{m.get(k, float('nan')):.6g}" for k in METRIC_KEYS)])
    return buf.getvalue()


def write_metrics(
    table: Mapping[str, Mapping[str, float]],
    json_path: str | os.PathLike,
    csv_path: str | os.PathLike,
    extra: Mapping | None = None,
) -> None:
    """Write the table as JSON (with ``extra`` keys beside it) and as CSV, atomically."""
    doc = {"metrics": table, **(dict(extra) if extra else {})}
    write_text_atomic(json_path, json.dumps(doc, indent=2, sort_keys=True) + "\n")
    write_text_atomic(csv_path, metrics_csv(table))


def format_table(table: Mapping[str, Mapping[str, float]]) -> str:
    """Human-readable summary: RMSE, relative errors and R^2 per target."""
    lines = [f"{'target':<12}{'n':>6}{'RMSE':>10}{'bias':>10}{'rel RMS':>9}"
             f"{'rel mean':>9}{'rel med':>9}{'R2':>8}"]  # fmt: skip
    for t, m in table.items():
        lines.append(
            f"{t:<12}{int(m['n']):>6}{m['rmse']:>10.4g}{m['bias']:>10.3g}"
            f"{m['rel_rmse']:>9.2%}{m['rel_mean_abs']:>9.2%}{m['rel_median_abs']:>9.2%}"
            f"{m['r2']:>8.4f}"
        )
    return "\n".join(lines)


def interval_score(y: np.ndarray, lo: np.ndarray, hi: np.ndarray, alpha: float) -> np.ndarray:
    """The interval score of central ``1 - alpha`` intervals ``[lo, hi]`` for truths ``y``
    (Gneiting and Raftery 2007; Winkler 1972): the width, plus ``2 / alpha`` times how far
    the truth falls outside. A proper scoring rule: lower is better, and it is least in
    expectation for the true quantiles, so it rewards intervals that are as narrow as
    the data allow and no narrower."""
    y, lo, hi = (np.asarray(v, float) for v in (y, lo, hi))
    return (hi - lo) + (2.0 / alpha) * (np.maximum(lo - y, 0.0) + np.maximum(y - hi, 0.0))


def target_metrics(true: np.ndarray, pred: np.ndarray,
                   intervals: Mapping[str, tuple[np.ndarray, np.ndarray]] | None = None
                   ) -> dict[str, float]:  # fmt: skip
    """The evaluation metrics of one target over rows with a truth.

    Parameters
    ----------
    true, pred : ndarray (N,)
        Truths and estimates; a missing estimate (NaN) is a refusal: it counts in ``n``
        and not in ``answered`` or in the errors.
    intervals : mapping, optional
        ``{"68": (lo, hi), "95": (lo, hi)}``: interval bounds per row.

    Returns
    -------
    dict
        ``n`` (rows with a truth), ``answered`` (of those, rows with an estimate),
        ``rmse``, ``rel_rmse``, ``median_rel`` (median of |relative error|), ``bias``,
        and ``coverage68``/``coverage95`` where intervals are given, with, per level,
        ``interval_score{level}`` (:func:`interval_score`, mean over rows, on the
        relative scale ``ln`` for a positive target, else in the target's unit) and
        ``rel_halfwidth{level}`` (median of the half-width over |truth|); and
        ``sharpness95``: the median relative 95 % half-width over the one a calibrated
        Gaussian with these errors would have (``median_rel * 1.96 / 0.674``).
    """
    t = np.asarray(true, float)
    p = np.asarray(pred, float)
    has_truth = np.isfinite(t)
    ok = has_truth & np.isfinite(p)
    err = p[ok] - t[ok]
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = err / t[ok]
    rel = rel[np.isfinite(rel)]
    nan = float("nan")
    out = {
        "n": int(has_truth.sum()),
        "answered": int(ok.sum()),
        "rmse": float(np.sqrt(np.mean(err**2))) if err.size else nan,
        "rel_rmse": float(np.sqrt(np.mean(rel**2))) if rel.size else nan,
        "median_rel": float(np.median(np.abs(rel))) if rel.size else nan,
        "bias": float(np.mean(err)) if err.size else nan,
    }
    for level, (lo, hi) in (intervals or {}).items():
        lo, hi = np.asarray(lo, float)[ok], np.asarray(hi, float)[ok]
        inside = (t[ok] >= lo) & (t[ok] <= hi)
        out[f"coverage{level}"] = float(np.mean(inside)) if inside.size else nan
        alpha = 1.0 - float(level) / 100.0
        positive = bool(np.all(t[ok] > 0) and np.all(lo > 0))
        y, a, b = (np.log(t[ok]), np.log(lo), np.log(hi)) if positive else (t[ok], lo, hi)
        score = interval_score(y, a, b, alpha)
        out[f"interval_score{level}"] = float(np.mean(score)) if score.size else nan
        with np.errstate(divide="ignore", invalid="ignore"):
            half = 0.5 * (hi - lo) / np.abs(t[ok])
        half = half[np.isfinite(half)]
        out[f"rel_halfwidth{level}"] = float(np.median(half)) if half.size else nan
    if "rel_halfwidth95" in out and out["median_rel"] > 0:
        out["sharpness95"] = out["rel_halfwidth95"] / (out["median_rel"] * 1.959964 / 0.674490)
    return out
