"""Figures: parity plots coloured by point density, loss curves, per-trace window panels.

Matplotlib with the Agg backend (no display needed); every file is written atomically.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from stickslip.atomic import atomic_path  # noqa: E402

LABELS = {
    "F_mean_nN": r"$\langle F\rangle$ [nN]",
    "F_mean_net": r"$\langle F\rangle$ (network) [nN]",
    "U0_eV": r"$U_0$ [eV]",
    "K_N_m": r"$K$ [N/m]",
    "eta": r"$\eta$",
}


def _save(fig: plt.Figure, path: str | os.PathLike) -> Path:
    path = Path(path)
    with atomic_path(path, suffix=path.suffix or ".png") as tmp:
        fig.savefig(tmp, dpi=120, format=(path.suffix.lstrip(".") or "png"))
    plt.close(fig)
    return path


def point_density(x: np.ndarray, y: np.ndarray, bins: int = 60) -> np.ndarray:
    """Local density of each point: count of its cell in a 2-D histogram, smoothed."""
    from scipy.ndimage import gaussian_filter

    if x.size == 0:
        return np.empty(0)
    h, xe, ye = np.histogram2d(x, y, bins=bins)
    h = gaussian_filter(h, 1.0, mode="constant")
    ix = np.clip(np.searchsorted(xe, x, side="right") - 1, 0, bins - 1)
    iy = np.clip(np.searchsorted(ye, y, side="right") - 1, 0, bins - 1)
    return h[ix, iy]


def parity_plot(
    true: Mapping[str, np.ndarray],
    pred: Mapping[str, np.ndarray],
    metrics: Mapping[str, Mapping[str, float]],
    path: str | os.PathLike,
    title: str = "",
) -> Path:
    """Predicted versus true per target, coloured by point density (paper Figure 3)."""
    keys = [k for k in pred if k in true]
    fig, axes = plt.subplots(1, len(keys), figsize=(4.2 * len(keys), 4.0), squeeze=False)
    for ax, k in zip(axes[0], keys, strict=True):
        t = np.asarray(true[k], float)
        p = np.asarray(pred[k], float)
        ok = np.isfinite(t) & np.isfinite(p)
        t, p = t[ok], p[ok]
        d = point_density(t, p)
        order = np.argsort(d)
        ax.scatter(t[order], p[order], c=d[order], s=6, cmap="viridis", linewidths=0)
        lo = float(min(t.min(initial=0), p.min(initial=0)))
        hi = float(max(t.max(initial=1), p.max(initial=1)))
        ax.plot([lo, hi], [lo, hi], "k--", lw=0.8)
        m = metrics.get(k, {})
        ax.set_title(f"RMSE {m.get('rmse', np.nan):.3g}, rel {m.get('rel_mean_abs', np.nan):.1%}")
        ax.set_xlabel(f"true {LABELS.get(k.replace('_net', '_nN'), k)}")
        ax.set_ylabel(f"predicted {LABELS.get(k, k)}")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return _save(fig, path)


def loss_curve(
    train_loss: Sequence[float], val_loss: Sequence[float], path: str | os.PathLike
) -> Path:
    """Training and validation loss per epoch (log scale)."""
    fig, ax = plt.subplots(figsize=(5, 3.5))
    epochs = np.arange(1, len(train_loss) + 1)
    ax.semilogy(epochs, train_loss, label="train")
    ax.semilogy(epochs, val_loss, label="validation")
    ax.set_xlabel("epoch")
    ax.set_ylabel("loss (sum of standardised MSE)")
    ax.legend()
    fig.tight_layout()
    return _save(fig, path)


def window_panels(
    x_nm: np.ndarray,
    force_nN: np.ndarray,
    centres_nm: np.ndarray,
    window_values: Mapping[str, np.ndarray],
    trace_values: Mapping[str, float],
    path: str | os.PathLike,
    title: str = "",
    reference: Mapping[str, float] | None = None,
) -> Path:
    """The trace and the window-wise estimates of each parameter (paper Fig. 5 d-g).

    Dashed lines: the per-trace mean; dotted: ``reference`` values (e.g. the classical
    estimator's), where given.
    """
    keys = list(window_values)
    fig, axes = plt.subplots(len(keys) + 1, 1, figsize=(7, 1.7 * (len(keys) + 1)), sharex=True)
    for ax, k in zip(axes[:-1], keys, strict=True):
        ax.plot(centres_nm, window_values[k], "o", ms=3, color="tab:green", label="window")
        if k in trace_values:
            ax.axhline(trace_values[k], ls="--", color="tab:pink", lw=1, label="trace (mean)")
        if reference and np.isfinite(reference.get(k, np.nan)):
            ax.axhline(reference[k], ls=":", color="k", lw=1, label="classical")
        ax.set_ylabel(LABELS.get(k, k))
    handles = {h.get_label(): h for ax in axes[:-1] for h in ax.get_lines()}
    axes[0].legend(handles=list(handles.values()), loc="upper right", fontsize=7, ncols=3)
    axes[-1].plot(x_nm, force_nN, "-", lw=0.7, color="tab:red")
    axes[-1].set_ylabel("F [nN]")
    axes[-1].set_xlabel("x [nm]")
    if title:
        axes[0].set_title(title)
    fig.tight_layout()
    return _save(fig, path)
