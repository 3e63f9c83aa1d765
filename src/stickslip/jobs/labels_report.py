"""The labels CSV written by ``stickslip label``: one row per trace.

Required columns first, in this order: ``trace, F_mean_nN, U0_eV, K_N_m, eta, k_exp_N_m,
F_peak_nN, n_slips, regime, quality``, then their ``*_std`` columns (spread over slips),
then any trace metadata present (file, channel, direction, line, load, ...). Traces
that could not be read get a row with ``quality`` set to the reason and empty values.
"""

from __future__ import annotations

import csv
import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from stickslip.atomic import atomic_path
from stickslip.estimators.classical.estimator import ClassicalEstimate
from stickslip.traces.trace import TraceReadError

COLUMNS = (
    "trace", "F_mean_nN", "U0_eV", "K_N_m", "eta", "k_exp_N_m", "F_peak_nN", "n_slips",
    "regime", "quality",
)  # fmt: skip
STD_COLUMNS = tuple(f"{c}_std" for c in ("F_mean_nN", "U0_eV", "K_N_m", "eta", "k_exp_N_m",
                                         "F_peak_nN"))  # fmt: skip
SKIPPED_META = ("unit",)  # always nN once read


def _fmt(value: Any) -> str:
    if isinstance(value, float):
        return "" if math.isnan(value) else f"{value:.6g}"
    return str(value)


def label_rows(
    estimates: Sequence[ClassicalEstimate], errors: Sequence[TraceReadError] = ()
) -> tuple[list[str], list[dict[str, str]]]:
    """Header and string rows of the labels table (estimates first, then failures)."""
    meta_keys: list[str] = []
    for est in estimates:
        for k, v in est.meta.items():
            if k not in meta_keys and k not in SKIPPED_META and isinstance(v, str | int | float):
                meta_keys.append(k)
    own = {*COLUMNS, *STD_COLUMNS}
    # a trace's metadata may carry values under the same names (a simulated dataset
    # stores its true U0_eV, K_N_m ...): keep them, prefixed, never over the estimates
    meta_col = {k: f"meta_{k}" if k in own else k for k in meta_keys}
    header = [*COLUMNS, *STD_COLUMNS, *meta_col.values()]
    rows = []
    for est in estimates:
        d = est.as_dict()
        row = {c: _fmt(d[c]) for c in (*COLUMNS, *STD_COLUMNS)}
        row.update({meta_col[k]: _fmt(est.meta[k]) for k in meta_keys if k in est.meta})
        rows.append(row)
    for err in errors:
        rows.append({"trace": Path(err.path).stem, "quality": err.reason})
    return header, rows


def write_labels_csv(
    path: str | os.PathLike,
    estimates: Sequence[ClassicalEstimate],
    errors: Sequence[TraceReadError] = (),
) -> None:
    """Write the labels CSV atomically (see module docstring for the columns)."""
    header, rows = label_rows(estimates, errors)
    with atomic_path(path) as tmp:
        with open(tmp, "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=header, restval="")
            w.writeheader()
            w.writerows(rows)
