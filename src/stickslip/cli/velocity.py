"""``stickslip friction-velocity``: the thermally activated PT law from a velocity series."""

from __future__ import annotations

import math
from pathlib import Path

import typer

from stickslip.cli.app import app
from stickslip.cli.common import (
    CALIBRATION_HELP,
    EXIT_FAILED_INPUT,
    EXIT_OK,
    check_plot_path,
    check_table_path,
    echo,
    error,
    info,
    reading_options,
    usage_error,
)


def _velocities(text: str | None) -> list[float] | None:
    if text is None or not text.strip():
        return None
    out = []
    for part in text.split(","):
        try:
            v = float(part)
        except ValueError:
            usage_error(f"bad velocity '{part.strip()}' (expected numbers in nm/s like 3,30,300)")
        if not (math.isfinite(v) and v > 0):
            usage_error(f"bad velocity '{part.strip()}' (must be > 0 nm/s)")
        out.append(v)
    return out


@app.command("friction-velocity")
def friction_velocity_cmd(
    traces: list[str] = typer.Argument(
        ..., help="Traces at several scan velocities (files or folders, any readable format)."
    ),
    out: Path = typer.Option(
        ..., "--out", help="Result table, one row per trace (.csv, .json, .parquet); beside it "
        "<stem>.by_velocity and <stem>.velocity_fit in the same format."),
    plot: Path = typer.Option(
        ..., "--plot", help="Plot of force against velocity (PNG, PDF, SVG)."),
    velocities: str | None = typer.Option(
        None, "--velocities",
        help="Scan velocity in nm/s of each file (comma-separated, one per file after folders "
             "are expanded, or one for all), for files that do not state their own."),
    lattice: float = typer.Option(0.246, "--lattice", help="Lattice spacing a in nm."),
    temperature: float = typer.Option(296.0, "--temperature", help="Temperature in K."),
    check: bool = typer.Option(
        True, "--check/--no-check",
        help="Re-simulate the PT model at the lines' median (U0, K) at the same velocities and "
             "compare (2 nm lines of 96 pixels)."),
    check_lines: int = typer.Option(32, "--check-lines", help="Simulated lines per velocity."),
    seed: int = typer.Option(0, "--seed", help="Seed of the simulated check."),
    calibration: float | None = typer.Option(None, "--calibration", help=CALIBRATION_HELP),
) -> None:
    """Fit the thermally activated PT law to the peak force against scan velocity.

    F_peak(v) = F_c - (beta kB T ln(v_c/v))^(2/3) (Sang, Dube and Grant 2001; Riedo et al.
    2003): the athermal force F_c (pi U0/a in the PT model), the barrier shape beta, and
    the critical velocity v_c (and from it an attempt rate), each with its uncertainty.
    Each trace is labelled with the classical estimator at its own velocity (the file's,
    else --velocities); the per-line peak force is averaged per velocity and fitted, the
    mean friction <F> too (same law shifted by half the slip drop). The fit is checked
    against the simulator at the lines' median U0 and K. Prints the results; exit code 1
    if any input could not be used (the others are still processed), 2 for a usage error.
    """
    from stickslip.jobs.velocity import run_friction_velocity, write_outputs

    if not lattice > 0:
        usage_error(f"--lattice must be > 0 nm (got {lattice:g})")
    if not temperature > 0:
        usage_error(f"--temperature must be > 0 K for a thermal law (got {temperature:g})")
    if not 1 <= check_lines <= 1024:
        usage_error(f"--check-lines must be between 1 and 1024 (got {check_lines})")
    check_table_path("--out", out)
    check_plot_path("--plot", plot)
    opts = reading_options(calibration, None, None)
    if check:
        info("simulating the check series (slow velocities take longest) ...")
    try:
        report = run_friction_velocity(traces, _velocities(velocities), lattice, temperature,
                                       check=check, check_lines=check_lines, seed=seed,
                                       options=opts)  # fmt: skip
    except ValueError as e:
        usage_error(str(e))
    for e in report.errors:
        error(str(e))
    for note in report.notes:
        info(f"stickslip: note: {note}")
    flagged = [r for r in report.table.rows if r.get("quality") not in ("ok", None)
               and r.get("file") not in {e.path for e in report.errors}]  # fmt: skip
    if flagged:
        info(f"stickslip: note: {len(flagged)} trace(s) not labelled (their rows say why)")
    for line in report.summary_lines():
        echo(line)
    try:
        written = write_outputs(report, out, plot)
    except OSError as e:
        usage_error(f"cannot write the outputs ({e.strerror})")
    info("wrote " + ", ".join(str(p) for p in written))
    if report.peak is None or report.errors:
        raise typer.Exit(EXIT_FAILED_INPUT)
    raise typer.Exit(EXIT_OK)
