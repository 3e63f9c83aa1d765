"""Commands ``train``, ``infer``, ``evaluate`` and ``demo`` (the learned estimator)."""

from __future__ import annotations

from pathlib import Path

import typer

from stickslip.cli.common import (
    CALIBRATION_HELP,
    EXIT_FAILED_INPUT,
    EXIT_OK,
    LOADS_HELP,
    LPL_HELP,
    error,
    info,
    parse_loads_arg,
    reading_options,
    usage_error,
)
from stickslip.cli.main import app

MODEL_HELP = "Model file from 'stickslip train' (default: the bundled model)."


def _load_model(path: Path | None, any_kind: bool = False):
    from stickslip.estimators.line.modelfile import load_any_model
    from stickslip.estimators.window.modelfile import ModelFileError, load_model

    try:
        return load_any_model(path) if any_kind else load_model(path)
    except ModelFileError as e:
        usage_error(str(e))


def _load_data(path: Path):
    from stickslip.traces.dataset import DatasetError, load_dataset

    try:
        return load_dataset(path)
    except DatasetError as e:
        usage_error(str(e))


@app.command("train")
def train_cmd(
    data: Path = typer.Option(..., "--data", help="Simulated sweep (.h5) from 'simulate'."),
    out: Path = typer.Option(..., "--out", "-o", help="Model file to write (.pt)."),
    features: str = typer.Option("pi", "--features", help="Input recipe: raw or pi."),
    epochs: int = typer.Option(50, "--epochs", help="Training epochs."),
    batch_size: int = typer.Option(300, "--batch-size", help="Windows per batch."),
    lr: float = typer.Option(5e-4, "--lr", help="Adam learning rate."),
    window: int = typer.Option(64, "--window", help="Pixels per window p."),
    stride: int | None = typer.Option(
        None, "--stride", help="Window stride at inference (default: the window, no overlap)."
    ),
    train_stride: int = typer.Option(16, "--train-stride", help="Window stride for training."),
    seed: int = typer.Option(0, "--seed", help="Seed of the split and the optimiser."),
    noise: float = typer.Option(
        0.0, "--noise", help="Augmentation: white noise per window, sigma uniform in [0, NOISE] "
        "nN, redrawn every epoch (0: the paper's clean training)."
    ),
    progress: bool = typer.Option(True, "--progress/--no-progress", help="Progress bar."),
) -> None:
    """Train the reference paper's MLP on a simulated sweep (80/20 split by trajectory).

    Writes the model file, a loss-curve plot beside it (<out>.loss.png) and prints the
    validation metrics (per-trajectory, mean over windows).
    """
    from stickslip.diagnostics.plots import loss_curve
    from stickslip.estimators.window.features import FeatureError
    from stickslip.estimators.window.training import TrainConfig, spec_for_dataset, train_model
    from stickslip.jobs.workflow import validate_and_save

    if features not in ("raw", "pi"):
        usage_error(f"--features must be raw or pi (got '{features}')")
    if epochs < 1 or batch_size < 1 or not lr > 0 or noise < 0:
        usage_error("--epochs, --batch-size and --lr must be positive, --noise >= 0")
    ds = _load_data(data)
    try:
        spec = spec_for_dataset(ds, features, window, stride or window, train_stride)
        if ds.force_nN.shape[1] < window:
            usage_error(f"--window {window} is longer than the traces ({ds.force_nN.shape[1]})")
        cfg = TrainConfig(epochs=epochs, batch_size=batch_size, lr=lr, seed=seed, noise_nN=noise)
        model, hist, val_idx = train_model(ds, spec, cfg, progress=progress)
    except (FeatureError, ValueError) as e:
        usage_error(str(e))
    ev = validate_and_save(model, ds, val_idx, out)
    loss_curve(hist.train_loss, hist.val_loss, out.with_suffix(".loss.png"))
    info(f"trained {epochs} epochs in {hist.seconds:.0f} s; validation ({val_idx.size} traj.):")
    typer.echo(ev.summary())
    info(f"wrote {out} and {out.with_suffix('.loss.png')}")


@app.command("infer")
def infer_cmd(
    traces: list[str] = typer.Argument(..., help="Trace files or folders."),
    out: Path = typer.Option(..., "--out", "-o", help="Result table (CSV)."),
    model: Path | None = typer.Option(None, "--model", help=MODEL_HELP),
    lattice: float | None = typer.Option(
        None, "--lattice", help="Lattice spacing a in nm (default: the model's, 0.246)."
    ),
    velocity: float | None = typer.Option(None, "--velocity", help="Scan velocity, nm/s."),
    temperature: float | None = typer.Option(None, "--temperature", help="Temperature, K."),
    calibration: float | None = typer.Option(None, "--calibration", help=CALIBRATION_HELP),
    lines_per_load: int | None = typer.Option(None, "--lines-per-load", help=LPL_HELP),
    loads: str | None = typer.Option(None, "--loads", help=LOADS_HELP),
    plots: Path | None = typer.Option(None, "--plots", help="Folder for per-trace panels."),
    classical: bool = typer.Option(
        True, "--classical/--no-classical", help="Add the classical estimator's columns."
    ),
    check: bool = typer.Option(
        False, "--check", help="Line models: re-simulate each trace at its estimate and report"
        " a goodness of fit (gof, ppc_flag); with --plots the overlay is drawn."
    ),
) -> None:
    """Estimate <F>, U0, K and eta of each trace with a trained network.

    Default model: the bundled whole-line CNN ensemble, one row per trace with the
    estimates, their standard deviations (*_std) and 68 % / 95 % intervals (*_lo68,
    *_hi68, *_lo95, *_hi95). With a window model (--model from 'stickslip train'): mean
    over windows, spread over windows (*_std) and window count. The classical
    estimator's values are beside them (classical_*). Unreadable or too-short traces
    are reported one line each; the others are processed (exit code 1).
    """
    from stickslip.jobs.workflow import infer_job

    for name, v in (("--lattice", lattice), ("--velocity", velocity)):
        if v is not None and not v > 0:
            usage_error(f"{name} must be > 0")
    if temperature is not None and temperature < 0:
        usage_error("--temperature must be >= 0 K")
    opts = reading_options(calibration, lines_per_load, parse_loads_arg(loads))
    m = _load_model(model, any_kind=True)
    failed = infer_job(
        m, traces, out, plots, lattice_nm=lattice, velocity_nm_per_s=velocity,
        temperature_K=temperature, reader_options=opts, classical=classical,
        echo=typer.echo, warn=error, note=info, check=check,
    )  # fmt: skip
    raise typer.Exit(EXIT_FAILED_INPUT if failed else EXIT_OK)


@app.command("evaluate")
def evaluate_cmd(
    model: Path | None = typer.Option(None, "--model", help=MODEL_HELP),
    data: Path = typer.Option(..., "--data", help="Labelled simulated sweep (.h5)."),
    out: Path = typer.Option(..., "--out", "-o", help="Output folder."),
) -> None:
    """RMSE and relative errors per target, parity plots, metrics as JSON and CSV."""
    from stickslip.jobs.report import evaluate_model, write_evaluation

    m = _load_model(model)
    ds = _load_data(data)
    ev = evaluate_model(m, ds)
    write_evaluation(ev, out, {"model": str(model or "bundled"), "data": str(data),
                               "data_fingerprint": ds.fingerprint()})  # fmt: skip
    typer.echo(ev.summary())
    info(f"wrote metrics.json, metrics.csv, predictions.csv, parity.png in {out}")


@app.command("demo")
def demo_cmd(
    out: Path = typer.Option(Path("stickslip-demo"), "--out", "-o", help="Output folder."),
) -> None:
    """Run 'infer' with the bundled model on the bundled example traces."""
    from stickslip.jobs.workflow import demo_job

    failed = demo_job(out, echo=typer.echo, warn=error, note=info)
    raise typer.Exit(EXIT_FAILED_INPUT if failed else EXIT_OK)
