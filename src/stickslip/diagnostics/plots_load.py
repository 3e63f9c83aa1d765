"""Plots of per-load-group results (friction, U0, K ... versus load), written atomically."""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from stickslip.atomic import atomic_path


def _bar(row: Mapping[str, Any], key: str, mean: float) -> tuple[float, float]:
    """(below, above) error bar: the row's interval if it has one, else +- its std."""
    lo, hi = row.get(f"{key}_lo"), row.get(f"{key}_hi")
    if lo is not None and hi is not None and math.isfinite(mean):
        return max(mean - lo, 0.0), max(hi - mean, 0.0)
    std = row.get(f"{key}_std", math.nan)
    return (0.0, 0.0) if math.isnan(std) else (std, std)


def plot_versus_load(
    summary: Sequence[Mapping[str, Any]],
    quantities: Sequence[tuple[str, str]],
    out: str | os.PathLike,
    title: str = "",
    curves: Mapping[str, Sequence[tuple[str, Sequence[float], Sequence[float]]]] | None = None,
) -> None:
    """Plot ``<key>_mean`` (with ``<key>_std`` error bars) versus load, one panel each.

    Where the rows carry ``<key>_lo`` and ``<key>_hi`` (an interval), the error bars span
    that interval instead of +- ``<key>_std``.

    Parameters
    ----------
    summary : sequence of mapping
        Rows of :func:`stickslip.traces.formats.maps.summarise_by_load`; rows whose load
        is ``None`` are left out.
    quantities : sequence of (key, axis label)
        E.g. ``[("friction", "friction (V)"), ("U0_eV", "U0 (eV)")]``.
    out : path-like
        Image file (format from its suffix), written atomically.
    title : str
        Figure title.
    curves : mapping, optional
        Per key, lines drawn over its data: ``(label, loads, values)`` each (fitted laws).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [r for r in summary if r.get("load") is not None]
    unit = next((r.get("load_unit") for r in rows if r.get("load_unit")), "")
    fig, axes = plt.subplots(len(quantities), 1, figsize=(5, 2.6 * len(quantities)),
                             sharex=True, squeeze=False)
    for ax, (key, label) in zip(axes[:, 0], quantities, strict=True):
        loads = [r["load"] for r in rows]
        means = [r.get(f"{key}_mean", math.nan) for r in rows]
        errs = [_bar(r, key, m) for r, m in zip(rows, means, strict=True)]
        ax.errorbar(loads, means, yerr=np.array(errs).T, marker="o", capsize=3, linestyle="none"
                    if curves and key in curves else "-")
        for name, xs, ys in (curves or {}).get(key, ()):
            ax.plot(xs, ys, label=name)
        if curves and curves.get(key):
            # above the panel: inside, the fits' long labels covered data points
            ax.legend(fontsize=7, loc="lower left", bbox_to_anchor=(0.0, 1.01),
                      borderaxespad=0.0, frameon=False)  # fmt: skip
        if not any(math.isfinite(m) for m in means):
            ax.text(0.5, 0.5, "no estimate in any load group", transform=ax.transAxes,
                    ha="center", va="center", color="0.4")  # fmt: skip
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel(f"load / setpoint ({unit})" if unit else "load / setpoint")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    suffix = os.path.splitext(os.fspath(out))[1] or ".png"
    try:
        with atomic_path(out, suffix=suffix) as tmp:
            fig.savefig(tmp, format=suffix.lstrip("."), dpi=120, bbox_inches="tight")
    finally:
        plt.close(fig)
