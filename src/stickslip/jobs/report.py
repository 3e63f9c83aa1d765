"""Evaluate a model on a simulated dataset: predictions, metrics, plots and tables."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from stickslip.atomic import write_text_atomic
from stickslip.diagnostics.metrics import format_table, metrics_table, write_metrics
from stickslip.estimators.window.inference import PIXEL_TOLERANCE, map_trace, predict_array
from stickslip.estimators.window.modelfile import TrainedModel
from stickslip.traces.dataset import Dataset

EVAL_KEYS = ("F_mean_nN", "F_mean_net", "U0_eV", "K_N_m", "eta")


@dataclass
class Evaluation:
    """Per-trajectory truth and predictions, and their metrics."""

    true: dict[str, np.ndarray]
    pred: dict[str, np.ndarray]
    metrics: dict[str, dict[str, float]]

    def summary(self) -> str:
        return format_table(self.metrics)


def evaluate_model(
    model: TrainedModel,
    data: Dataset,
    rows: np.ndarray | None = None,
    batch: int = 4096,
    lattice_mapping: bool = True,
) -> Evaluation:
    """Per-trajectory estimates of a dataset's traces and the metrics against its labels.

    With ``lattice_mapping``, each trajectory's own lattice spacing
    (``params["lattice_nm"]``) is used to map it onto the training lattice; traces
    whose pixel differs from the training pixel are resampled either way.
    """
    rows = np.arange(data.n) if rows is None else np.asarray(rows)
    spec = model.features
    pixel = float((data.x_nm[-1] - data.x_nm[0]) / (data.x_nm.size - 1))

    lattice = np.asarray(data.params["lattice_nm"], dtype=float)[rows]
    forces = data.force_nN[rows]
    out: dict[str, list[np.ndarray]] = {k: [] for k in EVAL_KEYS}
    for a in np.unique(lattice) if lattice_mapping else [None]:
        sel = np.flatnonzero(lattice == a) if a is not None else np.arange(rows.size)
        for s in range(0, sel.size, batch):
            idx = sel[s : s + batch]
            f = forces[idx]
            scale = 1.0 if a is None else a / spec.lattice_nm
            if abs(pixel / scale / spec.pixel_nm - 1) > PIXEL_TOLERANCE:
                f = np.stack([map_trace(data.x_nm, fi, model, a) for fi in f])
            res = predict_array(model, f, lattice_nm=a)
            res["F_mean_nN"] = forces[idx].mean(axis=1)
            for k in EVAL_KEYS:
                out[k].append(np.column_stack([idx, res[k]]))
    pred = {}
    for k, parts in out.items():
        arr = np.concatenate(parts)
        v = np.empty(rows.size)
        v[arr[:, 0].astype(int)] = arr[:, 1]
        pred[k] = v
    true = {k: np.asarray(data.params[k], dtype=float)[rows] for k in EVAL_KEYS if k in data.params}
    true["F_mean_net"] = true["F_mean_nN"]
    return Evaluation(true=true, pred=pred, metrics=metrics_table(true, pred))


def write_evaluation(ev: Evaluation, out_dir: str | os.PathLike, extra: dict | None = None):
    """Write metrics.json, metrics.csv, predictions.csv and parity plots into ``out_dir``."""
    from stickslip.diagnostics.plots import parity_plot

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    write_metrics(ev.metrics, out / "metrics.json", out / "metrics.csv", extra)
    keys = list(ev.pred)
    header = ",".join([f"true_{k}" for k in keys] + [f"pred_{k}" for k in keys])
    rows = np.column_stack([ev.true[k] for k in keys] + [ev.pred[k] for k in keys])
    lines = [header] + [",".join(f"{v:.6g}" for v in r) for r in rows]
    write_text_atomic(out / "predictions.csv", "\n".join(lines) + "\n")
    main = {k: ev.pred[k] for k in ("F_mean_net", "U0_eV", "K_N_m")}
    parity_plot(ev.true, main, ev.metrics, out / "parity.png")
    parity_plot(ev.true, {"eta": ev.pred["eta"]}, ev.metrics, out / "parity_eta.png")
    return out
