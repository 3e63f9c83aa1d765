"""Friction against load: the usual laws fitted with their uncertainties.

Two laws are fitted to the mean friction of each load group, and both are reported
with a goodness of fit; neither is chosen for the user:

- **linear** (Amontons with an adhesion offset): ``F = mu L + F0``; ``mu`` is the friction
  coefficient, ``F0`` the friction at zero load (adhesion), ``-F0/mu`` the load where
  the line reaches zero friction.
- **DMT-like 2/3 power**: ``F = c (L + L_adh)^(2/3)``. For a single-asperity contact
  whose friction is proportional to the contact area, the DMT area grows as
  ``(L + L_adh)^(2/3)`` with the adhesive load ``L_adh`` (pull-off force); ``c`` is the
  shear strength times the area prefactor. The law is linear in ``c`` for a given
  ``L_adh``, so ``L_adh`` is found by a one-dimensional profile and ``c`` follows in
  closed form. Where the data cannot tell the curvature (a straight series),
  ``L_adh`` runs to the search limit, 1000 load spans; the fit says so (``note``).

Uncertainties are one standard deviation from the fit covariance,
``cov = s^2 (J^T W J)^-1``. With per-point errors ``sigma`` (the standard error of each
group mean) ``W = 1/sigma^2`` and ``s^2 = max(1, chi2/dof)``: the stated errors, widened
by the scatter of the data about the law where that is larger. Without errors the
points weigh the same and ``s^2 = RSS/dof`` (the residual variance). ``chi2_red`` (with
errors) and ``rms`` (always, in friction units) are the goodness of fit. The load and
friction units are whatever the data carry (volts of setpoint and of lateral signal
for an uncalibrated ramp): ``mu`` is then in friction units per load unit.

Only array functions here; reading the ramp (:func:`collect_friction_rows`) and the
per-load summary of learned estimates (:func:`estimates_by_load`) prepare their input.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from stickslip.estimators.pooling import group_table
from stickslip.estimators.table import float_or_nan, read_table
from stickslip.traces.formats.maps import TRACE, summarise_by_load
from stickslip.traces.readers import expand_paths, is_scan_file, read_file, read_scan
from stickslip.traces.trace import Trace, TraceReadError

MIN_POINTS = 3  # two parameters and at least one degree of freedom
ADHESION_SPAN_LIMIT = 1e3  # L_adh search limit, in load spans beyond the smallest load
LAWS = ("linear", "dmt")


@dataclass
class LawFit:
    """One law fitted to friction against load.

    Attributes
    ----------
    law : str
        ``linear`` or ``dmt``.
    formula : str
        The law, in words of its parameters.
    names : tuple of str
        Parameter names (``mu``, ``F0``; or ``c``, ``L_adh``).
    values, stds : ndarray (2,)
        Best-fit values and one-standard-deviation uncertainties.
    cov : ndarray (2, 2)
        Parameter covariance (already scaled, see the module docstring).
    chi2_red : float
        chi^2 per degree of freedom with the given errors (NaN without errors).
    rms : float
        Root-mean-square residual, in friction units.
    dof : int
        Points minus parameters.
    note : str
        Empty, or what the user should know about this fit (a parameter at its limit).
    """

    law: str
    formula: str
    names: tuple[str, str]
    values: np.ndarray
    stds: np.ndarray
    cov: np.ndarray
    chi2_red: float
    rms: float
    dof: int
    note: str = ""

    def predict(self, load: np.ndarray | float) -> np.ndarray:
        """The fitted law at the given loads (NaN where the 2/3 power is undefined)."""
        L = np.asarray(load, dtype=float)
        p, q = self.values
        if self.law == "linear":
            return p * L + q
        base = L + q
        return np.where(base >= 0, p * np.cbrt(np.maximum(base, 0.0)) ** 2, np.nan)

    def param(self, name: str) -> tuple[float, float]:
        """(value, standard deviation) of one parameter."""
        i = self.names.index(name)
        return float(self.values[i]), float(self.stds[i])

    def summary(self, friction_unit: str = "", load_unit: str = "") -> str:
        """One line: the law, its parameters with uncertainties, and the goodness of fit."""
        units = _units(self.law, friction_unit, load_unit)
        parts = [f"{n} = {v:.4g} +- {s:.2g}{(' ' + u) if u else ''}"
                 for n, v, s, u in zip(self.names, self.values, self.stds, units, strict=True)]
        gof = f"rms {self.rms:.3g}{(' ' + friction_unit) if friction_unit else ''}"
        if math.isfinite(self.chi2_red):
            gof = f"chi2/dof {self.chi2_red:.3g} (dof {self.dof}), " + gof
        line = f"{self.law}: {self.formula}: {', '.join(parts)}; {gof}"
        return line + (f"; {self.note}" if self.note else "")

    def rows(self, friction_unit: str = "", load_unit: str = "") -> list[dict[str, Any]]:
        """Table rows: one per parameter (law, parameter, value, std, unit, gof)."""
        units = _units(self.law, friction_unit, load_unit)
        return [
            {"law": self.law, "formula": self.formula, "parameter": n, "value": float(v),
             "std": float(s), "unit": u, "chi2_red": self.chi2_red, "rms": self.rms,
             "dof": self.dof, "note": self.note or None}
            for n, v, s, u in zip(self.names, self.values, self.stds, units, strict=True)
        ]  # fmt: skip


def _units(law: str, friction_unit: str, load_unit: str) -> tuple[str, str]:
    if law == "linear":
        mu = f"{friction_unit}/{load_unit}" if friction_unit and load_unit else ""
        return mu, friction_unit
    c = f"{friction_unit}/{load_unit}^(2/3)" if friction_unit and load_unit else ""
    return c, load_unit


def _prepare(load: Sequence[float], friction: Sequence[float],
             sigma: Sequence[float] | None) -> tuple[np.ndarray, ...]:  # fmt: skip
    L = np.asarray(load, dtype=float)
    F = np.asarray(friction, dtype=float)
    if L.shape != F.shape or L.ndim != 1:
        raise ValueError("load and friction must be 1-D arrays of equal length")
    keep = np.isfinite(L) & np.isfinite(F)
    s = None
    if sigma is not None:
        s = np.asarray(sigma, dtype=float)
        if s.shape != L.shape:
            raise ValueError("sigma must match load in length")
        keep &= np.isfinite(s) & (s > 0)
        s = s[keep]
    L, F = L[keep], F[keep]
    if L.size < MIN_POINTS or np.unique(L).size < 2:
        raise ValueError(f"need at least {MIN_POINTS} loads with a friction value "
                         f"({L.size} given)")  # fmt: skip
    w = np.ones_like(L) if s is None else 1.0 / s**2
    return L, F, w, (s is not None)


def _finish(law: str, formula: str, names: tuple[str, str], values: np.ndarray,
            J: np.ndarray, resid: np.ndarray, w: np.ndarray, weighted: bool,
            note: str = "") -> LawFit:  # fmt: skip
    dof = resid.size - 2
    chi2 = float(np.sum(w * resid**2))
    if weighted:
        chi2_red = chi2 / dof
        scale = max(1.0, chi2_red)
    else:
        chi2_red = math.nan
        scale = chi2 / dof
    A = J.T @ (w[:, None] * J)
    try:
        cov = np.linalg.inv(A) * scale
    except np.linalg.LinAlgError:
        cov = np.full((2, 2), np.nan)
    stds = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    rms = float(np.sqrt(np.mean(resid**2)))
    return LawFit(law, formula, names, values, stds, cov, chi2_red, rms, dof, note)


def fit_linear(load: Sequence[float], friction: Sequence[float],
               sigma: Sequence[float] | None = None) -> LawFit:  # fmt: skip
    """Fit ``F = mu L + F0`` (weighted least squares; see the module docstring).

    Parameters
    ----------
    load, friction : array_like (n,)
        Load of each group and its mean friction; NaN entries are left out.
    sigma : array_like (n,), optional
        Standard error of each friction value.

    Returns
    -------
    LawFit
        Parameters ``mu`` (friction per unit load) and ``F0`` (friction units).

    Raises
    ------
    ValueError
        With fewer than three usable points.
    """
    L, F, w, weighted = _prepare(load, friction, sigma)
    J = np.column_stack([L, np.ones_like(L)])
    A = J.T @ (w[:, None] * J)
    values = np.linalg.solve(A, J.T @ (w * F))
    resid = F - J @ values
    return _finish("linear", "F = mu L + F0", ("mu", "F0"), values, J, resid, w, weighted)


def _dmt_profile(L: np.ndarray, F: np.ndarray, w: np.ndarray,
                 L_adh: float) -> tuple[float, float]:  # fmt: skip
    g = np.cbrt(L + L_adh) ** 2
    c = float(np.sum(w * g * F) / np.sum(w * g * g))
    return c, float(np.sum(w * (F - c * g) ** 2))


def fit_dmt(load: Sequence[float], friction: Sequence[float],
            sigma: Sequence[float] | None = None) -> LawFit:  # fmt: skip
    """Fit the DMT-like law ``F = c (L + L_adh)^(2/3)`` (see the module docstring).

    ``L_adh`` is searched above ``-min(L)`` (every ``L + L_adh`` positive) up to
    ``ADHESION_SPAN_LIMIT`` load spans beyond it, on a log grid refined by a bounded
    scalar minimisation; ``c`` is linear given ``L_adh``.

    Parameters
    ----------
    load, friction, sigma : array_like (n,)
        As in :func:`fit_linear`.

    Returns
    -------
    LawFit
        Parameters ``c`` and ``L_adh`` (load units).
    """
    from scipy.optimize import minimize_scalar

    L, F, w, weighted = _prepare(load, friction, sigma)
    span = float(np.ptp(L))
    lo, hi = math.log(1e-6 * span), math.log(ADHESION_SPAN_LIMIT * span)
    L0 = float(L.min())

    def rss(log_s: float) -> float:
        return _dmt_profile(L, F, w, math.exp(log_s) - L0)[1]

    grid = np.linspace(lo, hi, 121)
    G = np.cbrt(L[None, :] + (np.exp(grid)[:, None] - L0)) ** 2
    c_grid = (G * (w * F)).sum(axis=1) / (G * G * w).sum(axis=1)
    vals = (w * (F - c_grid[:, None] * G) ** 2).sum(axis=1)
    k = int(np.argmin(vals))
    a, b = grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]
    best = minimize_scalar(rss, bounds=(a, b), method="bounded",
                           options={"xatol": 1e-10}).x if b > a else grid[k]  # fmt: skip
    note = ""
    if best >= hi - 1e-3 * (hi - lo):
        note = (f"L_adh at its search limit ({ADHESION_SPAN_LIMIT:g} load spans): the data "
                "are straight within their scatter and do not fix the 2/3 curvature")
    elif best <= lo + 1e-3 * (hi - lo):
        note = "L_adh at -min(load): the data curve the other way from the 2/3 law"
    L_adh = math.exp(best) - L0
    c, _ = _dmt_profile(L, F, w, L_adh)
    base = L + L_adh
    g = np.cbrt(base) ** 2
    J = np.column_stack([g, (2.0 / 3.0) * c / np.cbrt(base)])
    resid = F - c * g
    return _finish("dmt", "F = c (L + L_adh)^(2/3)", ("c", "L_adh"), np.array([c, L_adh]), J,
                   resid, w, weighted, note)  # fmt: skip


def fit_load_laws(load: Sequence[float], friction: Sequence[float],
                  sigma: Sequence[float] | None = None) -> list[LawFit]:  # fmt: skip
    """Both laws (linear, then DMT-like), each with its goodness of fit."""
    return [fit_linear(load, friction, sigma), fit_dmt(load, friction, sigma)]


def group_errors(summary: Sequence[Mapping[str, Any]], key: str) -> np.ndarray | None:
    """Standard error of each group mean (``<key>_std / sqrt(n)``), or None if any is missing.

    Groups of one line, or whose lines agree exactly, have no error of their own: then
    the fits weigh all points the same (None).
    """
    err = np.array([float(r.get(f"{key}_std", math.nan)) / math.sqrt(max(int(r["n"]), 1))
                    for r in summary])  # fmt: skip
    return err if err.size and np.all(np.isfinite(err)) and np.all(err > 0) else None


# ---------------------------------------------------------------- reading a ramp


@dataclass
class FrictionRows:
    """Per-line friction loops read from a ramp of maps.

    Attributes
    ----------
    rows : list of dict
        One per scan line: file, line, load, load_unit, friction, offset, unit.
    errors : list of TraceReadError
        Inputs that could not be used, each with a one-line reason.
    notes : list of str
        Files found in a folder and skipped as no part of a ramp (force curves, files
        without a load), one line each.
    """

    rows: list[dict[str, Any]] = field(default_factory=list)
    errors: list[TraceReadError] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


def friction_rows(traces: Sequence[Trace]) -> list[dict[str, Any]]:
    """One row per friction loop (the trace direction of each line that has a retrace)."""
    return [
        {
            "file": t.meta.get("file", t.source),
            "line": t.meta.get("line"),
            "load": t.meta.get("load"),
            "load_unit": t.meta.get("load_unit"),
            "friction": t.meta["loop_friction"],
            "offset": t.meta["loop_offset"],
            "unit": t.meta.get("unit"),
        }
        for t in traces
        if t.meta.get("direction") == TRACE and "loop_friction" in t.meta
    ]


def _is_force_curve(path: Path) -> bool:
    """True for a vendor file that holds no image channel at all (a force curve)."""
    if not is_scan_file(path):
        return False
    try:
        return not read_scan(path).channels
    except TraceReadError:
        return False


def _in_folders(args: Sequence[str | os.PathLike]) -> set[Path]:
    files, _ = expand_paths([a for a in args if str(a).strip() and Path(a).is_dir()])
    return set(files)


def collect_friction_rows(
    args: Sequence[str | os.PathLike],
    options: Mapping[str, Any] | None = None,
    loads: Sequence[float] | None = None,
    load_unit: str = "nN",
) -> FrictionRows:
    """Friction loops of every line of a load ramp, never stopping at a bad file.

    Parameters
    ----------
    args : sequence of path-like
        Files and folders as the user named them.
    options : mapping, optional
        Reader options (:func:`stickslip.traces.formats.maps.reader_options`).
    loads : sequence of float, optional
        One load per file (after folders are expanded), in ``load_unit``; overrides the
        setpoint stored in the files. With a line schedule, pass it in ``options``.
    load_unit : str
        Unit of ``loads``.

    Returns
    -------
    FrictionRows
        A file found in a folder that is no part of the ramp (a force curve: no image
        channel; or no load stored and none given) becomes one note, not an error, so a
        ramp folder with its calibration curve in it reads cleanly. Named files keep
        their errors.

    Raises
    ------
    ValueError
        If ``loads`` does not give one value per file.
    """
    paths, bad = expand_paths(args)
    if loads is not None and len(loads) != len(paths):
        raise ValueError(f"--loads gives {len(loads)} values for {len(paths)} files")
    from_folder = _in_folders(args)
    out = FrictionRows(errors=list(bad))
    for i, p in enumerate(paths):
        try:
            traces = read_file(p, **dict(options or {}))
        except TraceReadError as e:
            if p in from_folder and _is_force_curve(p):
                out.notes.append(f"skipped {p}: no image channel (a force curve), not a map")
            else:
                out.errors.append(e)
            continue
        if loads is not None:
            for t in traces:
                t.meta.update(load=float(loads[i]), load_unit=load_unit)
        rows = friction_rows(traces)
        if not rows:
            out.errors.append(TraceReadError(p, "no trace/retrace pair to form a friction loop"))
        elif all(r["load"] is None for r in rows):
            if p in from_folder:
                out.notes.append(f"skipped {p}: no load stored in the file (pass --loads to "
                                 "use it)")  # fmt: skip
            else:
                out.errors.append(TraceReadError(p, "load unknown (not stored in the file); "
                                                    "pass --loads"))  # fmt: skip
        else:
            out.rows.extend(rows)
    return out


def summary_csv(summary: Sequence[Mapping[str, Any]], unit: str) -> str:
    """The per-load table friction-load prints: mean and std of friction and offset."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["load", "load_unit", "n_lines", f"friction_{unit}", f"friction_std_{unit}",
                f"offset_{unit}"])  # fmt: skip
    for r in summary:
        w.writerow([f"{r['load']:.9g}", r["load_unit"] or "", r["n"],
                    f"{r['friction_mean']:.9g}", f"{r['friction_std']:.9g}",
                    f"{r['offset_mean']:.9g}"])  # fmt: skip
    return buf.getvalue()


def summarise_friction(rows: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Per-load mean and std of friction and offset (rows with a load only)."""
    return [r for r in summarise_by_load(rows, ["friction", "offset"]) if r["load"] is not None]


# ---------------------------------------------------------------- learned estimates


def read_estimate_rows(path: str | os.PathLike) -> list[dict[str, Any]]:
    """Rows of a result table written by ``label`` or ``infer`` (CSV or JSON).

    Raises
    ------
    ValueError
        One line: unreadable, another format, or no ``load`` column.
    """
    p = Path(path)
    try:
        if p.suffix.lower() == ".json":
            rows = json.loads(p.read_text())
            if not isinstance(rows, list) or not all(isinstance(r, dict) for r in rows):
                raise ValueError(f"{p}: not a list of rows")
        elif p.suffix.lower() == ".csv":
            rows = read_table(p)
        else:
            raise ValueError(f"{p}: estimates table must be .csv or .json")
    except OSError as e:
        raise ValueError(f"{p}: cannot read ({e.strerror})") from None
    except (json.JSONDecodeError, UnicodeDecodeError, csv.Error) as e:
        raise ValueError(f"{p}: not a result table ({type(e).__name__})") from None
    if not rows or not any("load" in r for r in rows):
        raise ValueError(f"{p}: no load column (label or infer a map with loads first)")
    return rows


ESTIMATE_KEYS = ("U0_eV", "K_N_m")
POOLED_KEYS = ("F_mean_nN", "U0_eV", "K_N_m")


def _load_rows(rows: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Rows with their cells as numbers where they are numbers (a CSV reads strings)."""
    out = []
    for r in rows:
        rec: dict[str, Any] = {}
        for k, v in r.items():
            if isinstance(v, str) and k not in ("trace", "file", "channel", "direction",
                                                 "quality", "load_unit", "in_domain"):
                f = float_or_nan(v)
                rec[k] = None if v == "" else (f if math.isfinite(f) or v.lower() == "nan"
                                               else v)  # fmt: skip
            else:
                rec[k] = None if v == "" else v
        if isinstance(rec.get("line"), float) and math.isfinite(rec["line"]):
            rec["line"] = int(rec["line"])
        out.append(rec)
    return out


def pooled_by_load(rows: Sequence[Mapping[str, Any]],
                   keys: Sequence[str] = POOLED_KEYS) -> list[dict[str, Any]]:  # fmt: skip
    """Per-load pooled estimates of the map lines among ``rows``, with their intervals.

    The maps' lines are pooled (:func:`stickslip.estimators.pooling.group_table`); per
    load, the whole-map group of trace and retrace together (one direction where a map
    has one). For each key: ``<key>_mean`` (the pooled value; the mean of the maps' values
    where several maps share a load), ``<key>_lo``/``<key>_hi`` (the pooled 68 % interval,
    its mean over those maps), ``<key>_sigma`` (half its width), ``<key>_n`` (lines used)
    and ``<key>_interval``. Loads with no map are left out.
    """
    groups = [g for g in group_table(_load_rows(rows)) if g["segment"] == "all"
              and g.get("load") is not None]  # fmt: skip
    chosen: dict[tuple, dict[str, Any]] = {}
    for g in groups:
        key = (g["file"], g["channel"], g["load_group"], g["load"])
        if key not in chosen or g["direction"] == "both":
            chosen[key] = g
    out = []
    for load in sorted({float(g["load"]) for g in chosen.values()}):
        maps = [g for g in chosen.values() if float(g["load"]) == load]
        rec: dict[str, Any] = {"load": load, "load_unit": maps[0].get("load_unit") or "",
                               "n": sum(int(g["n_lines"]) for g in maps)}  # fmt: skip
        for k in keys:
            v = np.array([float_or_nan(g.get(k)) for g in maps])
            lo = np.array([float_or_nan(g.get(f"{k}_lo68")) for g in maps])
            hi = np.array([float_or_nan(g.get(f"{k}_hi68")) for g in maps])
            ok = np.isfinite(v) & np.isfinite(lo) & np.isfinite(hi)
            if not ok.any():
                continue
            rec.update({f"{k}_mean": float(v[ok].mean()), f"{k}_lo": float(lo[ok].mean()),
                        f"{k}_hi": float(hi[ok].mean()), f"{k}_n": rec["n"],
                        f"{k}_sigma": float((hi[ok] - lo[ok]).mean() / 2),
                        f"{k}_interval": "pooled 68 % interval of the map"})  # fmt: skip
        out.append(rec)
    return out


def fit_pooled_friction(summary: Sequence[Mapping[str, Any]], key: str = "F_mean_nN"
                        ) -> tuple[list[LawFit], str]:  # fmt: skip
    """Both laws fitted to the maps' pooled <F> against load, each load weighted by its
    pooled interval (:func:`pooled_by_load`); or no fit and the one-line reason."""
    pts = [r for r in summary if math.isfinite(float_or_nan(r.get(f"{key}_mean")))]
    sigma = np.array([float_or_nan(r.get(f"{key}_sigma")) for r in pts])
    try:
        return fit_load_laws([r["load"] for r in pts], [r[f"{key}_mean"] for r in pts],
                             sigma if np.all(sigma > 0) else None), ""  # fmt: skip
    except ValueError as e:
        return [], f"no law fitted to the pooled <F>: {e}"


def estimates_by_load(rows: Sequence[Mapping[str, Any]],
                      keys: Sequence[str] = ESTIMATE_KEYS) -> list[dict[str, Any]]:  # fmt: skip
    """Per-load estimates with an interval: the maps' pooled answer where the rows are
    map lines (:func:`pooled_by_load`), else a plain summary over lines.

    Plain summary, for each load group and key: ``<key>_mean`` (mean over the lines whose
    ``quality`` is ``ok``, or all lines where there is no quality column), ``<key>_std``
    (spread over lines), ``<key>_n``, and ``<key>_lo``/``<key>_hi``: the median over lines
    of each line's 68 % interval (``<key>_lo68``/``_hi68``, as ``infer`` writes) where the
    table has one, else mean +- the spread over lines. Rows without a load are left out.
    """
    pooled = pooled_by_load(rows, tuple(dict.fromkeys([*keys, "F_mean_nN"])))
    if pooled:
        return pooled
    usable = []
    for r in rows:
        q = r.get("quality")
        load = float_or_nan(r.get("load"))
        if (q in (None, "", "ok")) and math.isfinite(load):
            usable.append({**r, "load": load})
    out = []
    for load in sorted({r["load"] for r in usable}):
        group = [r for r in usable if r["load"] == load]
        rec: dict[str, Any] = {"load": load, "load_unit": group[0].get("load_unit") or "",
                               "n": len(group)}  # fmt: skip
        for k in keys:
            v = np.array([float_or_nan(r.get(k)) for r in group])
            lo = np.array([float_or_nan(r.get(f"{k}_lo68")) for r in group])
            hi = np.array([float_or_nan(r.get(f"{k}_hi68")) for r in group])
            ok = np.isfinite(v)
            mean = float(v[ok].mean()) if ok.any() else math.nan
            std = float(v[ok].std(ddof=1)) if ok.sum() > 1 else math.nan
            rec.update({f"{k}_mean": mean, f"{k}_std": std, f"{k}_n": int(ok.sum())})
            both = ok & np.isfinite(lo) & np.isfinite(hi)
            if both.any():
                rec[f"{k}_lo"] = float(np.median(lo[both]))
                rec[f"{k}_hi"] = float(np.median(hi[both]))
                rec[f"{k}_interval"] = "median 68 % interval of a line"
            else:
                half = std if math.isfinite(std) else 0.0
                rec[f"{k}_lo"], rec[f"{k}_hi"] = mean - half, mean + half
                rec[f"{k}_interval"] = "spread over lines"
        out.append(rec)
    return out


# ---------------------------------------------------------------- outputs


def fit_or_reason(summary: Sequence[Mapping[str, Any]]) -> tuple[list[LawFit], str]:
    """Both laws fitted to a friction summary, or no fit and the one-line reason."""
    loads = [r["load"] for r in summary]
    friction = [r["friction_mean"] for r in summary]
    try:
        return fit_load_laws(loads, friction, group_errors(summary, "friction")), ""
    except ValueError as e:
        return [], f"no law fitted: {e}"


def fits_rows(laws: Sequence[LawFit], friction_unit: str,
              load_unit: str) -> list[dict[str, Any]]:  # fmt: skip
    """Rows of the fit table: one per law and parameter."""
    return [row for f in laws for row in f.rows(friction_unit, load_unit)]


def merge_by_load(*summaries: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Per-load rows of several summaries merged on their load (sorted by load)."""
    merged: dict[float, dict[str, Any]] = {}
    for summary in summaries:
        for r in summary:
            if r.get("load") is None:
                continue
            rec = merged.setdefault(float(r["load"]), {})
            for k, v in r.items():
                if k not in rec or rec[k] in (None, ""):
                    rec[k] = v
    return [merged[k] for k in sorted(merged)]


def plot_friction_load(
    summary: Sequence[Mapping[str, Any]],
    laws: Sequence[LawFit],
    out: str | os.PathLike,
    unit: str,
    estimates: Sequence[Mapping[str, Any]] | None = None,
) -> None:
    """Friction against load with both fitted laws drawn over it; U0 and K below if given.

    Parameters
    ----------
    summary : sequence of mapping
        Per-load friction (:func:`summarise_friction`).
    laws : sequence of LawFit
        Fitted laws (labels carry their parameters and goodness of fit).
    out : path-like
        Image file, written atomically.
    unit : str
        Friction unit.
    estimates : sequence of mapping, optional
        :func:`estimates_by_load` rows: U0 and K panels with their intervals.
    """
    from stickslip.diagnostics.plots_load import plot_versus_load

    loads = np.array([r["load"] for r in summary], dtype=float)
    curves: dict[str, list[tuple[str, np.ndarray, np.ndarray]]] = {}
    if laws and loads.size:
        pad = 0.05 * float(np.ptp(loads))
        grid = np.linspace(loads.min() - pad, loads.max() + pad, 200)
        load_unit = next((r.get("load_unit") for r in summary if r.get("load_unit")), "") or ""
        curves["friction"] = [(_legend(f, unit, load_unit), grid, f.predict(grid)) for f in laws]
    quantities = [("friction", f"friction, (trace - retrace)/2 ({unit})")]
    rows: list[dict[str, Any]] = [dict(r) for r in summary]
    if estimates:
        quantities += [("U0_eV", "U0 (eV)"), ("K_N_m", "K (N/m)")]
        rows = merge_by_load(summary, estimates)
    plot_versus_load(rows, quantities, out, title="friction versus load", curves=curves)


def _legend(f: LawFit, friction_unit: str, load_unit: str) -> str:
    (n1, n2), (v1, v2), (s1, s2) = f.names, f.values, f.stds
    gof = f"chi2/dof {f.chi2_red:.2g}" if math.isfinite(f.chi2_red) else f"rms {f.rms:.2g}"
    return f"{f.law}: {n1} = {v1:.3g}+-{s1:.2g}, {n2} = {v2:.3g}+-{s2:.2g} ({gof})"
