"""Per-load reporting: results of scan lines grouped by normal load, table and plot."""

from __future__ import annotations

import csv
import io
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from stickslip.atomic import write_text_atomic
from stickslip.diagnostics.plots_load import plot_versus_load
from stickslip.traces.formats.maps import summarise_by_load

QUANTITIES = (("F_mean_nN", "friction <F> (nN)"), ("U0_eV", "U0 (eV)"), ("K_N_m", "K (N/m)"))


def write_load_report(rows: Sequence[Mapping[str, Any]], out: str | os.PathLike,
                      title: str = "") -> list[Path]:  # fmt: skip
    """Per-load summary beside the result table ``out``, if any row carries a load.

    Writes ``<out stem>.by_load.csv`` (mean, std and count of <F>, U0 and K per load
    group) and ``<out stem>.by_load.png`` (the three against load); returns their paths
    (none when no trace has a load).
    """
    if not any(r.get("load") is not None for r in rows):
        return []
    keys = [k for k, _ in QUANTITIES]
    summary = summarise_by_load(rows, keys)
    out = Path(out)
    table = out.with_name(out.stem + ".by_load.csv")
    figure = out.with_name(out.stem + ".by_load.png")
    cols = ["load", "load_unit", "n", *(f"{k}_{s}" for k in keys for s in ("mean", "std"))]
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=cols, extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    w.writerows(summary)
    write_text_atomic(table, buf.getvalue())
    plot_versus_load(summary, QUANTITIES, figure, title=title)
    return [table, figure]
