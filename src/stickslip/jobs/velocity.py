"""The ``friction-velocity`` job: friction traces at several scan velocities in; the
thermally activated PT law fitted, checked against the simulator; tables and a plot out.

Steps:

1. read every input; each trace's velocity is the file's own (``velocity_nm_per_s`` in
   its metadata), else the value given for that file; a file with neither is an error;
2. label each trace with the classical estimator at its velocity, the given lattice
   and temperature (:class:`~stickslip.estimators.classical.ClassicalEstimator`);
3. average the per-line peak force ``F_peak`` (and ``<F>``) per velocity and fit the law
   of :mod:`stickslip.diagnostics.velocity`;
4. check: simulate the PT model at the lines' median (U0, K) at the same velocities
   (short lines, see :func:`~stickslip.diagnostics.velocity.simulated_series`), label
   the simulated lines the same way, and compare per velocity (z-scores) and by fitting
   the same law to them.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from stickslip.atomic import atomic_path
from stickslip.diagnostics import velocity as vel
from stickslip.estimators.classical.estimator import ClassicalEstimator
from stickslip.estimators.table import ResultTable, failure_row
from stickslip.traces.readers import expand_paths, read_file
from stickslip.traces.trace import Trace, TraceReadError
from stickslip.units import fmax_nN

VELOCITY = "velocity_nm_per_s"


@dataclass
class VelocityReport:
    """Everything the job produced.

    Attributes
    ----------
    table : ResultTable
        One row per trace (classical estimates, the velocity and its source), then one
        per unreadable input.
    peak, mean : VelocityGroups or None
        Per-velocity mean ``F_peak`` and ``<F>`` of the lines labelled ``ok``.
    peak_fit, mean_fit : VelocityFit or None
        The law fitted to them (None with too few velocities: see ``notes``).
    U0_eV, K_N_m, k_exp_N_m : float
        Medians over the ``ok`` lines (the check simulates at the first two).
    sim, sim_fit : VelocityGroups, VelocityFit or None
        The simulated check: per-velocity mean ``F_peak`` at the medians, and its fit.
    z : ndarray or None
        Per velocity, (measured - simulated) / combined standard error.
    z_rms : float
        RMS of ``z``: about 1 when the simulator at the estimates reproduces the series.
    errors : list of TraceReadError
        Inputs that could not be used.
    notes : list of str
        Things the user should know (one line each).
    """

    table: ResultTable
    lattice_nm: float
    temperature_K: float
    peak: vel.VelocityGroups | None = None
    mean: vel.VelocityGroups | None = None
    peak_fit: vel.VelocityFit | None = None
    mean_fit: vel.VelocityFit | None = None
    U0_eV: float = math.nan
    K_N_m: float = math.nan
    k_exp_N_m: float = math.nan
    sim: vel.VelocityGroups | None = None
    sim_fit: vel.VelocityFit | None = None
    z: np.ndarray | None = None
    z_rms: float = math.nan
    errors: list[TraceReadError] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    @property
    def F_max_nN(self) -> float:
        """``pi U0 / a`` at the median classical U0 (thermally corrected)."""
        return float(fmax_nN(self.U0_eV, self.lattice_nm)) if math.isfinite(self.U0_eV) \
            else math.nan  # fmt: skip

    def summary_lines(self) -> list[str]:
        """The results in a few lines (fits, the athermal comparison, the check)."""
        out = []
        if self.peak is not None:
            pts = ", ".join(f"{v:.3g}: {m:.4g}+-{s:.2g}" for v, m, s in
                            zip(self.peak.velocity_nm_per_s, self.peak.mean, self.peak.sem,
                                strict=True))  # fmt: skip
            out.append(f"F_peak per velocity (nm/s: nN): {pts}")
        for f in (self.peak_fit, self.mean_fit):
            if f is not None:
                out.append(f.summary())
        if self.peak_fit is not None and math.isfinite(self.F_max_nN):
            f = self.peak_fit
            inside = f.F_c_lo <= self.F_max_nN <= f.F_c_hi
            out.append(f"athermal check: F_c = {f.F_c_nN:.4g} nN (68 %: {f.F_c_lo:.4g} to "
                       f"{f.F_c_hi:.4g}) against pi U0/a = {self.F_max_nN:.4g} nN at the lines' "
                       f"median U0 = {self.U0_eV:.4g} eV: {'inside' if inside else 'outside'} "
                       "the interval")  # fmt: skip
            f0, lo, hi = f.attempt_rate(self.k_exp_N_m, float(np.mean(self.peak.mean)))
            out.append(f"attempt rate f0 ~ {f0:.3g} 1/s (68 %: {lo:.3g} to {hi:.3g}; from v_c "
                       f"with k = k_exp = {self.k_exp_N_m:.3g} N/m)")  # fmt: skip
        if self.sim is not None:
            out.append(f"simulator check at U0 = {self.U0_eV:.4g} eV, K = {self.K_N_m:.4g} N/m: "
                       f"RMS z = {self.z_rms:.3g} over {self.sim.mean.size} velocities "
                       f"(z: {', '.join(f'{z:.2g}' for z in self.z)})")  # fmt: skip
            if self.sim_fit is not None:
                out.append("simulated " + self.sim_fit.summary())
        return out


def _velocity_values(values: Sequence[float] | None, n_files: int) -> list[float | None]:
    if not values:
        return [None] * n_files
    if len(values) == 1:
        return [float(values[0])] * n_files
    if len(values) != n_files:
        raise ValueError(f"--velocities gives {len(values)} values for {n_files} files "
                         "(give one per file, or one for all)")  # fmt: skip
    return [float(v) for v in values]


def read_series(
    args: Sequence[str | os.PathLike],
    velocities: Sequence[float] | None = None,
    options: Mapping[str, Any] | None = None,
) -> tuple[list[tuple[Trace, str]], list[TraceReadError], list[str]]:
    """Traces with their velocity: the file's, else the one given for the file.

    Returns
    -------
    traces : list of (Trace, source)
        Each trace with ``meta["velocity_nm_per_s"]`` set and the source of the value
        (``file`` or ``flag``).
    errors : list of TraceReadError
        Unreadable files and files with no velocity.
    notes : list of str
        Files whose own velocity overrode a different value given for them.

    Raises
    ------
    ValueError
        If ``velocities`` is neither one value nor one per file.
    """
    paths, errors = expand_paths(args)
    given = _velocity_values(velocities, len(paths))
    out: list[tuple[Trace, str]] = []
    notes: list[str] = []
    for p, v in zip(paths, given, strict=True):
        try:
            traces = read_file(p, **dict(options or {}))
        except TraceReadError as e:
            errors.append(e)
            continue
        own = [t.meta.get(VELOCITY) for t in traces]
        if all(isinstance(x, (int, float)) and x > 0 for x in own):
            if v is not None and any(abs(x - v) > 1e-3 * v for x in own):
                notes.append(f"{p}: the file states {own[0]:g} nm/s; the given {v:g} nm/s "
                             "is not used")  # fmt: skip
            out.extend((t, "file") for t in traces)
        elif v is not None:
            for t in traces:
                t.meta[VELOCITY] = v
            out.extend((t, "flag") for t in traces)
        else:
            errors.append(TraceReadError(p, "velocity unknown (not in the file); pass "
                                            "--velocities"))  # fmt: skip
    return out, errors, notes


def _median(rows: Sequence[Mapping[str, Any]], key: str) -> float:
    vals = np.array([float(r[key]) for r in rows if isinstance(r.get(key), (int, float))])
    vals = vals[np.isfinite(vals)]
    return float(np.median(vals)) if vals.size else math.nan


def run_friction_velocity(
    args: Sequence[str | os.PathLike],
    velocities: Sequence[float] | None = None,
    lattice_nm: float = 0.246,
    temperature_K: float = 296.0,
    check: bool = True,
    check_lines: int = 32,
    check_length_nm: float = 2.0,
    check_pixels: int = 96,
    seed: int = 0,
    options: Mapping[str, Any] | None = None,
) -> VelocityReport:
    """Read, label, fit and check a friction-velocity series (see the module docstring).

    Parameters
    ----------
    args : sequence of path-like
        Trace files or folders.
    velocities : sequence of float, optional
        Scan velocity (nm/s) per file (after folders are expanded), or one for all;
        used where a file does not state its own.
    lattice_nm, temperature_K : float
        Lattice spacing and temperature of the measurement.
    check : bool
        Re-simulate at the median estimates and compare.
    check_lines, check_length_nm, check_pixels : int, float, int
        Simulated lines per velocity and their recorded length and pixels.
    seed : int
        Seed of the simulated check.
    options : mapping, optional
        Reader options (calibration, load schedule).

    Returns
    -------
    VelocityReport
    """
    found, errors, notes = read_series(args, velocities, options)
    est = ClassicalEstimator()
    table = ResultTable(estimator=est.name, intervals=False)
    # one batch per source: a value from the file or one given for it
    for src in ("file", "flag"):
        traces = [t for t, s in found if s == src]
        if not traces:
            continue
        if src == "file":
            part = est.predict(traces, lattice_nm=lattice_nm, temperature_K=temperature_K)
        else:  # the given velocity, marked as the user's
            part = ResultTable(estimator=est.name)
            for v in sorted({t.meta[VELOCITY] for t in traces}):
                group = [t for t in traces if t.meta[VELOCITY] == v]
                part.extend(est.predict(group, lattice_nm=lattice_nm, velocity_nm_per_s=v,
                                        temperature_K=temperature_K))  # fmt: skip
        table.extend(part)
    for e in errors:
        table.rows.append(failure_row(Path(e.path).stem, e.reason, est.name, file=e.path))
    report = VelocityReport(table=table, lattice_nm=lattice_nm, temperature_K=temperature_K,
                            errors=errors, notes=notes)  # fmt: skip
    ok = table.ok()
    if not ok:
        report.notes.append("no trace could be labelled: nothing to fit")
        return report
    v = np.array([float(r[VELOCITY]) for r in ok])
    peak = np.array([vel_value(r, "F_peak_nN") for r in ok])
    sem = vel.line_sem(np.array([vel_value(r, "F_peak_nN_std") for r in ok]),
                       np.array([vel_value(r, "n_slips") for r in ok]))  # fmt: skip
    report.peak = vel.group_by_velocity(v, peak, sem)
    # <F>: one line's error is the spread of its per-cycle mean force over sqrt(cycles)
    mean_sem = vel.line_sem(np.array([vel_value(r, "F_mean_nN_std") for r in ok]),
                            np.array([vel_value(r, "n_slips") for r in ok]) - 1)  # fmt: skip
    report.mean = vel.group_by_velocity(v, np.array([vel_value(r, "F_mean_nN") for r in ok]),
                                        mean_sem)  # fmt: skip
    report.U0_eV, report.K_N_m = _median(ok, "U0_eV"), _median(ok, "K_N_m")
    report.k_exp_N_m = _median(ok, "k_exp_N_m")
    for attr, g, name in (("peak_fit", report.peak, "F_peak_nN"),
                          ("mean_fit", report.mean, "F_mean_nN")):  # fmt: skip
        try:
            setattr(report, attr, vel.fit_thermal_law(g.velocity_nm_per_s, g.mean, g.sem,
                                                      temperature_K, name))  # fmt: skip
        except ValueError as e:
            report.notes.append(f"no law fitted to {name}: {e}")
    if check and math.isfinite(report.U0_eV) and math.isfinite(report.K_N_m):
        s = vel.simulated_series(report.U0_eV, report.K_N_m, report.peak.velocity_nm_per_s,
                                 lattice_nm=lattice_nm, temperature_K=temperature_K,
                                 lines=check_lines, length_nm=check_length_nm,
                                 pixels=check_pixels, seed=seed)  # fmt: skip
        report.sim = vel.group_by_velocity(s[VELOCITY], s["F_peak_nN"],
                                           vel.line_sem(s["F_peak_nN_std"], s["n_slips"]))
        report.z, report.z_rms = vel.check_rows(report.peak, report.sim)
        try:
            report.sim_fit = vel.fit_thermal_law(report.sim.velocity_nm_per_s, report.sim.mean,
                                                 report.sim.sem, temperature_K,
                                                 "F_peak_nN (simulated)")  # fmt: skip
        except ValueError:
            pass
    return report


def vel_value(row: Mapping[str, Any], key: str) -> float:
    """A numeric cell as float (NaN where missing)."""
    v = row.get(key)
    return float(v) if isinstance(v, (int, float, np.integer, np.floating)) else math.nan


def by_velocity_table(report: VelocityReport) -> ResultTable:
    """One row per velocity: measured means, the fitted law there, the simulated check."""
    rows: list[dict[str, Any]] = []
    g = report.peak
    if g is None:
        return ResultTable(rows=rows)
    for i, v in enumerate(g.velocity_nm_per_s):
        row: dict[str, Any] = {VELOCITY: v, "n_lines": int(g.n_lines[i]),
                               "F_peak_nN": g.mean[i], "F_peak_nN_sem": g.sem[i]}  # fmt: skip
        if report.peak_fit is not None:
            row["F_peak_fit_nN"] = float(report.peak_fit.predict(v))
        if report.mean is not None:
            j = int(np.argmin(np.abs(report.mean.velocity_nm_per_s - v)))
            row["F_mean_nN"] = report.mean.mean[j]
            row["F_mean_nN_sem"] = report.mean.sem[j]
        if report.sim is not None and report.z is not None:
            j = int(np.argmin(np.abs(np.log(report.sim.velocity_nm_per_s / v))))
            row["F_peak_sim_nN"] = report.sim.mean[j]
            row["F_peak_sim_nN_sem"] = report.sim.sem[j]
            row["z_sim"] = report.z[i]
        rows.append(row)
    return ResultTable(rows=rows)


def fit_table(report: VelocityReport) -> ResultTable:
    """One row per fitted parameter (F_peak, <F>, the simulated series), then derived ones."""
    rows: list[dict[str, Any]] = []
    a = report.lattice_nm
    for f in (report.peak_fit, report.mean_fit, report.sim_fit):
        if f is not None:
            rows += vel.fit_rows(f, a)
    if report.peak_fit is not None and report.peak is not None:
        mean_peak = float(np.mean(report.peak.mean))
        f0, lo, hi = report.peak_fit.attempt_rate(report.k_exp_N_m, mean_peak)
        rows.append({"quantity": "F_peak_nN", "parameter": "f0 (attempt rate)", "value": f0,
                     "lo68": lo, "hi68": hi, "unit": "1/s",
                     "note": f"3 k v_c sqrt(F_c - <F_peak>)/(2 beta kT), k = k_exp = "
                             f"{report.k_exp_N_m:.4g} N/m"})  # fmt: skip
    if math.isfinite(report.U0_eV):
        rows.append({"quantity": "classical estimates", "parameter": "pi U0/a", "value":
                     report.F_max_nN, "unit": "nN", "note": f"median U0 {report.U0_eV:.4g} eV, "
                     f"median K {report.K_N_m:.4g} N/m"})  # fmt: skip
    if report.sim is not None:
        rows.append({"quantity": "simulator check", "parameter": "RMS z", "value": report.z_rms,
                     "unit": "", "note": "measured minus simulated F_peak per velocity over "
                     "their combined standard error"})  # fmt: skip
    return ResultTable(rows=rows)


def side_paths(out: str | os.PathLike) -> tuple[Path, Path]:
    """The per-velocity and fit tables written beside ``out`` (same format)."""
    out = Path(out)
    return (out.with_name(f"{out.stem}.by_velocity{out.suffix}"),
            out.with_name(f"{out.stem}.velocity_fit{out.suffix}"))  # fmt: skip


def write_outputs(report: VelocityReport, out: str | os.PathLike,
                  plot: str | os.PathLike | None = None) -> list[Path]:  # fmt: skip
    """Write the per-trace table, the two side tables and the plot; returns their paths."""
    by_v, fits = side_paths(out)
    written = [report.table.write(out)]
    if report.peak is not None:
        written += [by_velocity_table(report).write(by_v), fit_table(report).write(fits)]
    if plot is not None and report.peak is not None:
        plot_velocity(report, plot)
        written.append(Path(plot))
    return written


def plot_velocity(report: VelocityReport, out: str | os.PathLike) -> None:
    """Peak force and <F> against velocity with the fitted law, the athermal F_max and the
    simulated check; the classical U0 per velocity below (it should not depend on v)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    g = report.peak
    assert g is not None
    fig, (ax, ax2) = plt.subplots(2, 1, figsize=(6, 6.4), sharex=True,
                                  gridspec_kw={"height_ratios": [2.2, 1]})  # fmt: skip
    vmin, vmax = float(g.velocity_nm_per_s.min()), float(g.velocity_nm_per_s.max())
    grid = np.geomspace(vmin / 2, vmax * 2, 200)
    ax.errorbar(g.velocity_nm_per_s, g.mean, yerr=np.nan_to_num(g.sem), fmt="o", capsize=3,
                color="C0", label="F_peak (measured, mean over lines)")  # fmt: skip
    f = report.peak_fit
    if f is not None:
        hi = "inf" if math.isinf(f.F_c_hi) else f"{f.F_c_hi:.3g}"
        ax.plot(grid, f.predict(grid), color="C0",
                label=f"fit: F_c = {f.F_c_nN:.3g} nN (68 %: {f.F_c_lo:.3g} to {hi}), v_c = "
                      f"{f.v_c_nm_per_s:.3g} nm/s")  # fmt: skip
        if math.isfinite(f.F_c_hi):
            ax.axhspan(f.F_c_lo, f.F_c_hi, color="C0", alpha=0.12)
    if math.isfinite(report.F_max_nN):
        ax.axhline(report.F_max_nN, color="k", ls="--", lw=1,
                   label=f"pi U0/a = {report.F_max_nN:.3g} nN (median classical U0)")
    if report.sim is not None:
        s = report.sim
        ax.errorbar(s.velocity_nm_per_s * 1.06, s.mean, yerr=np.nan_to_num(s.sem), fmt="s",
                    capsize=3, color="C3", mfc="none", label="F_peak simulated at median "
                    f"U0 = {report.U0_eV:.3g} eV, K = {report.K_N_m:.3g} N/m (RMS z "
                    f"{report.z_rms:.2g})")  # fmt: skip
        if report.sim_fit is not None:
            ax.plot(grid, report.sim_fit.predict(grid), color="C3", ls=":")
    m = report.mean
    if m is not None:
        ax.errorbar(m.velocity_nm_per_s, m.mean, yerr=np.nan_to_num(m.sem), fmt="^", capsize=3,
                    color="C2", label="<F> (measured)")  # fmt: skip
        if report.mean_fit is not None:
            ax.plot(grid, report.mean_fit.predict(grid), color="C2")
    ax.set_xscale("log")
    ax.set_ylabel("force (nN)")
    ax.set_title(f"friction versus velocity, T = {report.temperature_K:g} K, "
                 f"a = {report.lattice_nm:g} nm")  # fmt: skip
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=6.5, loc="lower right")
    rows = report.table.ok()
    v = np.array([float(r[VELOCITY]) for r in rows])
    u = np.array([vel_value(r, "U0_eV") for r in rows])
    ax2.plot(v, u, ".", color="0.6", ms=3, label="per line")
    uv = vel.group_by_velocity(v, u)
    ax2.errorbar(uv.velocity_nm_per_s, uv.mean, yerr=np.nan_to_num(uv.sem), fmt="o", capsize=3,
                 color="C1", label="mean per velocity")  # fmt: skip
    ax2.set_ylabel("classical U0 (eV)")
    ax2.set_xlabel("scan velocity (nm/s)")
    ax2.grid(alpha=0.3, which="both")
    ax2.legend(fontsize=6.5)
    fig.tight_layout()
    suffix = os.path.splitext(os.fspath(out))[1] or ".png"
    try:
        with atomic_path(out, suffix=suffix) as tmp:
            fig.savefig(tmp, format=suffix.lstrip("."), dpi=120)
    finally:
        plt.close(fig)


__all__ = [
    "VelocityReport",
    "by_velocity_table",
    "fit_table",
    "plot_velocity",
    "read_series",
    "run_friction_velocity",
    "side_paths",
    "write_outputs",
]
