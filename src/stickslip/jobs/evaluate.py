"""The ``evaluate`` job: any estimator on any labelled set, scored one way.

A labelled set is a simulated sweep (HDF5 or Zarr: the truths are stored beside each
trace) or trace files with a truth table (columns ``trace, U0_eV, K_N_m, F_mean_nN``
and optionally ``eta``; as ``label`` writes it, or as a person writes it by hand).
Truth rows match result rows by the ``trace`` name ``infer`` writes; a name with no
result row, or given twice, is reported once and left out (counted).
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from stickslip.atomic import write_text_atomic
from stickslip.diagnostics.calibration import reliability_plot
from stickslip.diagnostics.metrics import target_metrics
from stickslip.diagnostics.plots import parity_plot
from stickslip.estimators.base import Estimator
from stickslip.estimators.table import (
    TARGETS,
    ResultTable,
    by_trace,
    domain_verdict,
    float_or_nan,
    has_estimate,
    read_table,
)
from stickslip.traces.dataset import Dataset, dataset_traces
from stickslip.units import eta_from

TRUTH_COLUMNS = ("trace", "U0_eV", "K_N_m", "F_mean_nN")
LEVELS = ("68", "95")


class TruthError(ValueError):
    """A truth table that cannot be used (one line)."""


@dataclass
class Evaluation:
    """Truth-matched rows and the metrics of every target."""

    metrics: dict[str, dict[str, float]]
    truth: dict[str, np.ndarray]
    table: ResultTable
    problems: list[str] = field(default_factory=list)
    info: dict[str, Any] = field(default_factory=dict)

    def summary(self) -> str:
        """A terminal table: one line per target."""
        head = (f"{'target':<11}{'n':>6}{'answered':>9}{'RMSE':>10}{'rel RMS':>9}{'rel med':>9}"
                f"{'cov68':>7}{'cov95':>7}")  # fmt: skip
        lines = [head]
        for k, m in self.metrics.items():
            c68, c95 = m.get("coverage68"), m.get("coverage95")
            lines.append(
                f"{k:<11}{m['n']:>6}{m['answered']:>9}{m['rmse']:>10.4g}{m['rel_rmse']:>9.2%}"
                f"{m['median_rel']:>9.2%}"
                + (f"{c68:>7.3f}{c95:>7.3f}" if c68 is not None else f"{'-':>7}{'-':>7}")
            )
        if self.domain is not None:
            n_in, n_out = self.domain
            lines.append(f"in domain: {n_in} of {n_in + n_out} rows with an estimate"
                         + (f" ({n_in / (n_in + n_out):.3f}); the {n_out} out of domain count "
                            "above with their widened intervals" if n_out else ""))  # fmt: skip
        return "\n".join(lines)

    @property
    def domain(self) -> tuple[int, int] | None:
        """Rows in domain and out of domain among the matched rows with an estimate;
        None for an estimator without the in/out-of-domain verdict."""
        verdicts = [domain_verdict(r) for r in self.table.rows if has_estimate(r)]
        if all(v is None for v in verdicts):
            return None
        return sum(v is True for v in verdicts), sum(v is False for v in verdicts)


def truth_from_table(path: str | os.PathLike) -> dict[str, dict[str, float]]:
    """Truths by trace name from a CSV table (see the module docstring).

    Raises
    ------
    TruthError
        If the file cannot be read or lacks the ``trace`` column or every target.
    """
    try:
        rows = read_table(path)
    except FileNotFoundError:
        raise TruthError(f"{path}: truth table not found") from None
    except IsADirectoryError:
        raise TruthError(f"{path}: is a folder; --truth needs a table file (.csv, .json)") from None
    except UnicodeDecodeError:
        raise TruthError(f"{path}: truth table is not text (a CSV or JSON table)") from None
    except OSError as e:
        raise TruthError(f"{path}: cannot read truth table ({e.strerror or e})") from None
    if not rows or "trace" not in rows[0]:
        raise TruthError(f"{path}: truth table needs columns {', '.join(TRUTH_COLUMNS)}")
    if not any(k in rows[0] for k in TARGETS):
        raise TruthError(f"{path}: truth table has none of {', '.join(TARGETS)}")
    out: dict[str, dict[str, float]] = {}
    dup: set[str] = set()
    for r in rows:
        name = r["trace"]
        if name in out:
            dup.add(name)
        out[name] = {k: float_or_nan(r.get(k)) for k in TARGETS}
    for name in dup:  # a name given twice cannot be matched
        out[name] = {"duplicate": 1.0}
    return out


def truth_from_traces(table: ResultTable, traces: Sequence[Any]) -> dict[str, dict[str, float]]:
    """Truths stored with the traces themselves (simulated sweeps keep their params)."""
    out: dict[str, dict[str, float]] = {}
    for row, t in zip(table.rows, traces, strict=False):
        if t is None:
            continue
        meta = t.meta
        if all(k in meta for k in ("U0_eV", "K_N_m")):
            out[row["trace"]] = {k: float_or_nan(meta.get(k)) for k in TARGETS}
    return out


def evaluate(table: ResultTable, truth: Mapping[str, Mapping[str, float]],
             intervals: bool | None = None) -> Evaluation:  # fmt: skip
    """Match rows to truths by trace name and score every target.

    Rows of unreadable inputs and refusals count in ``n`` and not in ``answered``.
    """
    problems: list[str] = []
    rows = by_trace(table.rows)
    matched: list[tuple[Mapping[str, Any], Mapping[str, float]]] = []
    for name, t in truth.items():
        if "duplicate" in t:
            problems.append(f"{name}: named twice in the truth table; left out")
        elif name not in rows:
            problems.append(f"{name}: no result row with this trace name; left out")
        elif len(rows[name]) > 1:
            problems.append(f"{name}: {len(rows[name])} result rows share this name; left out")
        else:
            matched.append((rows[name][0], t))
    intervals = table.intervals if intervals is None else intervals
    true = {k: np.array([t.get(k, np.nan) for _, t in matched]) for k in TARGETS}
    if np.all(np.isnan(true["eta"])) and matched:
        a = np.array([float_or_nan(r.get("lattice_nm")) for r, _ in matched])
        true["eta"] = eta_from(true["U0_eV"], true["K_N_m"], a)
    kept = ResultTable(rows=[dict(r) for r, _ in matched], estimator=table.estimator,
                       intervals=table.intervals)  # fmt: skip
    metrics = {}
    for k in TARGETS:
        pred = kept.column(k)
        iv = {lv: (kept.column(f"{k}_lo{lv}"), kept.column(f"{k}_hi{lv}")) for lv in LEVELS}
        m = target_metrics(true[k], pred, iv if intervals else None)
        metrics[k] = m
    for r, t in zip(kept.rows, (t for _, t in matched), strict=True):
        r.update({f"true_{k}": t.get(k) for k in TARGETS})
    return Evaluation(metrics=metrics, truth=true, table=kept, problems=problems)


def write_evaluation(ev: Evaluation, out_dir: str | os.PathLike,
                     info: Mapping[str, Any] | None = None) -> list[Path]:  # fmt: skip
    """``metrics.json`` (one object per target at its top level; other information
    under other keys), ``predictions.csv`` (the matched rows with their truths),
    ``parity.png`` and, for estimators with intervals, ``reliability.png``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    doc: dict[str, Any] = {k: _json_safe(m) for k, m in ev.metrics.items()}
    doc.update({"info": _json_safe(dict(info or {})), "left_out": ev.problems})
    if ev.domain is not None:
        doc["domain"] = {"in_domain": ev.domain[0], "out_of_domain": ev.domain[1]}
    paths = [out / "metrics.json", out / "metrics.csv", out / "predictions.csv",
             out / "parity.png"]
    write_text_atomic(paths[0], json.dumps(doc, indent=2) + "\n")
    keys = list(next(iter(ev.metrics.values()))) if ev.metrics else []
    lines = [",".join(["target", *keys])]
    lines += [",".join([k, *("" if not np.isfinite(m[c]) else f"{m[c]:.6g}" for c in keys)])
              for k, m in ev.metrics.items()]  # fmt: skip
    write_text_atomic(paths[1], "\n".join(lines) + "\n")
    ev.table.write(paths[2])
    pred = {k: ev.table.column(k) for k in TARGETS}
    parity_plot(ev.truth, pred, {k: {"rmse": m["rmse"], "rel_mean_abs": m["median_rel"]}
                                 for k, m in ev.metrics.items()}, paths[3],
                title=f"{ev.table.estimator}: estimate against truth")  # fmt: skip
    if ev.table.intervals and len(ev.table):
        curves = {}
        for k in TARGETS:
            nominal = np.array([0.68, 0.95])
            observed = np.array([ev.metrics[k].get("coverage68", np.nan),
                                 ev.metrics[k].get("coverage95", np.nan)])  # fmt: skip
            curves[k] = (nominal, observed)
        paths.append(out / "reliability.png")
        reliability_plot(curves, f"{ev.table.estimator}: interval coverage", paths[-1])
    return paths


def _json_safe(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {str(k): _json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_json_safe(v) for v in obj]
    if isinstance(obj, (float, np.floating)):
        return None if not np.isfinite(obj) else float(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    return obj


def evaluate_dataset(estimator: Estimator, data: Dataset, rows: np.ndarray | None = None,
                     name: str = "sweep", **conditions: float | None) -> Evaluation:  # fmt: skip
    """An estimator on rows of an in-memory simulated set, scored against its params.

    ``conditions`` (``lattice_nm``, ``velocity_nm_per_s``, ``temperature_K``) are passed
    to the estimator as user values; by default each trace's own (from its params) are
    used.
    """
    traces = dataset_traces(data, rows, name)
    table = estimator.predict(traces, **conditions)
    return evaluate(table, truth_from_traces(table, traces))
