"""Diagnostic and accuracy plots of the classical estimator (matplotlib, Agg)."""

from __future__ import annotations

import os
from collections.abc import Mapping
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from stickslip.atomic import atomic_path  # noqa: E402
from stickslip.estimators.classical.slips import SLIP_F, SLIP_PEAK, SLIP_X, SlipAnalysis  # noqa: E402


def plot_trace_diagnostics(
    path: str | os.PathLike,
    x_nm: np.ndarray,
    force_nN: np.ndarray,
    analysis: SlipAnalysis,
    row: Mapping[str, Any],
    unit: str = "nN",
) -> None:
    """Trace with detected stick segments, their fitted branches and the slip points.

    ``row`` is the trace's row of the classical estimator's table. On a flagged row
    (``quality`` not ``ok``) the fitted branches are not drawn: they do not describe
    the data; the title says why. ``unit`` is the force unit: ``"V"`` for a trace read
    without a calibration, whose row has ``U0_V_nm``, ``K_V_per_nm`` ... (never nN).
    """
    fig, ax = plt.subplots(figsize=(10, 4))
    ax.plot(x_nm, force_nN, ".", ms=2, color="0.6", label="trace")
    ok = row.get("quality") == "ok"
    for k in range(analysis.segments.shape[0] if ok else 0):
        xs, fs = analysis.segment_curve(k, x_nm)
        ax.plot(xs, fs, "-", lw=1.2, color="C0", label="stick fits" if k == 0 else None)
    s = analysis.slips
    ax.plot(s[:, SLIP_X], s[:, SLIP_F], "v", ms=4, color="C3", label="slips")
    ax.plot(s[:, SLIP_X], s[:, SLIP_PEAK], "_", ms=8, color="C1", label="peaks")
    ax.set_xlabel("support position X (nm)")
    ax.set_ylabel(f"lateral force F ({unit})")
    def g(k: str) -> float:
        v = row.get(k)
        return float(v) if isinstance(v, (int, float, np.number)) else float("nan")

    if ok and unit == "V":
        title = (f"{row['trace']}: U0 = {g('U0_V_nm'):.3g} V nm, K = {g('K_V_per_nm'):.3g} "
                 f"V/nm, eta = {g('eta'):.3g}, k_exp = {g('k_exp_V_per_nm'):.3g} V/nm, "
                 f"{int(g('n_slips'))} slips, {row.get('regime') or '-'} (no calibration)")
    elif ok:
        title = (f"{row['trace']}: U0 = {g('U0_eV'):.3g} eV, K = {g('K_N_m'):.3g} N/m, "
                 f"eta = {g('eta'):.3g}, k_exp = {g('k_exp_N_m'):.3g} N/m, "
                 f"{int(g('n_slips'))} slips, {row.get('regime') or '-'}")  # fmt: skip
    else:
        title = f"{row['trace']}: flagged ({row.get('quality')}); no stick fit drawn"
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    _save(fig, path)


def parity_plot(
    path: str | os.PathLike,
    truths: dict[str, np.ndarray],
    estimates: dict[str, np.ndarray],
    title: str = "",
) -> None:
    """One log-log parity panel per quantity (true on x, estimated on y)."""
    names = list(truths)
    fig, axes = plt.subplots(1, len(names), figsize=(4 * len(names), 4))
    for ax, name in zip(np.atleast_1d(axes), names, strict=True):
        t, e = np.asarray(truths[name]), np.asarray(estimates[name])
        ok = np.isfinite(e) & (e > 0)
        ax.loglog(t[ok], e[ok], ".", ms=3)
        lo, hi = np.nanmin(t), np.nanmax(t)
        ax.plot([lo, hi], [lo, hi], "k-", lw=0.8)
        ax.set_xlabel(f"true {name}")
        ax.set_ylabel(f"estimated {name}")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    _save(fig, path)


def _save(fig: plt.Figure, path: str | os.PathLike) -> None:
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)
