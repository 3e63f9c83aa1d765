"""Commands ``inspect`` (what a file holds) and ``friction-load`` (friction vs load)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import typer

from stickslip.atomic import write_text_atomic
from stickslip.cli.app import app
from stickslip.cli.common import (
    CALIBRATION_HELP,
    EXIT_FAILED_INPUT,
    EXIT_OK,
    LOADS_HELP,
    LPL_HELP,
    check_output_file,
    check_plot_path,
    check_table_path,
    echo,
    error,
    info,
    parse_loads_arg,
    reading_options,
    usage_error,
)
from stickslip.traces.formats.common import ScanFile
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
    if scan.frames:
        lines.append(f"  frames ({len(scan.frames)}):")
        lines += [f"    {f.describe()}" for f in scan.frames]
    return lines


def _describe_traces(traces: list[Trace]) -> list[str]:
    units = sorted({str(t.meta.get("unit", "nN")) for t in traces})
    dirs = sorted({str(t.meta.get("direction", "trace")) for t in traces})
    lines = [f"  traces: {len(traces)} ({', '.join(dirs)}), unit {'/'.join(units)}"]
    if "V" in units:
        lines.append("    not calibrated: forces in volts; pass --calibration NN_PER_V")
    n = traces[0].n
    x_unit = traces[0].meta.get("x_unit", "nm")
    lines.append(f"    {n} samples each, x from 0 to {traces[0].x_nm[-1]:.6g} {x_unit}"
                 + (" (pixel index: no x axis in the file; --scan-size-nm NM)"
                    if x_unit == "px" else ""))  # fmt: skip
    masked = sum(1 for t in traces if t.meta.get("masked_pixels"))
    if masked:
        lines.append(f"    {masked} trace(s) with missing (NaN) pixels, interpolated")
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
    velocity: float | None = typer.Option(
        None, "--velocity", help="Support speed in nm/s, for a recording against time."
    ),
) -> None:
    """Show channels, scan size, rate, setpoint and the traces a file would give."""
    opts = reading_options(calibration, lines_per_load, parse_loads_arg(loads), scan_size_nm,
                           velocity_nm_per_s=velocity)  # fmt: skip
    paths, bad = expand_paths(files)
    for e in bad:
        error(str(e))
    failed = len(bad)
    for p in paths:
        try:
            out = [f"{p}"]
            if is_scan_file(p):
                scan = read_scan(p)
                out += _describe_scan(scan)
                if scan.channels and not scan.lateral():  # an image, but not a friction map
                    typer.echo("\n".join([*out, "  traces: none (no lateral-force channel)"]))
                    continue
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
    fits: Path | None = typer.Option(
        None, "--fits", help="Write the fitted laws, one row per parameter (.csv, .json, "
                             ".parquet)."),
    estimates: Path | None = typer.Option(
        None, "--estimates",
        help="Result table of label or infer on the same maps (CSV or JSON, with a load "
             "column): the maps' pooled U0 and K against load, with their intervals, under "
             "the friction; both laws also fitted to the pooled <F> (law pooled_*)."),
) -> None:
    """Mean friction, half (trace - retrace), versus setpoint/load for a load ramp.

    Fits both the linear law F = mu L + F0 and the DMT-like F = c (L + L_adh)^(2/3), with
    one-standard-deviation uncertainties and a goodness of fit each (printed to stderr,
    drawn over the data, and with --fits written as a table); neither is chosen for you.
    In a folder, force curves and files without a load are skipped with a note.
    """
    from stickslip.diagnostics import load_fits as lf
    from stickslip.estimators.table import ResultTable

    check_plot_path("--out", out)
    if csv_out is not None:
        check_output_file("--csv", csv_out)
    load_list = parse_loads_arg(loads)
    opts = reading_options(calibration, lines_per_load, load_list if lines_per_load else None,
                           None, load_unit)
    if fits is not None:
        check_table_path("--fits", fits)
    failed = 0
    est_summary = None
    if estimates is not None:
        try:
            est_summary = lf.estimates_by_load(lf.read_estimate_rows(estimates))
        except ValueError as e:
            error(str(e))
            failed += 1
    try:
        found = lf.collect_friction_rows(files, opts, None if lines_per_load else load_list,
                                         load_unit)
    except ValueError as e:
        usage_error(str(e))
    for e in found.errors:
        error(str(e))
    for note in found.notes:
        info(f"stickslip: note: {note}")
    failed += len(found.errors)
    rows = found.rows
    if rows:
        units = {r["unit"] for r in rows}
        load_units = {r["load_unit"] for r in rows}
        if len(units) > 1 or len(load_units) > 1:
            error(f"mixed units across files (friction {sorted(map(str, units))}, "
                  f"load {sorted(map(str, load_units))}); pass --calibration or --loads")
            raise typer.Exit(EXIT_FAILED_INPUT)
        unit = str(units.pop())
        load_unit_found = str(load_units.pop() or "")
        summary = lf.summarise_friction(rows)
        text = lf.summary_csv(summary, unit)
        echo(text.rstrip("\n"))
        if csv_out is not None:
            write_text_atomic(csv_out, text)
        laws, reason = lf.fit_or_reason(summary)
        for law in laws:
            info(law.summary(unit, load_unit_found))
        if reason:
            info(f"stickslip: note: {reason}")
        fit_rows = lf.fits_rows(laws, unit, load_unit_found)
        if est_summary and any("F_mean_nN_sigma" in r for r in est_summary):
            pooled_laws, why = lf.fit_pooled_friction(est_summary)
            for law in pooled_laws:
                info("pooled <F> of the estimates: " + law.summary("nN", load_unit_found))
            if why:
                info(f"stickslip: note: {why}")
            fit_rows += [{**row, "law": f"pooled_{row['law']}"}
                         for row in lf.fits_rows(pooled_laws, "nN", load_unit_found)]
        lf.plot_friction_load(summary, laws, out, unit, est_summary)
        if fits is not None and fit_rows:
            ResultTable(rows=fit_rows).write(fits)
    raise typer.Exit(EXIT_FAILED_INPUT if failed or not rows else EXIT_OK)
