"""Commands ``inspect`` (what a file holds) and ``friction-load`` (friction vs load)."""

from __future__ import annotations

import csv
import io
from pathlib import Path
from typing import Any

import typer

from stickslip.atomic import write_text_atomic
from stickslip.cli.common import (
    CALIBRATION_HELP,
    EXIT_FAILED_INPUT,
    EXIT_OK,
    LOADS_HELP,
    LPL_HELP,
    error,
    parse_loads_arg,
    reading_options,
    usage_error,
)
from stickslip.cli.main import app
from stickslip.diagnostics.plots_load import plot_versus_load
from stickslip.traces.formats.common import ScanFile
from stickslip.traces.formats.maps import TRACE, summarise_by_load
from stickslip.traces.readers import expand_paths, is_scan_file, read_file, read_scan
from stickslip.traces.trace import Trace, TraceReadError


def _fmt(v: Any, unit: str = "") -> str:
    if v is None:
        return "unknown"
    if isinstance(v, float):
        return f"{v:.6g}{' ' + unit if unit else ''}"
    return f"{v}{' ' + unit if unit else ''}"


def _describe_scan(scan: ScanFile) -> list[str]:
    m = scan.meta
    lines = [f"  format: {scan.fmt}"]
    shape = next((c.shape for c in scan.channels), None)
    size = scan.scan_size_nm
    if size and shape:
        lines.append(
            f"  scan size: {size:.6g} nm, {shape[0]} lines x {shape[1]} pixels "
            f"(pixel {size / shape[1]:.4g} nm)"
        )
    else:
        lines.append(f"  scan size: {_fmt(size, 'nm')}")
    lines.append(
        f"  scan rate: {_fmt(m.get('scan_rate_hz'), 'Hz')}, "
        f"velocity: {_fmt(m.get('velocity_nm_per_s'), 'nm/s')}"
    )
    lines.append(f"  setpoint/load: {_fmt(m.get('load'), m.get('load_unit') or '')}")
    lines.append(f"  channels ({len(scan.channels)}):")
    for c in scan.channels:
        tag = "  lateral" if c.is_lateral else ""
        lines.append(
            f"    {c.name:<20} {c.direction or '?':<8} {c.unit or '?':<4} "
            f"{c.shape[0]}x{c.shape[1]}{tag}"
        )
    return lines


def _describe_traces(traces: list[Trace]) -> list[str]:
    units = sorted({str(t.meta.get("unit", "nN")) for t in traces})
    dirs = sorted({str(t.meta.get("direction", "trace")) for t in traces})
    lines = [f"  traces: {len(traces)} ({', '.join(dirs)}), unit {'/'.join(units)}"]
    if "V" in units:
        lines.append("    not calibrated: forces in volts; pass --calibration NN_PER_V")
    n = traces[0].n
    lines.append(f"    {n} samples each, x from 0 to {traces[0].x_nm[-1]:.6g} "
                 f"{traces[0].meta.get('x_unit', 'nm')}")
    lines.append(f"    first: {traces[0].name}")
    if len(traces) > 1:
        lines.append(f"    last:  {traces[-1].name}")
    groups = sorted({t.meta.get("load_group") for t in traces} - {None})
    if groups:
        loads = sorted({t.meta.get("load") for t in traces} - {None})
        lines.append(f"    load groups: {len(groups)}; loads: {', '.join(f'{v:g}' for v in loads)}")
    return lines


@app.command("inspect")
def inspect_cmd(
    files: list[str] = typer.Argument(..., help="Files or folders to describe."),
    calibration: float | None = typer.Option(None, "--calibration", help=CALIBRATION_HELP),
    lines_per_load: int | None = typer.Option(None, "--lines-per-load", help=LPL_HELP),
    loads: str | None = typer.Option(None, "--loads", help=LOADS_HELP),
    scan_size_nm: float | None = typer.Option(
        None, "--scan-size-nm", help="Line length for files that do not state it."
    ),
) -> None:
    """Show channels, scan size, rate, setpoint and the traces a file would give."""
    opts = reading_options(calibration, lines_per_load, parse_loads_arg(loads), scan_size_nm)
    paths, bad = expand_paths(files)
    for e in bad:
        error(str(e))
    failed = len(bad)
    for p in paths:
        try:
            out = [f"{p}"]
            if is_scan_file(p):
                out += _describe_scan(read_scan(p))
            traces = read_file(p, **opts)
            if not is_scan_file(p):
                out.append(f"  format: {traces[0].meta.get('format', p.suffix.lstrip('.'))}")
            out += _describe_traces(traces)
        except TraceReadError as e:
            error(str(e))
            failed += 1
            continue
        typer.echo("\n".join(out))
    raise typer.Exit(EXIT_FAILED_INPUT if failed else EXIT_OK)


def _friction_rows(traces: list[Trace]) -> list[dict[str, Any]]:
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


def _csv_text(rows: list[dict[str, Any]], unit: str) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["load", "load_unit", "n_lines", f"friction_{unit}", f"friction_std_{unit}",
                f"offset_{unit}"])
    for r in rows:
        w.writerow([f"{r['load']:.9g}", r["load_unit"] or "", r["n"], f"{r['friction_mean']:.9g}",
                    f"{r['friction_std']:.9g}", f"{r['offset_mean']:.9g}"])
    return buf.getvalue()


@app.command("friction-load")
def friction_load_cmd(
    files: list[str] = typer.Argument(..., help="Friction maps or loops (files or folders)."),
    out: Path = typer.Option(..., "--out", help="Plot of friction versus load (PNG, PDF, SVG)."),
    csv_out: Path | None = typer.Option(None, "--csv", help="Also write the table as CSV."),
    loads: str | None = typer.Option(
        None, "--loads",
        help="Comma-separated loads: one per file, or per line group with --lines-per-load. "
             "Default: the setpoint stored in each file.",
    ),
    load_unit: str = typer.Option("nN", "--load-unit", help="Unit of --loads."),
    lines_per_load: int | None = typer.Option(None, "--lines-per-load", help=LPL_HELP),
    calibration: float | None = typer.Option(None, "--calibration", help=CALIBRATION_HELP),
) -> None:
    """Mean friction, half (trace - retrace), versus setpoint/load for a load ramp."""
    load_list = parse_loads_arg(loads)
    opts = reading_options(calibration, lines_per_load, load_list if lines_per_load else None,
                           None, load_unit)
    paths, bad = expand_paths(files)
    for e in bad:
        error(str(e))
    if load_list and not lines_per_load and len(load_list) != len(paths):
        usage_error(f"--loads gives {len(load_list)} values for {len(paths)} files")
    rows: list[dict[str, Any]] = []
    failed = len(bad)
    for i, p in enumerate(paths):
        try:
            traces = read_file(p, **opts)
            if load_list and not lines_per_load:
                for t in traces:
                    t.meta.update(load=load_list[i], load_unit=load_unit)
            file_rows = _friction_rows(traces)
            if not file_rows:
                raise TraceReadError(p, "no trace/retrace pair to form a friction loop")
            if all(r["load"] is None for r in file_rows):
                raise TraceReadError(p, "load unknown (not stored in the file); pass --loads")
            rows.extend(file_rows)
        except TraceReadError as e:
            error(str(e))
            failed += 1
    if rows:
        units = {r["unit"] for r in rows}
        load_units = {r["load_unit"] for r in rows}
        if len(units) > 1 or len(load_units) > 1:
            error(f"mixed units across files (friction {sorted(map(str, units))}, "
                  f"load {sorted(map(str, load_units))}); pass --calibration or --loads")
            raise typer.Exit(EXIT_FAILED_INPUT)
        unit = units.pop()
        summary = summarise_by_load(rows, ["friction", "offset"])
        text = _csv_text(summary, unit)
        typer.echo(text, nl=False)
        if csv_out is not None:
            write_text_atomic(csv_out, text)
        plot_versus_load(summary, [("friction", f"friction, (trace - retrace)/2 ({unit})")], out,
                         title="friction versus load")
    raise typer.Exit(EXIT_FAILED_INPUT if failed or not rows else EXIT_OK)

