"""The result table every estimator returns: one row per trace, one set of column names.

Columns, in this order where present:

- ``trace`` (the name ``infer`` writes: the file stem for a one-trace file, the line's
  full name for map lines), ``estimator``, ``quality`` (``ok`` or the reason there is
  no estimate: a refusal, or an unreadable input);
- the estimates ``F_mean_nN, U0_eV, K_N_m, eta``, then ``*_std``, and where the
  estimator gives intervals ``*_lo68, *_hi68, *_lo95, *_hi95``; a trace in volts (read
  without a calibration) has ``F_mean_V, U0_V_nm, K_V_per_nm`` instead (:data:`VOLT_NAMES`:
  volts are never shown as nN);
- the conditions used and the source of each (:mod:`stickslip.conditions`);
- provenance: ``file, channel, direction, line, load, load_unit``;
- then the estimator's own columns (``regime``, ``k_exp_N_m``, ``n_windows``, ``gof``,
  ``classical_*`` ...), and any other metadata of the trace (``meta_*`` where its name
  is taken).

One file convention for every format: a missing value is an empty cell in CSV and
``null`` in JSON. ``--out`` picks the format by extension (``.csv``, ``.json``,
``.parquet``; the last needs pyarrow, ``pip install 'stickslip[parquet]'``).
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from stickslip.atomic import atomic_path, write_text_atomic
from stickslip.conditions import QUANTITIES
from stickslip.traces.trace import READ_NOTE
from stickslip.units import EV_TO_NN_NM

TARGETS = ("F_mean_nN", "U0_eV", "K_N_m", "eta")
BOUNDS = ("lo68", "hi68", "lo95", "hi95")
HEAD = ("trace", "estimator", "quality")
#: Names of the estimates of a trace in volts (read without a calibration): <F> in V,
#: U0 = F_max a / pi in V nm, K and the stick slopes in V/nm, the peak force and the
#: noise in V; eta does not depend on the calibration and keeps its name.
VOLT_NAMES = {"F_mean_nN": "F_mean_V", "U0_eV": "U0_V_nm", "K_N_m": "K_V_per_nm",
              "k_exp_N_m": "k_exp_V_per_nm", "F_peak_nN": "F_peak_V", "noise_nN": "noise_V"}
VOLT_TARGETS = tuple(VOLT_NAMES[k] for k in TARGETS[:3])
STD_COLUMNS = tuple(f"{k}_std" for k in TARGETS)
VOLT_STD_COLUMNS = tuple(f"{k}_std" for k in VOLT_TARGETS)
INTERVAL_COLUMNS = tuple(f"{k}_{b}" for b in BOUNDS for k in TARGETS)
CONDITION_COLUMNS = tuple(c for q in QUANTITIES for c in (q, q.split("_")[0] + "_source"))
PROVENANCE = ("file", "channel", "direction", "line", "load", "load_unit")
COLUMNS = (*HEAD, *TARGETS[:3], *VOLT_TARGETS, TARGETS[3], *STD_COLUMNS[:3], *VOLT_STD_COLUMNS,
           STD_COLUMNS[3], *INTERVAL_COLUMNS, *CONDITION_COLUMNS, *PROVENANCE)  # fmt: skip
OK = "ok"
#: The ``quality`` of a row refused because the line is two regimes (its sticks change
#: slope part-way): the verdict then says where.
TWO_REGIMES = "two regimes"
TABLE_SUFFIXES = (".csv", ".json", ".parquet")
# trace metadata that is not provenance: the unit is a reading detail, the conditions
# have their own columns
_SKIP_META = {"unit", "calibrated", "unusable", READ_NOTE, *QUANTITIES}


class TableFormatError(ValueError):
    """An output path whose extension is not a table format."""


def table_format(path: str | os.PathLike) -> str:
    """The table format of an output path (``csv``, ``json`` or ``parquet``).

    Raises
    ------
    TableFormatError
        For any other extension (one line naming it and the choices).
    """
    suffix = Path(path).suffix.lower()
    if suffix not in TABLE_SUFFIXES:
        raise TableFormatError(
            f"{path}: unknown table format '{suffix or '(none)'}'; use "
            + ", ".join(TABLE_SUFFIXES)
        )
    return suffix[1:]


def is_missing(value: Any) -> bool:
    """True for None and NaN (the one 'missing' of the table)."""
    if value is None:
        return True
    return isinstance(value, (float, np.floating)) and math.isnan(value)


def truthy(value: Any) -> bool:
    """A flag column's value as a bool (a missing one is False); read back from a file,
    ``"true"``, ``"1"``, ``"yes"`` ... too."""
    if is_missing(value):
        return False
    if isinstance(value, str):
        return value.strip().lower() in ("1", "true", "yes", "y", "t")
    try:
        return bool(value)
    except (TypeError, ValueError):
        return False


def domain_verdict(row: Mapping[str, Any]) -> bool | None:
    """A row's in/out-of-domain verdict (``in_domain``): True, False, or None where the
    row has none (an estimator without the verdict, or a missing value: an empty cell of
    a table read back from CSV too)."""
    value = row.get("in_domain")
    return None if is_missing(value) or value == "" else truthy(value)


def has_estimate(row: Mapping[str, Any]) -> bool:
    """True for a row with estimate columns (in nN units or, for volts, in V units)."""
    return "U0_eV" in row or VOLT_NAMES["U0_eV"] in row


def to_volt_columns(row: Mapping[str, Any]) -> dict[str, Any]:
    """A row estimated on forces in volts, with its columns named and scaled in volts.

    An estimator reading volts as if they were nN gives ``F_mean_nN`` (V), ``K_N_m``
    (V/nm) and ``U0_eV`` (V nm divided by 1 eV in nN nm); they become ``F_mean_V``,
    ``K_V_per_nm`` and ``U0_V_nm`` (:data:`VOLT_NAMES`, with their ``_std`` ... suffixes).
    """
    out: dict[str, Any] = {}
    for key, value in row.items():
        base = next((b for b in VOLT_NAMES if key == b or key.startswith(b + "_")), None)
        if base is None:
            out[key] = value
            continue
        if base == "U0_eV" and isinstance(value, (int, float, np.number)) \
                and not is_missing(value):  # fmt: skip
            value = float(value) * EV_TO_NN_NM
        out[VOLT_NAMES[base] + key[len(base):]] = value
    return out


def _plain(value: Any) -> Any:
    if is_missing(value):
        return None
    if isinstance(value, (np.bool_, bool)):
        return bool(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.floating):
        return float(value)
    return value


def provenance(trace: Any) -> dict[str, Any]:
    """The provenance columns of a trace, and its other scalar metadata."""
    meta = dict(getattr(trace, "meta", {}) or {})
    row: dict[str, Any] = {"file": getattr(trace, "source", "") or None}
    for k in PROVENANCE[1:]:
        if not is_missing(meta.get(k)):
            row[k] = meta[k]
    for k, v in meta.items():
        if k in row or k in _SKIP_META or k in PROVENANCE:
            continue
        if isinstance(v, (str, int, float, np.integer, np.floating)) and not is_missing(v):
            row[f"meta_{k}" if k in COLUMNS or k.startswith("classical_") else k] = v
    return row


@dataclass
class ResultTable:
    """Rows of estimates (dicts keyed by column name), with the table's metadata.

    Attributes
    ----------
    rows : list of dict
        One per trace; a missing value is None or NaN.
    estimator : str
        Name of the estimator that made the rows.
    intervals : bool
        Whether the rows carry ``*_lo68 ... *_hi95``.
    notes : list of str
        Things the user should know about the run (one line each).
    """

    rows: list[dict[str, Any]] = field(default_factory=list)
    estimator: str = ""
    intervals: bool = False
    notes: list[str] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.rows)

    @property
    def columns(self) -> list[str]:
        """Column order: the standard columns present, then the others as first seen."""
        seen: dict[str, None] = {}
        for r in self.rows:
            for k in r:
                seen.setdefault(k, None)
        always: set[str] = set()
        if self.estimator:
            # an estimator's table has its estimates as columns even where every row was
            # refused (code reading df["U0_eV"] must not depend on the data): in nN units
            # unless the rows carry only volts
            nN = any(c in seen for c in (*TARGETS[:3], *STD_COLUMNS[:3]))
            volts = any(c in seen for c in (*VOLT_TARGETS, *VOLT_STD_COLUMNS))
            always.update((TARGETS[3], STD_COLUMNS[3]))
            if nN or not volts:
                always.update((*TARGETS[:3], *STD_COLUMNS[:3]))
        if self.intervals:  # intervals are columns even if every value is missing
            always.update(INTERVAL_COLUMNS)
        std = [c for c in COLUMNS if c in seen or c in always]
        return std + [c for c in seen if c not in COLUMNS]

    def ok(self) -> list[dict[str, Any]]:
        """Rows with an estimate."""
        return [r for r in self.rows if r.get("quality") == OK]

    def column(self, name: str) -> np.ndarray:
        """One numeric column as floats (NaN where missing or not a number)."""
        out = np.full(len(self.rows), np.nan)
        for i, r in enumerate(self.rows):
            v = r.get(name)
            if isinstance(v, (int, float, np.integer, np.floating)) and not is_missing(v):
                out[i] = float(v)
        return out

    def extend(self, other: ResultTable) -> None:
        """Append another table's rows and notes."""
        self.rows.extend(other.rows)
        self.notes.extend(n for n in other.notes if n not in self.notes)

    def records(self) -> list[dict[str, Any]]:
        """Rows as plain Python values, every column present (None where missing)."""
        cols = self.columns
        return [{c: _plain(r.get(c)) for c in cols} for r in self.rows]

    def to_frame(self):
        """The table as a pandas DataFrame (missing values as NaN / None)."""
        import pandas as pd

        return pd.DataFrame.from_records(self.records(), columns=self.columns)

    def to_csv(self) -> str:
        """CSV text: LF line endings, missing values as empty cells."""
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        cols = self.columns
        w.writerow(cols)
        for r in self.records():
            w.writerow([_cell(r[c]) for c in cols])
        return buf.getvalue()

    def write(self, path: str | os.PathLike) -> Path:
        """Write the table atomically in the format its extension names."""
        return write_records(self.records(), self.columns, path)

    def groups(self, calibration: Any = None):
        """The per-map pooled answer as a pandas DataFrame, one row per group of lines
        (a map's direction, its trace and retrace together, each side of a change
        point; columns :data:`stickslip.estimators.pooling.GROUP_COLUMNS`), the same
        table ``infer`` writes as ``<out>.groups.csv``.

        ``calibration``: a :class:`~stickslip.estimators.pooling.PoolingCalibration`
        (default: the bundled one).
        """
        import pandas as pd

        from stickslip.estimators.pooling import GROUP_COLUMNS, group_table

        records = [{c: _plain(v) for c, v in g.items()}
                   for g in group_table(self.rows, calibration)]  # fmt: skip
        return pd.DataFrame.from_records(records, columns=list(GROUP_COLUMNS))


def write_records(records: Sequence[Mapping[str, Any]], columns: Sequence[str],
                  path: str | os.PathLike) -> Path:  # fmt: skip
    """Write rows (plain values, None where missing) atomically in the format the
    extension names (``.csv``, ``.json``, ``.parquet``), columns in the order given."""
    fmt = table_format(path)
    path = Path(path)
    cols = list(columns)
    if fmt == "csv":
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(cols)
        for r in records:
            w.writerow([_cell(_plain(r.get(c))) for c in cols])
        write_text_atomic(path, buf.getvalue())
    elif fmt == "json":
        plain = [{c: _plain(r.get(c)) for c in cols} for r in records]
        write_text_atomic(path, json.dumps(plain, indent=1) + "\n")
    else:
        import pandas as pd

        frame = pd.DataFrame.from_records([{c: _plain(r.get(c)) for c in cols} for r in records],
                                          columns=cols)  # fmt: skip
        with atomic_path(path) as tmp:
            frame.to_parquet(tmp, index=False)
    return path


def sibling_path(out: str | os.PathLike, part: str) -> Path:
    """``<out stem>.<part><out suffix>`` beside ``out`` (``results.groups.csv``)."""
    out = Path(out)
    return out.with_name(f"{out.stem}.{part}{out.suffix}")


def _cell(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)


def failure_row(name: str, reason: str, estimator: str, file: str | None = None,
                extra: Mapping[str, Any] | None = None) -> dict[str, Any]:  # fmt: skip
    """The row of a trace (or an input) with no estimate: its name and the reason."""
    row = {"trace": name, "estimator": estimator, "quality": reason}
    if file:
        row["file"] = file
    row.update(extra or {})
    return row


def _finite(value: Any) -> bool:
    return (isinstance(value, (int, float, np.integer, np.floating))
            and not isinstance(value, (bool, np.bool_)) and math.isfinite(value))  # fmt: skip


def nonfinite_reason(row: Mapping[str, Any], intervals: bool) -> str | None:
    """Why an estimated row may not be written as ``ok`` (a sentence), or None.

    Every estimate (``F_mean_nN, U0_eV, K_N_m, eta``, or their volt names) must be a
    finite number, and so must every ``*_std`` the row holds and, for an estimator with
    ``intervals``, every interval bound: an overflow inside an estimator (a trace far
    outside what it can read) gives ``inf`` or NaN, never an answer.
    """
    names = (*VOLT_TARGETS, TARGETS[3]) if VOLT_NAMES["U0_eV"] in row else TARGETS
    need = list(names)
    need += [f"{k}_{b}" for b in BOUNDS for k in names] if intervals else []
    bad = [c for c in need if not _finite(row.get(c))]
    bad += [c for k in names if (c := f"{k}_std") in row and not _finite(row[c])]
    if not bad:
        return None
    shown = ", ".join(f"{c} = {row.get(c)}" for c in bad[:3]) + (", ..." if len(bad) > 3 else "")
    if all(_finite(row.get(k)) for k in names):
        # the values came out but not their uncertainty: a learned model whose members
        # disagree beyond any interval on a line unlike their training (not a unit slip)
        return (f"the estimate's uncertainty is unbounded ({shown}): the estimator cannot "
                "place this line, which lies far from what it was trained on; read it with "
                "the classical estimator")
    return (f"the estimate is not a finite number ({shown}): the trace lies outside what "
            "this estimator can read; check its units and conditions")


def read_table(path: str | os.PathLike) -> list[dict[str, str]]:
    """Rows of a CSV table as strings (as a person or ``label`` writes it)."""
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def concat(tables: Iterable[ResultTable]) -> ResultTable:
    """One table from several (rows in order; the first's estimator name)."""
    tables = list(tables)
    out = ResultTable(estimator=tables[0].estimator if tables else "",
                      intervals=any(t.intervals for t in tables))  # fmt: skip
    for t in tables:
        out.extend(t)
    return out


def float_or_nan(value: Any) -> float:
    """A table cell as float (NaN for empty or non-numeric)."""
    try:
        return float(value)
    except (TypeError, ValueError):
        return float("nan")


def by_trace(rows: Sequence[Mapping[str, Any]]) -> dict[str, list[Mapping[str, Any]]]:
    """Rows grouped by their ``trace`` name (several where a name repeats)."""
    out: dict[str, list[Mapping[str, Any]]] = {}
    for r in rows:
        out.setdefault(str(r.get("trace", "")), []).append(r)
    return out
