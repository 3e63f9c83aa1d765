"""The ``infer`` job for whole-line models: estimates with intervals, checks, panels.

One row per trace: ``F_mean_nN, U0_eV, K_N_m, eta``, their predictive standard
deviations (``*_std``) and central 68 % / 95 % intervals (``*_lo68, *_hi68, *_lo95,
*_hi95``), the lattice and velocity used, and, with ``check``, the posterior predictive
goodness of fit (``gof``; ``ppc_flag`` = 1 where the PT model cannot describe the
trace). The classical estimator's values sit beside them as for window models.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from stickslip.estimators.line.ensemble import LineEnsemble, predict_raw_lines
from stickslip.estimators.window.inference import MAX_PIXEL_RATIO
from stickslip.jobs.window_results import META_COLUMNS, _classical, safe_name

OUTPUTS = ("F_mean_nN", "U0_eV", "K_N_m", "eta")


@dataclass
class LineInferenceResult:
    """Rows of the table, the traces behind them, failures and PPC replicates."""

    rows: list[dict[str, Any]]
    indices: list[int]
    failures: list[tuple[str, str]]
    notes: list[str] = field(default_factory=list)
    replicates: dict[int, np.ndarray] = field(default_factory=dict)


def run_line_inference(
    ens: LineEnsemble,
    traces: Sequence[Any],
    lattice_nm: float | None = None,
    velocity_nm_per_s: float | None = None,
    temperature_K: float | None = None,
    classical: bool = True,
    check: bool = False,
) -> LineInferenceResult:
    """Estimates with uncertainty for every trace long enough to read.

    Lattice and velocity come from the arguments, else each trace's metadata, else the
    model's reference values; they enter both the mapping and the network's
    conditioning inputs.
    """
    spec = ens.spec
    a = np.array([float(lattice_nm or t.meta.get("lattice_nm") or spec.lattice_nm)
                  for t in traces])  # fmt: skip
    v = np.array([float(velocity_nm_per_s or t.meta.get("velocity_nm_per_s")
                        or spec.velocity_nm_per_s) for t in traces])  # fmt: skip
    T = float(temperature_K if temperature_K is not None else spec.temperature_K)
    notes = []
    if abs(T - spec.temperature_K) > 1:
        notes.append(f"model trained at T = {spec.temperature_K:g} K, traces at {T:g} K: "
                     "estimates are extrapolated")  # fmt: skip
    failures, ok = [], []
    for i, t in enumerate(traces):
        s = a[i] / spec.lattice_nm
        pixel = (t.x_nm[-1] - t.x_nm[0]) / max(t.x_nm.size - 1, 1)
        mapped_pixels = (t.x_nm[-1] - t.x_nm[0]) / s / spec.pixel_nm
        if pixel > MAX_PIXEL_RATIO * spec.pixel_nm * s:
            failures.append((t.name, f"pixel {pixel:.3g} nm does not resolve the {a[i]:.3g} nm "
                                     f"lattice (the model needs pixels <= "
                                     f"{MAX_PIXEL_RATIO * spec.pixel_nm * s:.3g} nm)"))  # fmt: skip
        elif mapped_pixels < spec.min_pixels:
            failures.append((t.name, f"too short: {mapped_pixels:.0f} mapped pixels, at least "
                                     f"{spec.min_pixels} needed"))  # fmt: skip
        else:
            ok.append(i)
    result = LineInferenceResult(rows=[], indices=ok, failures=failures, notes=notes)
    if not ok:
        return result
    sel = [traces[i] for i in ok]
    pred = predict_raw_lines(ens, [t.x_nm for t in sel], [t.force_nN for t in sel], a[ok], v[ok])
    extra, why = _classical(sel, list(a[ok]), T, list(v[ok])) if classical else ([], None)
    if why:
        notes.append(why)
    ppc = _check(sel, pred, a[ok], v[ok], T) if check else None
    for j, (i, t) in enumerate(zip(ok, sel, strict=True)):
        row: dict[str, Any] = {"trace": t.name}
        for k in OUTPUTS:
            row[k] = pred.values[k][j]
        for k in OUTPUTS:
            row[f"{k}_std"] = pred.std[k][j]
        for bound in ("lo68", "hi68", "lo95", "hi95"):
            for k in OUTPUTS:
                row[f"{k}_{bound}"] = getattr(pred, bound)[k][j]
        row.update({"lattice_nm": a[i], "velocity_nm_per_s": v[i],
                    "source": getattr(t, "source", ""), "model": "line-cnn"})  # fmt: skip
        if ppc is not None:
            row["gof"] = ppc.gof[j]
            row["ppc_flag"] = int(ppc.flagged[j])
            result.replicates[i] = ppc.replicate_nN[j]
        row.update({k: t.meta[k] for k in META_COLUMNS if t.meta.get(k) is not None})
        if extra:
            row.update({f"classical_{k}": val for k, val in extra[j].items()})
        result.rows.append(row)
    return result


def _check(traces, pred, a, v, T):
    """Posterior predictive check of each trace at its estimate (traces grouped by length)."""
    from stickslip.diagnostics.ppc import PPCResult, posterior_predictive_check

    n = len(traces)
    gof, flagged = np.zeros(n), np.zeros(n, bool)
    reps: list[np.ndarray | None] = [None] * n
    sizes = np.array([t.force_nN.size for t in traces])
    for size in np.unique(sizes):
        idx = np.flatnonzero(sizes == size)
        x = traces[idx[0]].x_nm
        r = posterior_predictive_check(
            x, np.stack([traces[i].force_nN for i in idx]), pred.values["U0_eV"][idx],
            pred.values["K_N_m"][idx], lattice_nm=a[idx], velocity_nm_per_s=v[idx],
            temperature_K=T,
        )  # fmt: skip
        gof[idx], flagged[idx] = r.gof, r.flagged
        for k, i in enumerate(idx):
            reps[i] = r.replicate_nN[k]
    return PPCResult(gof=gof, flagged=flagged, z=np.empty((n, 0)), replicate_nN=reps)


def write_line_panels(result: LineInferenceResult, traces: Sequence[Any],
                      out_dir: str | os.PathLike) -> list[Path]:  # fmt: skip
    """Per trace: the trace (and, after a check, the PT model at the estimate), with the
    estimates and their 95 % intervals in the title."""
    from stickslip.diagnostics.ppc import plot_overlay

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for n, (i, row) in enumerate(zip(result.indices, result.rows, strict=True)):
        t = traces[i]
        title = (f"{row['trace']}:  U0 = {row['U0_eV']:.3g} eV [{row['U0_eV_lo95']:.3g}, "
                 f"{row['U0_eV_hi95']:.3g}],  K = {row['K_N_m']:.3g} N/m [{row['K_N_m_lo95']:.3g},"
                 f" {row['K_N_m_hi95']:.3g}],  eta = {row['eta']:.3g}")  # fmt: skip
        if "gof" in row:
            title += f",  gof = {row['gof']:.2f}{' FLAGGED' if row['ppc_flag'] else ''}"
        path = out / f"{n:03d}_{safe_name(row['trace'])}.png"
        plot_overlay(t.x_nm, t.force_nN, result.replicates.get(i), title, path)
        paths.append(path)
    return paths
