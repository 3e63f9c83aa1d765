"""Inference: traces in, per-trace and per-window estimates of <F>, U0, K and eta out.

Per-trace estimate = mean over its windows (reference paper); ``*_std`` = standard
deviation over the windows (their spread, not a standard error).

Traces on another lattice are mapped onto the training lattice by
:mod:`stickslip.estimators.mapping`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch

from stickslip.estimators.mapping import refusal, to_reference
from stickslip.estimators.window.features import (
    FeatureError,
    n_windows,
    window_features,
    windows,
)
from stickslip.estimators.window.modelfile import TrainedModel
from stickslip.units import eta_from

OUTPUTS = ("F_mean_nN", "U0_eV", "K_N_m", "eta")
CHUNK_WINDOWS = 1 << 16


@dataclass
class TraceEstimate:
    """Network estimate for one trace.

    ``values`` and ``std`` map each of :data:`OUTPUTS` to the mean and the spread over
    windows; ``windows`` holds the per-window values (for the panels), ``centres_nm``
    the window centres in the trace's own positions; ``index`` the trace's position in
    the input list. ``F_mean_nN`` is the trace's own
    mean (exact for a recorded line); the network's window estimate is ``F_mean_net``.
    """

    trace: str
    index: int
    values: dict[str, float]
    std: dict[str, float]
    n_windows: int
    windows: dict[str, np.ndarray] = field(default_factory=dict)
    centres_nm: np.ndarray = field(default_factory=lambda: np.empty(0))
    meta: dict[str, Any] = field(default_factory=dict)


def _standardise(x: np.ndarray, norm: dict[str, np.ndarray]) -> np.ndarray:
    return (x - norm["x_mean"]) / norm["x_std"]


def to_physical(y_std: np.ndarray, model: TrainedModel) -> np.ndarray:
    """Network outputs (standardised, transformed) -> physical target values."""
    y = y_std * model.normalisation["y_std"] + model.normalisation["y_mean"]
    for j, name in enumerate(model.targets):
        if model.transforms.get(name) == "log":
            y[..., j] = np.exp(y[..., j])
    return y


def forward(model: TrainedModel, features: np.ndarray) -> np.ndarray:
    """Run the network on input vectors ``(M, n_inputs)``; physical targets ``(M, T)``."""
    x = _standardise(features, model.normalisation).astype(np.float32, copy=False)
    out = np.empty((x.shape[0], len(model.targets)), dtype=np.float32)
    model.net.eval()
    with torch.inference_mode():
        for s in range(0, x.shape[0], CHUNK_WINDOWS):
            out[s : s + CHUNK_WINDOWS] = model.net(torch.from_numpy(x[s : s + CHUNK_WINDOWS]))
    return to_physical(out.astype(np.float64), model)


def predict_windows(model: TrainedModel, force_nN: np.ndarray, stride: int | None = None):
    """Per-window physical estimates of equally long traces on the training pixel grid.

    Parameters
    ----------
    force_nN : ndarray (N, P)
        Traces already on the model's pixel and lattice scale.
    stride : int, optional
        Window stride (default: the model's inference stride).

    Returns
    -------
    ndarray (N, W, T)
        One row of targets per window, in the order of ``model.targets``.
    """
    spec = model.features
    win = windows(np.asarray(force_nN, dtype=np.float32), spec.window, stride or spec.stride)
    n, w = win.shape[:2]
    feats = window_features(win.reshape(n * w, spec.window), spec)
    return forward(model, feats).reshape(n, w, -1)


def predict_array(
    model: TrainedModel,
    force_nN: np.ndarray,
    lattice_nm: float | None = None,
    stride: int | None = None,
) -> dict[str, np.ndarray]:
    """Per-trace estimates for a stack of traces recorded on the model's pixel grid.

    The fast path (no resampling): traces must already have the training pixel size.
    With ``lattice_nm`` other than the training lattice, the traces are taken as already
    rescaled onto the training lattice (see :func:`map_trace`) and only the answer is
    mapped back.

    Returns
    -------
    dict
        ``F_mean_nN`` (trace means), ``F_mean_net``, ``U0_eV``, ``K_N_m``, ``eta`` and
        ``*_std`` over windows, each ``(N,)``; ``windows``: ``(N, W, 4)`` of F_mean_net,
        U0, K, eta per window.
    """
    force_nN = np.asarray(force_nN)
    per_win = predict_windows(model, force_nN, stride)
    a0 = model.features.lattice_nm
    a = a0 if lattice_nm is None else float(lattice_nm)
    s = a / a0
    col = {t: per_win[..., j] for j, t in enumerate(model.targets)}
    U0 = col["U0_eV"] * s
    K = col["K_N_m"] / s
    Fw = col.get("F_mean_nN", np.broadcast_to(force_nN.mean(axis=1)[:, None], U0.shape))
    eta = eta_from(U0, K, a)
    stack = np.stack([Fw, U0, K, eta], axis=-1)
    out = {
        "F_mean_nN": force_nN.mean(axis=1).astype(float),
        "F_mean_net": Fw.mean(axis=1),
        "F_mean_net_std": Fw.std(axis=1),
        "windows": stack,
    }
    for name, v in zip(("U0_eV", "K_N_m", "eta"), (U0, K, eta), strict=True):
        out[name] = v.mean(axis=1)
        out[f"{name}_std"] = v.std(axis=1)
    out["F_mean_nN_std"] = out["F_mean_net_std"]
    return out


def map_trace(
    x_nm: np.ndarray, force_nN: np.ndarray, model: TrainedModel, lattice_nm: float | None
) -> np.ndarray:
    """A trace on the model's scale (:func:`stickslip.estimators.mapping.to_reference`).

    Raises
    ------
    FeatureError
        If the mapped trace is shorter than one window, or its pixels are more than
        4x the training pixel (fewer than ~3 pixels per lattice spacing).
    """
    spec = model.features
    a = spec.lattice_nm if lattice_nm is None else float(lattice_nm)
    why = refusal(x_nm, a, spec.reference, spec.window)
    if why:
        raise FeatureError(why)
    f = to_reference(x_nm, force_nN, a, spec.reference)
    if f.size < spec.window:
        raise FeatureError(f"too short: {f.size} reference pixels, one window needs {spec.window}")
    return f


def predict_traces(
    model: TrainedModel,
    traces: list[Any],
    lattice_nm: float | Sequence[float] | None = None,
    keep_windows: bool = False,
) -> tuple[list[TraceEstimate], list[tuple[str, str]]]:
    """Estimates for :class:`~stickslip.traces.trace.Trace` objects of any length and pixel.

    Parameters
    ----------
    model : TrainedModel
    traces : list of Trace
    lattice_nm : float or sequence of float, optional
        Lattice spacing of the sample, or one per trace (default: each trace's
        ``meta["lattice_nm"]``, else the training lattice).
    keep_windows : bool
        Keep per-window values (for plots).

    Returns
    -------
    estimates : list of TraceEstimate
        For every trace that could be processed, in input order.
    failures : list of (trace name, reason)
        Traces too short for one window.
    """
    spec = model.features
    mapped: list[tuple[int, np.ndarray, float]] = []
    failures: list[tuple[str, str]] = []
    per_trace = lattice_nm if isinstance(lattice_nm, (list, tuple, np.ndarray)) else None
    for i, t in enumerate(traces):
        if per_trace is not None:
            a = per_trace[i]
        else:
            a = lattice_nm or t.meta.get("lattice_nm") or spec.lattice_nm
        try:
            mapped.append((i, map_trace(t.x_nm, t.force_nN, model, a), float(a)))
        except FeatureError as e:
            failures.append((t.name, str(e)))
    results: dict[int, TraceEstimate] = {}
    groups: dict[tuple[int, float], list[tuple[int, np.ndarray]]] = {}
    for i, f, a in mapped:
        groups.setdefault((f.size, a), []).append((i, f))
    for (size, a), items in groups.items():
        res = predict_array(model, np.stack([f for _, f in items]), lattice_nm=a)
        n_win = n_windows(size, spec.window, spec.stride)
        starts = np.arange(n_win) * spec.stride
        centres = (starts + spec.window / 2) * spec.pixel_nm * a / spec.lattice_nm
        for row, (i, _) in enumerate(items):
            t = traces[i]
            results[i] = TraceEstimate(
                trace=t.name,
                index=i,
                values={k: float(res[k][row]) for k in (*OUTPUTS, "F_mean_net")},
                std={k: float(res[f"{k}_std"][row]) for k in OUTPUTS},
                n_windows=n_win,
                windows=dict(zip(("F_mean_net", "U0_eV", "K_N_m", "eta"),
                                 res["windows"][row].T, strict=True)) if keep_windows else {},
                centres_nm=centres + float(t.x_nm[0]),
                meta=dict(t.meta),
            )  # fmt: skip
    # the trace's own mean is taken on its original samples
    for i, est in results.items():
        est.values["F_mean_nN"] = float(np.mean(traces[i].force_nN))
    return [results[i] for i in sorted(results)], failures
