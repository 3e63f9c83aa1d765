"""Per-load reporting: results of scan lines grouped by normal load, table and plot."""

from __future__ import annotations

import csv
import io
import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from stickslip.atomic import write_text_atomic
from stickslip.diagnostics.plots_load import plot_versus_load
from stickslip.traces.formats.maps import summarise_by_load

QUANTITIES = (("F_mean_nN", "friction <F> (nN)"), ("U0_eV", "U0 (eV)"), ("K_N_m", "K (N/m)"))
#: The same for lines read without a calibration (forces in volts): never shown as nN.
VOLT_QUANTITIES = (("F_mean_V", "friction <F> (V)"), ("U0_V_nm", "U0 (V nm)"),
                   ("K_V_per_nm", "K (V/nm)"))
FRICTION_KEYS = ("F_mean_nN", "F_mean_V")


def _quantities(rows: Sequence[Mapping[str, Any]]) -> list[tuple[str, str]]:
    """The quantities the rows carry: nN ones, volt ones, or both for a mixed table."""
    out = []
    for nN, volt in zip(QUANTITIES, VOLT_QUANTITIES, strict=True):
        out += [q for q in (nN, volt) if any(q[0] in r for r in rows)]
    return out


def line_friction_rows(rows: Sequence[Mapping[str, Any]], key: str) -> list[dict[str, Any]]:
    """Rows for the friction summary: one per scan line that has a friction loop.

    A map line read in both directions gives two rows whose means differ by twice the
    lateral offset (an instrument offset, not friction); their loop, (trace - retrace)/2,
    is the line's friction (``loop_friction``). Such a line counts once, with its loop
    friction as ``key``; any other row counts with its own mean.
    """
    seen: set[tuple[Any, ...]] = set()
    out: list[dict[str, Any]] = []
    for r in rows:
        if r.get(key) is None:
            continue
        if r.get("loop_friction") is not None and r.get("direction") in ("trace", "retrace"):
            line = (r.get("file"), r.get("channel"), r.get("line"))
            if line in seen:
                continue
            seen.add(line)
            out.append({**r, key: r["loop_friction"]})
        else:
            out.append(dict(r))
    return out


def _cell(value: Any) -> Any:
    return "" if value is None or (isinstance(value, float) and math.isnan(value)) else value


def write_load_report(rows: Sequence[Mapping[str, Any]], out: str | os.PathLike,
                      title: str = "") -> list[Path]:  # fmt: skip
    """Per-load summary beside the result table ``out``, if any row carries a load.

    Writes ``<out stem>.by_load.csv`` (mean, std and count of <F>, U0 and K per load
    group; in V, V nm and V/nm for lines read without a calibration; a missing value is
    an empty cell) and ``<out stem>.by_load.png`` (the three against load, error bars the
    scatter over lines; <F> of a line is its friction loop where it has one, free of the
    lateral offset: :func:`line_friction_rows`); returns their paths (none when no trace
    has a load).
    """
    if not any(r.get("load") is not None for r in rows):
        return []
    quantities = _quantities(rows) or list(QUANTITIES)
    keys = [k for k, _ in quantities]
    summary = summarise_by_load(rows, [k for k in keys if k not in FRICTION_KEYS])
    for key in (k for k in keys if k in FRICTION_KEYS):
        friction = {rec["load"]: rec
                    for rec in summarise_by_load(line_friction_rows(rows, key), [key])}
        for rec in summary:
            other = friction.get(rec["load"], {})
            for s in ("mean", "std"):
                rec[f"{key}_{s}"] = other.get(f"{key}_{s}", math.nan)
    out = Path(out)
    table = out.with_name(out.stem + ".by_load.csv")
    figure = out.with_name(out.stem + ".by_load.png")
    cols = ["load", "load_unit", "n", *(f"{k}_{s}" for k in keys for s in ("mean", "std"))]
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=cols, extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    w.writerows({k: _cell(v) for k, v in rec.items()} for rec in summary)
    write_text_atomic(table, buf.getvalue())
    plot_versus_load(summary, quantities, figure, title=title)
    return [table, figure]
