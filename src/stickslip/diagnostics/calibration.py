"""Calibration of predictive uncertainty: interval coverage and reliability plots."""

from __future__ import annotations

import os
from collections.abc import Callable

import numpy as np

from stickslip.estimators.calibration import gaussian_z


def coverage(true: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> float:
    """Fraction of truths inside their intervals (non-finite entries skipped)."""
    t, lo, hi = (np.asarray(v, float) for v in (true, lo, hi))
    ok = np.isfinite(t) & np.isfinite(lo) & np.isfinite(hi)
    return float(np.mean((t[ok] >= lo[ok]) & (t[ok] <= hi[ok]))) if ok.any() else float("nan")


def reliability(true: np.ndarray, mean: np.ndarray, sigma: np.ndarray, log: bool,
                levels: np.ndarray | None = None,
                z_of_level: Callable[[float], float] | None = None,
                ) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Observed coverage of central intervals ``mean +- z(q) sigma`` at nominal ``levels``.

    ``mean``/``sigma`` are the predictive location and scale, in log space when ``log``
    (then ``mean`` is the log of the median and ``true`` is taken as its log).
    ``z_of_level`` gives the half-width at a level in units of ``sigma``: a Gaussian's
    quantile by default; a model whose errors are not Gaussian passes its own.
    """
    levels = np.linspace(0.05, 0.99, 25) if levels is None else np.asarray(levels)
    z_of_level = z_of_level or gaussian_z
    t = np.log(true) if log else np.asarray(true, float)
    z = np.abs(t - mean) / sigma
    observed = np.array([np.mean(z <= z_of_level(q)) for q in levels])
    return levels, observed


def reliability_plot(curves: dict[str, tuple[np.ndarray, np.ndarray]], title: str,
                     out: str | os.PathLike) -> None:  # fmt: skip
    """Observed against nominal coverage, one curve per target; the diagonal is ideal."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from stickslip.atomic import atomic_path

    fig, ax = plt.subplots(figsize=(4.2, 4.0), constrained_layout=True)
    ax.plot([0, 1], [0, 1], "k--", lw=0.8, label="ideal")
    for name, (nominal, observed) in curves.items():
        ax.plot(nominal, observed, marker=".", label=name)
    ax.set_xlabel("nominal coverage")
    ax.set_ylabel("observed coverage")
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=8)
    with atomic_path(out, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
