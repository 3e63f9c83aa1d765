"""``stickslip label``: classical (slip-detection + PT inversion) labels of traces."""

from __future__ import annotations

from pathlib import Path

import typer

from stickslip.cli.common import (
    CALIBRATION_HELP,
    EXIT_FAILED_INPUT,
    LOADS_HELP,
    LPL_HELP,
    error,
    info,
    parse_loads_arg,
    reading_options,
    usage_error,
)
from stickslip.cli.main import app


@app.command("label")
def label(
    traces: list[str] = typer.Argument(
        ..., help="Trace files (x_nm,force_nN CSV, or any readable format) or folders of them."
    ),
    out: Path = typer.Option(..., "--out", help="Labels CSV to write (one row per trace)."),
    lattice: float = typer.Option(0.246, "--lattice", help="Lattice spacing a in nm."),
    velocity: float = typer.Option(60.0, "--velocity", help="Scan velocity in nm/s."),
    temperature: float = typer.Option(296.0, "--temperature", help="Temperature in K."),
    plots: Path | None = typer.Option(
        None, "--plots", help="Folder for one diagnostic plot per trace (PNG)."
    ),
    calibration: float | None = typer.Option(None, "--calibration", help=CALIBRATION_HELP),
    lines_per_load: int | None = typer.Option(None, "--lines-per-load", help=LPL_HELP),
    loads: str | None = typer.Option(None, "--loads", help=LOADS_HELP),
) -> None:
    """Label traces with the classical stick-slip estimator.

    Finds the slips, fits the stick slopes and peak forces, and inverts the
    Prandtl-Tomlinson relations (F_max = pi U0/a, stick slope K eta c/(1 + eta c)),
    correcting the peak for thermal activation at the given temperature, velocity and
    lattice. Columns: trace, F_mean_nN, U0_eV, K_N_m, eta, k_exp_N_m, F_peak_nN,
    n_slips, regime, quality, then *_std (spread over slips) and the trace's provenance.
    Traces from maps with a load schedule (--lines-per-load, --loads, or loads stored in
    the file) are also summarised per load (<out>.by_load.csv and .png). Exit code 1 if
    any input could not be read (its row says why), 2 for a usage error.
    """
    if not lattice > 0:
        usage_error(f"--lattice must be > 0 nm (got {lattice:g})")
    if not velocity > 0:
        usage_error(f"--velocity must be > 0 nm/s (got {velocity:g})")
    if not temperature >= 0:
        usage_error(f"--temperature must be >= 0 K (got {temperature:g})")
    if out.is_dir():
        usage_error(f"--out {out} is a directory")

    from stickslip.diagnostics.loads import write_load_report
    from stickslip.estimators.classical import analyse_trace, estimate_traces
    from stickslip.jobs.labels_report import write_labels_csv
    from stickslip.traces.readers import collect_traces

    opts = reading_options(calibration, lines_per_load, parse_loads_arg(loads))
    found, errors = collect_traces(traces, **opts)
    for e in errors:
        error(str(e))
    estimates = estimate_traces(
        found, lattice_nm=lattice, temperature_K=temperature, velocity_nm_per_s=velocity
    )
    try:
        write_labels_csv(out, estimates, errors)
    except OSError as e:
        usage_error(f"cannot write {out} ({e.strerror})")
    by_load = write_load_report([{**e.meta, **e.as_dict()} for e in estimates], out,
                                "classical estimates versus load")  # fmt: skip
    if by_load:
        info(f"wrote {by_load[0]} and {by_load[1]} (per load group)")
    if plots is not None:
        from stickslip.diagnostics.plots_classical import plot_trace_diagnostics

        for tr, est in zip(found, estimates, strict=True):
            plot_trace_diagnostics(
                plots / f"{tr.name}.png", tr.x_nm, tr.force_nN, analyse_trace(tr.x_nm, tr.force_nN),
                est,
            )  # fmt: skip
    n_ok = sum(e.quality == "ok" for e in estimates)
    info(
        f"labelled {len(estimates)} trace(s) ({n_ok} ok, {len(estimates) - n_ok} flagged), "
        f"{len(errors)} unreadable -> {out}"
    )
    if errors:
        raise typer.Exit(EXIT_FAILED_INPUT)
