"""Plots of per-load-group results (friction, U0, K ... versus load), written atomically."""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from typing import Any

from stickslip.atomic import atomic_path


def plot_versus_load(
    summary: Sequence[Mapping[str, Any]],
    quantities: Sequence[tuple[str, str]],
    out: str | os.PathLike,
    title: str = "",
) -> None:
    """Plot ``<key>_mean`` (with ``<key>_std`` error bars) versus load, one panel each.

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
        errs = [0.0 if math.isnan(r.get(f"{key}_std", math.nan)) else r[f"{key}_std"]
                for r in rows]
        ax.errorbar(loads, means, yerr=errs, marker="o", capsize=3)
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel(f"load / setpoint ({unit})" if unit else "load / setpoint")
    if title:
        axes[0, 0].set_title(title)
    fig.tight_layout()
    suffix = os.path.splitext(os.fspath(out))[1] or ".png"
    try:
        with atomic_path(out, suffix=suffix) as tmp:
            fig.savefig(tmp, format=suffix.lstrip("."), dpi=120)
    finally:
        plt.close(fig)
