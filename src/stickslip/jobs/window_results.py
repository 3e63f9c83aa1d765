"""The ``infer`` job as a library call: traces -> result rows, CSV table and panels.

One row per trace: the network's per-trace estimates (mean over windows), their
spread over windows (``*_std``), the number of windows, and the classical
estimator's values beside them (``classical_*``) when that estimator is available.
"""

from __future__ import annotations

import csv
import io
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from stickslip.atomic import write_text_atomic
from stickslip.estimators.window.inference import OUTPUTS, TraceEstimate, predict_traces
from stickslip.estimators.window.modelfile import TrainedModel

COLUMNS = ("trace", *OUTPUTS, *(f"{k}_std" for k in OUTPUTS), "n_windows", "F_mean_net",
           "lattice_nm", "source")  # fmt: skip
META_COLUMNS = ("direction", "line", "load", "load_unit")  # from map readers, where known
CLASSICAL = ("F_mean_nN", "U0_eV", "K_N_m", "eta", "regime", "quality")


@dataclass
class InferenceResult:
    """Rows of the result table, the estimates behind them and per-trace failures."""

    rows: list[dict[str, Any]]
    estimates: list[TraceEstimate]
    failures: list[tuple[str, str]]
    notes: list[str] = field(default_factory=list)


def _classical(
    traces: Sequence[Any], lattice: Sequence[float], temperature_K: float, velocity: Sequence[float]
) -> tuple[list[dict[str, Any]], str | None]:
    """Classical estimates in input order, or an explanation of why there are none.

    Traces are estimated in groups of equal lattice spacing and velocity.
    """
    try:
        from stickslip.estimators.classical import estimate_traces
    except ImportError:
        return [], None
    out: list[dict[str, Any]] = [{} for _ in traces]
    try:
        for a, v in sorted(set(zip(lattice, velocity, strict=True))):
            keys = list(zip(lattice, velocity, strict=True))
            idx = [i for i, key in enumerate(keys) if key == (a, v)]
            est = estimate_traces([traces[i] for i in idx], lattice_nm=a,
                                  temperature_K=temperature_K, velocity_nm_per_s=v)  # fmt: skip
            for i, e in zip(idx, est, strict=True):
                out[i] = {k: getattr(e, k) for k in CLASSICAL}
    except Exception as e:  # the classical columns are an extra; never fail the job on them
        return [], f"classical estimator failed ({type(e).__name__}: {e}); columns left out"
    return out, None


def run_inference(
    model: TrainedModel,
    traces: Sequence[Any],
    lattice_nm: float | None = None,
    velocity_nm_per_s: float | None = None,
    temperature_K: float | None = None,
    classical: bool = True,
    keep_windows: bool = False,
) -> InferenceResult:
    """Network (and classical) estimates for every trace that can be processed.

    ``lattice_nm`` maps the traces onto the training lattice (see
    :mod:`stickslip.estimators.window.inference`); velocity and temperature are passed to the
    classical estimator and compared with the training values (a note is returned
    when they differ: the mapping does not carry thermal activation over).
    """
    spec = model.features
    a = [float(lattice_nm or t.meta.get("lattice_nm") or spec.lattice_nm) for t in traces]
    v = [float(velocity_nm_per_s or t.meta.get("velocity_nm_per_s") or spec.velocity_nm_per_s)
         for t in traces]  # fmt: skip
    T = float(temperature_K if temperature_K is not None else spec.temperature_K)
    notes = []
    off = [x for x in set(v) if abs(x / spec.velocity_nm_per_s - 1) > 0.01]
    if off or abs(T - spec.temperature_K) > 1:
        notes.append(
            f"model trained at v = {spec.velocity_nm_per_s:g} nm/s, T = {spec.temperature_K:g} K;"
            f" traces at v = {', '.join(f'{x:g}' for x in sorted(set(v)))} nm/s, T = {T:g} K: "
            "thermal activation is not mapped (error on simulated traces: docs/learning.md)"
        )
    estimates, failures = predict_traces(model, list(traces), lattice_nm, keep_windows)
    extra, why = _classical(traces, a, T, v) if classical and estimates else ([], None)
    if why:
        notes.append(why)
    rows = []
    for e in estimates:
        row: dict[str, Any] = {"trace": e.trace, **e.values}
        row.update({f"{k}_std": e.std[k] for k in OUTPUTS})
        row["n_windows"] = e.n_windows
        row["lattice_nm"] = a[e.index]
        row["source"] = getattr(traces[e.index], "source", "")
        row.update({k: e.meta[k] for k in META_COLUMNS if e.meta.get(k) is not None})
        if extra:
            row.update({f"classical_{k}": v for k, v in extra[e.index].items()})
        rows.append(row)
    return InferenceResult(rows=rows, estimates=estimates, failures=failures, notes=notes)


def _columns(rows: Sequence[dict[str, Any]]) -> list[str]:
    cols = list(COLUMNS)
    for r in rows:
        cols += [k for k in r if k not in cols]
    return cols


def _fmt(v: Any) -> str:
    if isinstance(v, (float, np.floating)):
        return f"{float(v):.6g}"
    return str(v)


def rows_csv(rows: Sequence[dict[str, Any]]) -> str:
    """The result table as CSV text."""
    cols = _columns(rows)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    for r in rows:
        w.writerow([_fmt(r.get(c, "")) for c in cols])
    return buf.getvalue()


def write_results(rows: Sequence[dict[str, Any]], path: str | os.PathLike) -> Path:
    """Write the result table atomically."""
    write_text_atomic(path, rows_csv(rows))
    return Path(path)


def format_rows(rows: Sequence[dict[str, Any]], truth: dict[str, dict] | None = None) -> str:
    """A compact terminal table (estimates +- their spread, classical beside; for line
    models the goodness of fit, '!' where the check flags the trace)."""
    has_cl = any("classical_U0_eV" in r for r in rows)
    w = min(max([len(r["trace"]) for r in rows] + [5]), 40) + 1
    last = "n_windows" if "n_windows" in rows[0] else "gof" if "gof" in rows[0] else None
    head = f"{'trace':<{w}}{'<F> nN':>9}{'U0 eV':>15}{'K N/m':>15}{'eta':>8}"
    head += {"n_windows": f"{'win':>5}", "gof": f"{'gof':>6}", None: ""}[last]
    if has_cl:
        head += f"{'| classical U0':>15}{'K':>8}"
    if truth:
        head += f"{'| true U0':>10}{'K':>7}"
    lines = [head]
    for r in rows:
        s = (f"{r['trace'][: w - 1]:<{w}}{r['F_mean_nN']:>9.3f}"
             f"{r['U0_eV']:>8.3f}+-{r['U0_eV_std']:<5.2f}{r['K_N_m']:>8.2f}+-{r['K_N_m_std']:<5.2f}"
             f"{r['eta']:>8.2f}")  # fmt: skip
        if last == "n_windows":
            s += f"{r['n_windows']:>5d}"
        elif last == "gof":
            s += f"{r['gof']:>5.1f}{'!' if r.get('ppc_flag') else ' '}"
        if has_cl:
            cu, ck = r.get("classical_U0_eV", np.nan), r.get("classical_K_N_m", np.nan)
            s += f"{cu:>15.3f}{ck:>8.2f}"
        if truth and r["trace"] in truth:
            t = truth[r["trace"]]
            s += f"{t.get('U0_eV', np.nan):>10.3f}{t.get('K_N_m', np.nan):>7.2f}"
        lines.append(s)
    return "\n".join(lines)


def safe_name(name: str) -> str:
    """A file-name-safe version of a trace name."""
    return re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("_") or "trace"


def write_panels(result: InferenceResult, traces: Sequence[Any], out_dir: str | os.PathLike):
    """Per trace, the trace and its window-wise estimates (PNG files in ``out_dir``)."""
    from stickslip.diagnostics.plots import window_panels

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for i, (e, row) in enumerate(zip(result.estimates, result.rows, strict=True)):
        t = traces[e.index]
        ref = {k: row.get(f"classical_{k}", np.nan) for k in ("U0_eV", "K_N_m", "eta")}
        ref = {k: float(v) if isinstance(v, (int, float)) else np.nan for k, v in ref.items()}
        paths.append(window_panels(
            t.x_nm, t.force_nN, e.centres_nm, e.windows, e.values,
            out / f"{i:03d}_{safe_name(e.trace)}.png", title=e.trace, reference=ref,
        ))  # fmt: skip
    return paths
