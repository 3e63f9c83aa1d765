"""The ``infer`` and ``label`` job: files in, one result table (and plots) out.

``label`` is this job with the classical estimator. The job reads every input (an
unreadable one becomes a row with its reason), runs the estimator through the one
interface (:class:`~stickslip.estimators.base.Estimator`), adds the classical
estimator's columns beside a learned one (``classical_*``), optionally runs the
posterior predictive check, and returns everything; :func:`write_outputs` writes the
table, the per-load summary and the panels.
"""

from __future__ import annotations

import os
import re
import textwrap
import zlib
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from stickslip.compiled import cached, compile_ahead
from stickslip.diagnostics.loads import write_load_report
from stickslip.diagnostics.plots import window_panels
from stickslip.diagnostics.plots_classical import plot_trace_diagnostics
from stickslip.diagnostics.ppc import plot_overlay, posterior_predictive_check
from stickslip.diagnostics.ppc import warm as ppc_warm
from stickslip.diagnostics.report_html import write_report
from stickslip.estimators import domain
from stickslip.estimators.base import Estimator
from stickslip.estimators.classical.estimator import KERNELS as CLASSICAL_KERNELS
from stickslip.estimators.classical.estimator import ClassicalEstimator
from stickslip.estimators.classical.estimator import warm as classical_warm
from stickslip.estimators.classical.slips import analyse_trace
from stickslip.estimators.pairs import add_pair_columns
from stickslip.estimators.pooling import GROUP_COLUMNS, groups_summary, pool_groups
from stickslip.estimators.table import (
    OK,
    VOLT_NAMES,
    ResultTable,
    domain_verdict,
    failure_row,
    has_estimate,
    sibling_path,
    write_records,
)
from stickslip.simulators.kernel import KERNELS as SIMULATOR_KERNELS
from stickslip.traces.readers import collect_traces, expand_paths
from stickslip.traces.trace import Trace, TraceReadError

CLASSICAL_BESIDE = ("F_mean_nN", "U0_eV", "K_N_m", "eta", "regime", "quality")
Progress = Callable[[int], None]


@dataclass
class InferResult:
    """What the job produced.

    Attributes
    ----------
    table : ResultTable
        One row per trace, then one per unreadable input.
    traces : list of Trace or None
        Aligned with ``table.rows``: the trace behind each row (None for an input that
        could not be read).
    read_errors : list of TraceReadError
        Inputs that could not be read.
    replicates : dict
        Row index -> the PT model simulated at the estimate (after ``check``).
    groups : list of dict
        The per-map pooled answer, one row per group of map lines
        (:func:`stickslip.estimators.pooling.pool_groups`); empty without map lines.
    """

    table: ResultTable
    traces: list[Trace | None]
    read_errors: list[TraceReadError] = field(default_factory=list)
    replicates: dict[int, np.ndarray] = field(default_factory=dict)
    groups: list[dict[str, Any]] = field(default_factory=list)

    @property
    def refused(self) -> list[int]:
        """Rows without an estimate (unreadable inputs, traces the estimator refused)."""
        return [i for i, r in enumerate(self.table.rows) if not has_estimate(r)]

    def error_lines(self) -> list[str]:
        """One line per unreadable input, and per file and reason for refused traces
        (a map whose 300 lines fail the same way gives one line with the count)."""
        refused = [(i, str(self.table.rows[i]["quality"])) for i in self.refused]
        return [str(e) for e in self.read_errors] + self._grouped(refused)

    def out_of_domain(self) -> list[int]:
        """Rows with an estimate that the in/out-of-domain verdict put out of domain."""
        return [i for i, r in enumerate(self.table.rows)
                if has_estimate(r) and domain_verdict(r) is False]  # fmt: skip

    def domain_lines(self, limit: int = 10) -> list[str]:
        """One line per out-of-domain trace with the verdict's reason, and per file and
        kind of reason for map lines (the numbers in a reason's parentheses differ
        from line to line, so a map's lines are grouped without them); at most
        ``limit`` lines, then how many more (each row's ``domain_reason`` is in the
        table)."""
        out = [(i, str(self.table.rows[i].get("domain_reason") or "out of domain"))
               for i in self.out_of_domain()]  # fmt: skip
        lines = self._grouped(out, key=lambda reason: _DETAIL.sub("", reason))
        if len(lines) > limit:
            lines = [*lines[:limit], f"... and {len(lines) - limit} more (domain_reason)"]
        return lines

    def _grouped(self, items: Sequence[tuple[int, str]],
                 key: Callable[[str], str] = str) -> list[str]:  # fmt: skip
        """``trace: reason`` for each (row, reason), one ``file: n lines: reason`` line
        per file and ``key(reason)`` where several lines of one file share it."""
        groups: dict[tuple[str, str], list[tuple[str, str]]] = {}
        for i, reason in items:
            row, tr = self.table.rows[i], self.traces[i]
            if tr is None:
                continue
            groups.setdefault((tr.source or row["trace"], key(reason)), []).append(
                (row["trace"], reason))
        return [f"{src}: {len(g)} lines: {k}" if len(g) > 1 else f"{g[0][0]}: {g[0][1]}"
                for (src, k), g in groups.items()]  # fmt: skip


#: A parenthesised detail of a verdict's reason (numbers that differ from line to line).
_DETAIL = re.compile(r"\s*\([^()]*\)")


#: The compiled kernels an ``infer`` meets, each with the step that compiles them ahead
#: (:func:`stickslip.compiled.compile_ahead`): every run's (the classical estimator, the
#: longest, and the verdict's trace checks), then the check's simulator.
COMPILE_STEPS = ((classical_warm, CLASSICAL_KERNELS), (domain.warm, domain.KERNELS))
CHECK_COMPILE_STEP = (ppc_warm, SIMULATOR_KERNELS)


def _compile_steps(check: bool) -> list[tuple[Callable[[], None], tuple]]:
    return [*COMPILE_STEPS, CHECK_COMPILE_STEP] if check else list(COMPILE_STEPS)


def kernels_cached(check: bool = False) -> bool:
    """Whether the compiled kernels an ``infer`` meets (the verdict's trace checks and
    the classical estimator; with ``check``, the simulator) are in numba's on-disk cache
    already; False on the first run after installing, which compiles them
    (:mod:`stickslip.compiled`)."""
    return all(cached(*kernels) for _, kernels in _compile_steps(check))


def compile_kernels(check: bool = False, processes: int | None = None) -> None:
    """Compile the kernels of :func:`kernels_cached` that the cache lacks, side by side
    in worker processes (:func:`stickslip.compiled.compile_ahead`), before a first run
    calls them one after another: call it where ``kernels_cached`` is False."""
    compile_ahead([step for step, kernels in _compile_steps(check) if not cached(*kernels)],
                  processes)  # fmt: skip


def read_inputs(paths: Sequence[str | os.PathLike], reader_options: dict[str, Any] | None = None,
                progress: Progress | None = None
                ) -> tuple[list[Trace], list[TraceReadError]]:  # fmt: skip
    """Every trace the inputs hold, and one error per input that cannot be read.

    ``progress`` is called with the number of files read so far (see
    :func:`stickslip.traces.readers.collect_traces`; :func:`count_inputs` gives the total).
    """
    return collect_traces(list(paths), progress=progress, **(reader_options or {}))


def count_inputs(paths: Sequence[str | os.PathLike]) -> int:
    """How many files the inputs expand to (folders expanded), for a progress total."""
    return len(expand_paths(paths)[0])


def infer(
    estimator: Estimator,
    traces: Sequence[Trace],
    read_errors: Sequence[TraceReadError] = (),
    *,
    lattice_nm: float | None = None,
    velocity_nm_per_s: float | None = None,
    temperature_K: float | None = None,
    classical: bool = True,
    check: bool = False,
    split_changes: bool = False,
    progress: Progress | None = None,
) -> InferResult:
    """Run an estimator on traces; see the module docstring.

    Parameters
    ----------
    estimator : Estimator
        Any estimator (:func:`stickslip.estimators.load.load_estimator`).
    traces : sequence of Trace
        Traces read from the inputs (:func:`read_inputs`).
    read_errors : sequence of TraceReadError
        Inputs that could not be read: each becomes a row with its reason.
    lattice_nm, velocity_nm_per_s, temperature_K : float, optional
        User-given conditions (they win over the files' metadata).
    classical : bool
        Add the classical estimator's columns beside a learned estimator's.
    check : bool
        Posterior predictive check of every estimated trace (``gof``, ``ppc_flag``).
    split_changes : bool
        Estimate the two parts of every trace that the verdict finds changing part-way
        (``change_nm``, a tip change) separately too, where each part holds at least
        :data:`MIN_SPLIT_FRACTION` of the trace: one more row each, named ``<trace>
        [x < c nm]`` and ``<trace> [x >= c nm]``.
    progress : callable, optional
        Called with the number of traces checked so far (long checks).
    """
    traces = list(traces)
    flags = {"lattice_nm": lattice_nm, "velocity_nm_per_s": velocity_nm_per_s,
             "temperature_K": temperature_K}  # fmt: skip
    table = estimator.predict(traces, **flags)
    if split_changes:
        parts = split_at_changes(table.rows, traces)
        if parts:
            table.rows.extend(estimator.predict(parts, **flags).rows)
            traces.extend(parts)
            table.notes.append(f"{len(parts) // 2} trace(s) change part-way: each part "
                               "estimated on its own too (rows '<trace> [x < c nm]', "
                               "'[x >= c nm]')")  # fmt: skip
    # both scan directions of a map line: the pair's friction, free of the offset
    n_pairs = add_pair_columns(table.rows, traces)
    if n_pairs:
        table.notes.append(f"{n_pairs} trace/retrace pair(s): friction_pair_* is the mean of "
                           "both directions' friction, free of offsets that do not reverse "
                           "with the scan; U0_pair_*, K_pair_*, eta_pair* the geometric "
                           "means of both directions' estimates, which an offset moves "
                           "in opposite directions")  # fmt: skip
    if classical and estimator.kind != "classical" and traces:
        cl_estimator = ClassicalEstimator()
        cl_estimator.domain_verdict = False  # only its estimates are shown beside
        beside = cl_estimator.predict(traces, **flags)
        for row, cl in zip(table.rows, beside.rows, strict=True):
            row.update({f"classical_{k}": cl.get(k) for k in CLASSICAL_BESIDE})
    result = InferResult(table=table, traces=[*traces])
    if check:
        result.replicates = _check(table, traces, progress)
    verdict = getattr(estimator, "domain_verdict", False)
    for e in read_errors:
        table.rows.append(failure_row(Path(e.path).stem, e.reason, estimator.name, file=e.path))
        if verdict:
            table.rows[-1].update(in_domain=False, domain_score=None,
                                  domain_reason=f"no estimate: {e.reason}")  # fmt: skip
        result.traces.append(None)
    result.read_errors = list(read_errors)
    add_map_groups(result)
    return result


#: The least share of a trace's samples each part of a split needs (``--split-changes``):
#: a few cycles on each side, as the verdict's change check asks for a fifth of them.
MIN_SPLIT_FRACTION = 0.2


def split_at_changes(rows: Sequence[dict[str, Any]], traces: Sequence[Trace]) -> list[Trace]:
    """The two parts of every trace whose row says it changes part-way (``change_nm``),
    where each part holds at least :data:`MIN_SPLIT_FRACTION` of the samples; map
    metadata (line, direction) is left off so that the parts join no map's answer."""
    parts: list[Trace] = []
    for row, t in zip(rows, traces, strict=False):
        c = row.get("change_nm")
        if c is None or not np.isfinite(c):
            continue
        left = np.asarray(t.x_nm) < c
        if min(left.mean(), 1.0 - left.mean()) < MIN_SPLIT_FRACTION:
            continue
        meta = {k: v for k, v in t.meta.items() if k not in ("line", "direction")}
        for mask, label in ((left, f"x < {c:.2f} nm"), (~left, f"x >= {c:.2f} nm")):
            parts.append(Trace(x_nm=np.asarray(t.x_nm)[mask],
                               force_nN=np.asarray(t.force_nN)[mask],
                               name=f"{t.name} [{label}]", source=t.source, meta=meta))  # fmt: skip
    return parts


#: The column that says why a map line was left out of its map's pooled answer.
MAP_REASON = "map_reason"


def add_map_groups(result: InferResult) -> None:
    """Pool the map lines of the result per map, direction and load group
    (:func:`~stickslip.estimators.pooling.pool_groups`): ``result.groups``, and on every
    line the pool left out (inconsistent with its map, or showing what the other lines
    of its map do not) why, ``map_reason``."""
    pooled = pool_groups(result.table.rows)
    result.groups = [{c: g.get(c) for c in GROUP_COLUMNS} for g in pooled.groups]
    for i, reason in pooled.reasons.items():
        result.table.rows[i][MAP_REASON] = reason
    n_flag, n_change = len(pooled.reasons), sum(
        1 for g in result.groups if g["segment"] == "all" and g["change_line"] is not None)
    if n_flag or n_change:
        result.table.notes.append(
            f"per-map pooling: {n_flag} line(s) inconsistent with their map or unlike its "
            f"other lines (map_reason) left out of its answer; {n_change} group(s) with a "
            "change point along the slow scan axis, pooled either side (groups table)")  # fmt: skip


def ppc_seed(name: str) -> int:
    """A replicate seed of the trace's own (never the simulator's default seed 0, so a
    simulated trace is not compared with its own noise)."""
    return 1_000_003 + zlib.crc32(name.encode())


#: Traces per simulate call of the check: large enough to keep every core busy, small
#: enough for a progress bar to move.
CHECK_BATCH = 32


def _check(table: ResultTable, traces: Sequence[Trace], progress: Progress | None
           ) -> dict[int, np.ndarray]:  # fmt: skip
    """Posterior predictive check of the estimated rows, in batches of traces sharing
    their pixel layout (:data:`CHECK_BATCH` per simulate call, progress after each)."""
    todo = [i for i, row in enumerate(table.rows[: len(traces)])
            if row.get("quality") == OK and np.isfinite(row.get("U0_eV", np.nan))]  # fmt: skip
    n_volts = sum(1 for row in table.rows[: len(traces)]
                  if row.get("quality") == OK and "U0_V_nm" in row)  # fmt: skip
    if n_volts:
        table.notes.append(f"--check skipped for {n_volts} trace(s) in volts: the PT model "
                           "is simulated in nN (pass --calibration)")  # fmt: skip
    coarse = [i for i in todo if traces[i].pixel_nm > table.rows[i]["lattice_nm"] / 4]
    if coarse:  # the statistics need slips resolved (and the simulation would be long)
        table.notes.append(f"--check skipped for {len(coarse)} trace(s) whose pixels are "
                           "longer than a quarter lattice period")  # fmt: skip
        todo = [i for i in todo if i not in set(coarse)]
    reps: dict[int, np.ndarray] = {}
    layouts: dict[tuple[int, float], list[int]] = {}
    for i in todo:
        layouts.setdefault((traces[i].n, round(traces[i].pixel_nm, 9)), []).append(i)
    done = 0
    for group in layouts.values():
        for start in range(0, len(group), CHECK_BATCH):
            idx = group[start: start + CHECK_BATCH]
            rows = [table.rows[i] for i in idx]
            r = posterior_predictive_check(
                traces[idx[0]].x_nm, np.stack([traces[i].force_nN for i in idx]),
                np.array([row["U0_eV"] for row in rows]),
                np.array([row["K_N_m"] for row in rows]),
                lattice_nm=np.array([row["lattice_nm"] for row in rows]),
                velocity_nm_per_s=np.array([row["velocity_nm_per_s"] for row in rows]),
                temperature_K=np.array([row["temperature_K"] for row in rows]),
                seed=ppc_seed(traces[idx[0]].name),
            )  # fmt: skip
            for k, (i, row) in enumerate(zip(idx, rows, strict=True)):
                row["gof"] = float(r.gof[k])
                row["ppc_flag"] = int(r.flagged[k])
                reps[i] = r.replicate_nN[k]
            done += len(idx)
            if progress is not None:
                progress(done)
    return reps


def write_outputs(result: InferResult, out: str | os.PathLike, title: str = "estimates"
                  ) -> list[Path]:  # fmt: skip
    """Write the table (format from the extension), the per-map pooled answer beside it
    where there are map lines (``<out stem>.groups.<ext>``) and, where lines carry loads,
    the per-load summary; returns the paths written."""
    written = [result.table.write(out)]
    if result.groups:
        written.append(write_records(result.groups, GROUP_COLUMNS, sibling_path(out, "groups")))
    estimated = [r for r in result.table.rows if has_estimate(r)]
    written += write_load_report(estimated, out, f"{title} versus load")
    return written


def safe_name(name: str) -> str:
    """A file-name-safe version of a trace name (no colons or slashes: valid on every OS)."""
    return re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("_") or "trace"


def _interval(row: dict[str, Any], key: str, unit: str) -> str:
    lo, hi = row.get(f"{key}_lo95"), row.get(f"{key}_hi95")
    text = f"{key.split('_')[0]} = {row[key]:.3g} {unit}"
    return text + (f" [{lo:.3g}, {hi:.3g}]" if lo is not None and hi is not None else "")


def count_panels(result: InferResult) -> int:
    """How many panels :func:`write_panels` draws at most (for a progress total)."""
    return sum(t is not None for t in result.traces)


def write_panels(result: InferResult, estimator: Estimator, out_dir: str | os.PathLike,
                 progress: Progress | None = None) -> list[Path]:  # fmt: skip
    """One PNG per estimated trace in ``out_dir``, drawn for the estimator's kind:
    classical (stick fits and slips; axes in V for a trace in volts), window
    (window-wise estimates), line (the trace, and after a check the PT model at the
    estimate; 95 % intervals in the title). ``progress`` is called with the number of
    traces done."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths: list[Path] = []
    rows = [(i, r, t) for i, (r, t) in enumerate(zip(result.table.rows, result.traces,
                                                     strict=True)) if t is not None]  # fmt: skip
    if estimator.kind == "window":
        idx = [i for i, r, _ in rows if "U0_eV" in r]
        ests, _ = estimator.window_estimates(  # type: ignore[attr-defined]
            [result.traces[i] for i in idx],
            [result.table.rows[i]["lattice_nm"] for i in idx])
        by_row = dict(zip(idx, ests, strict=True))
    for n, (i, row, t) in enumerate(rows):
        path = out / f"{n:03d}_{safe_name(row['trace'])}.png"
        if progress is not None and n:
            progress(n)
        if estimator.kind == "classical":
            plot_trace_diagnostics(path, t.x_nm, t.force_nN, analyse_trace(t.x_nm, t.force_nN),
                                   row, unit="V" if "U0_V_nm" in row else "nN")  # fmt: skip
        elif estimator.kind == "window" and i in by_row:
            e = by_row[i]
            ref = {k: float(row.get(f"classical_{k}") or np.nan) for k in ("U0_eV", "K_N_m", "eta")}
            window_panels(t.x_nm, t.force_nN, e.centres_nm, e.windows, e.values, path,
                          title=row["trace"], reference=ref)  # fmt: skip
        elif "U0_eV" in row:
            title = (f"{row['trace']}: {_interval(row, 'U0_eV', 'eV')}, "
                     f"{_interval(row, 'K_N_m', 'N/m')}, eta = {row['eta']:.3g}")  # fmt: skip
            if estimator.intervals:
                title += " (95 % intervals)"
            if "gof" in row:
                title += f", gof = {row['gof']:.2f}{' FLAGGED' if row['ppc_flag'] else ''}"
            if domain_verdict(row) is False:
                title += "\n" + textwrap.fill("OUT OF DOMAIN (intervals widened): "
                                              + str(row.get("domain_reason")), 110)
            plot_overlay(t.x_nm, t.force_nN, result.replicates.get(i), title, path)
        else:
            continue
        paths.append(path)
    if progress is not None and rows:
        progress(len(rows))
    return paths


#: How the terminal table shows a row's in/out-of-domain verdict.
DOMAIN_MARK = {True: "in", False: "OUT"}


def summary_text(table: ResultTable, truth: dict[str, dict] | None = None, limit: int = 40) -> str:
    """A compact terminal table of the estimated rows: estimates, +- their std (or the
    95 % interval), the in/out-of-domain verdict (:data:`DOMAIN_MARK`), the classical
    estimator's U0 and K beside, true values if known.
    Rows in volts (no calibration) give their values in V, V nm and V/nm, and say so."""
    rows = [r if "U0_V_nm" not in r else {**r, **{k: r.get(v) for k, v in VOLT_NAMES.items()},
                                          **{f"{k}_std": r.get(f"{v}_std")
                                             for k, v in VOLT_NAMES.items()}}
            for r in table.ok()]  # fmt: skip
    w = min(max([len(r["trace"]) for r in rows] + [5]), 40) + 1
    has_cl = any("classical_U0_eV" in r for r in rows)
    head = f"{'trace':<{w}}{'<F> nN':>9}{'U0 eV':>16}{'K N/m':>16}{'eta':>8}"
    has_dom = any("in_domain" in r for r in rows)
    head += f"{'domain':>8}" if has_dom else ""
    head += f"{'gof':>6}" if any("gof" in r for r in rows) else ""
    head += f"{'| classical U0':>15}{'K':>8}" if has_cl else ""
    head += f"{'| true U0':>10}{'K':>7}" if truth else ""
    lines = [head]

    def num(v: Any) -> float:
        return float(v) if isinstance(v, (int, float, np.number)) and v is not None else np.nan

    def pm(v: Any) -> str:
        # five characters whatever the size: a widened interval's std can be 400
        v = num(v)
        if not v >= 9.995:  # NaN too
            return f"{v:<5.2f}"
        return f"{v:<5.1f}" if v < 99.95 else f"{v:<5.0f}" if v < 99999.5 else f"{v:.0e}"

    for r in rows[:limit]:
        s = (f"{r['trace'][: w - 1]:<{w}}{num(r['F_mean_nN']):>9.3f}"
             f"{num(r['U0_eV']):>9.3f}+-{pm(r.get('U0_eV_std'))}"
             f"{num(r['K_N_m']):>9.2f}+-{pm(r.get('K_N_m_std'))}"
             f"{num(r['eta']):>8.2f}")
        if has_dom:
            s += f"{DOMAIN_MARK.get(domain_verdict(r), '-'):>8}"
        if "gof" in r:
            s += f"{r['gof']:>5.1f}{'!' if r.get('ppc_flag') else ' '}"
        if has_cl:
            s += f"{num(r.get('classical_U0_eV')):>15.3f}{num(r.get('classical_K_N_m')):>8.2f}"
        if truth and r["trace"] in truth:
            t = truth[r["trace"]]
            s += f"{t.get('U0_eV', np.nan):>10.3f}{t.get('K_N_m', np.nan):>7.2f}"
        if "U0_V_nm" in r:
            s += "  (in V, V nm, V/nm: no calibration)"
        lines.append(s)
    if len(rows) > limit:
        lines.append(f"... {len(rows) - limit} more rows in the table")
    return "\n".join(lines)


def groups_text(result: InferResult, limit: int = 12) -> str:
    """The short per-map summary the terminal prints after the table ('' without maps)."""
    return groups_summary(result.groups, limit)


def write_run_report(result: InferResult, estimator: Estimator, path: str | os.PathLike,
                     inputs: Sequence[str | os.PathLike], command: Sequence[str] = ()
                     ) -> Path:  # fmt: skip
    """The run's self-contained HTML report (:mod:`stickslip.diagnostics.report_html`)."""
    rows = result.table.rows
    conditions: dict[str, Any] = {}
    for q in ("lattice_nm", "velocity_nm_per_s", "temperature_K"):
        src = q.split("_")[0] + "_source"
        seen = Counter((r.get(q), r.get(src)) for r in rows if r.get(q) is not None)
        if seen:
            (value, source), _ = seen.most_common(1)[0]
            conditions[q] = {"value": value, "source": source}
    info = {
        "files": [str(p) for p in inputs],
        "estimator": f"{estimator.name}: {estimator.describe()}",
        "model": getattr(estimator, "source", estimator.name),
        "conditions": conditions,
        "unreadable": [(e.path, e.reason) for e in result.read_errors],
        "command": list(command),
    }
    traces = [t for t in result.traces if t is not None]
    overlays = {rows[i]["trace"]: rep for i, rep in result.replicates.items()}
    return write_report(path, result.table, traces, info, overlays, groups=result.groups)
