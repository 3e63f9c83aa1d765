"""Commands ``infer``, ``label``, ``evaluate``, ``train`` and ``demo``: argument parsing only.

Every command runs an estimator through the one interface
(:mod:`stickslip.estimators`) via the jobs of :mod:`stickslip.jobs`.
"""

from __future__ import annotations

import sys
from pathlib import Path

import typer

from stickslip.cli.app import app
from stickslip.cli.common import (
    CALIBRATION_HELP,
    EXIT_FAILED_INPUT,
    EXIT_OK,
    LOADS_HELP,
    LPL_HELP,
    check_output_file,
    check_table_path,
    echo,
    error,
    info,
    parse_loads_arg,
    progress_bar,
    reading_options,
    show_progress,
    usage_error,
)
from stickslip.conditions import GRAPHITE, check_values
from stickslip.estimators.base import Estimator
from stickslip.estimators.line.ensemble import ANY_CONTACT
from stickslip.estimators.line.streaming import StreamSettings
from stickslip.estimators.line.training import LineTrainConfig, family_settings
from stickslip.estimators.load import load_estimator, state_contact, state_zero_offset
from stickslip.estimators.table import has_estimate
from stickslip.estimators.window.features import FeatureError
from stickslip.estimators.window.modelfile import ModelFileError
from stickslip.estimators.window.training import TrainConfig
from stickslip.jobs import evaluate as ev
from stickslip.jobs import infer as inf
from stickslip.jobs import train as tr
from stickslip.jobs.demo import load_examples

MODEL_HELP = ("Estimator: a model file from 'stickslip train' (any kind), 'classical', or "
              "'window' (the bundled paper MLP); default: the bundled whole-line model.")
OUT_HELP = "Result table; the format follows the extension: .csv, .json or .parquet."
LATTICE_HELP = "Lattice spacing a in nm (wins over the file's; default: the estimator's, 0.246)."
VELOCITY_HELP = ("Scan velocity in nm/s (wins over the file's; default: the estimator's, 60); "
                 "also turns a recording's time axis into positions, x = v t.")
SPLIT_HELP = ("Where the verdict finds a trace changing part-way (a tip change, "
              "change_nm), estimate each part on its own too (one more row each).")
REPORT_HELP = "Also write one self-contained HTML report of the run (opens offline)."
CONTACT_HELP = ("The contact, if you know it: 'any' (default: the calibration covers "
                "multi-asperity tips and modulated or defective substrates) or 'ideal' (one "
                "asperity on a crystal without modulation or defects along the line: "
                "narrower U0 intervals). The line model only.")
TEMPERATURE_HELP = "Temperature in K (wins over the file's; default: the estimator's, 296)."
ZERO_OFFSET_HELP = ("State that the lateral force's zero carries no offset (taken from a "
                    "friction loop or a calibration): a lone line's <F> interval is then the "
                    "model's own, without the offset one line cannot tell from friction. The "
                    "line model only; trace/retrace pairs cancel the offset anyway.")


def _estimator(spec: str | None, contact: str = ANY_CONTACT,
               zero_offset: bool = False) -> Estimator:  # fmt: skip
    try:
        return state_zero_offset(state_contact(load_estimator(spec), contact), zero_offset)
    except (ModelFileError, ValueError) as e:
        usage_error(str(e))


def _check_conditions(lattice: float | None, velocity: float | None,
                      temperature: float | None) -> None:  # fmt: skip
    why = check_values(lattice, velocity, temperature)
    if why:
        usage_error(why)


def run_estimation(
    estimator: Estimator, traces: list[str], out: Path, *, lattice: float | None,
    velocity: float | None, temperature: float | None, calibration: float | None,
    lines_per_load: int | None, loads: str | None, plots: Path | None, classical: bool,
    check: bool, truth: dict | None = None, examples: bool = False, report: Path | None = None,
    split_changes: bool = False,
) -> int:  # fmt: skip
    """The shared body of ``infer``, ``label`` and ``demo``; returns the exit code."""
    check_table_path("--out", out)
    if report is not None:
        if report.suffix.lower() not in (".html", ".htm"):
            usage_error(f"--report {report}: the report is an .html file")
        check_output_file("--report", report)
    if plots is not None and plots.exists() and not plots.is_dir():
        usage_error(f"--plots {plots} is a file; it names a folder for the panels")
    _check_conditions(lattice, velocity, temperature)
    opts = reading_options(calibration, lines_per_load, parse_loads_arg(loads),
                           velocity_nm_per_s=velocity)  # fmt: skip
    if examples:
        found, errors = load_examples()[0], []
    else:
        with progress_bar(inf.count_inputs(traces), "read", "file") as bar:
            found, errors = inf.read_inputs(traces, opts, progress=bar)
    info(f"estimator: {estimator.describe()}; {len(found)} trace(s) read")
    if found and not inf.kernels_cached(check):
        info("first run after installing: compiling the numerical kernels, once (under a "
             "minute; later runs start in seconds)")  # fmt: skip
        inf.compile_kernels(check)
    with progress_bar(len(found) if check else 0, "check") as bar:
        result = inf.infer(estimator, found, errors, lattice_nm=lattice,
                           velocity_nm_per_s=velocity, temperature_K=temperature,
                           classical=classical, check=check, split_changes=split_changes,
                           progress=bar)  # fmt: skip
    for line in result.error_lines():
        error(line)
    for note in result.table.notes:
        info(f"note: {note}")
    ok = result.table.ok()
    if not result.table.rows:
        error("no input could be read; nothing written")
        return EXIT_FAILED_INPUT
    try:
        written = inf.write_outputs(result, out, estimator.name)
    except OSError as e:
        usage_error(f"cannot write {out} ({e.strerror or e})")
    if ok:
        echo(inf.summary_text(result.table, truth))
        if result.groups:
            echo(inf.groups_text(result))
    if plots is not None:
        with progress_bar(inf.count_panels(result), "panels") as bar:
            panels = inf.write_panels(result, estimator, plots, progress=bar)
        info(f"wrote {len(panels)} panels in {plots}")
    if report is not None:
        written.append(inf.write_run_report(result, estimator, report, traces, sys.argv))
    for line in result.domain_lines():
        info(f"out of domain: {line}")
    n_flag = len(result.table.rows) - len(ok) - len(result.refused)
    n_out = len(result.out_of_domain())
    out_note = f" ({n_out} out of domain: intervals widened)" if n_out else ""
    info(f"{len(ok)} ok{out_note}, {n_flag} flagged, {len(result.refused)} without an "
         "estimate -> " + ", ".join(str(p) for p in written))  # fmt: skip
    if not ok and not any(has_estimate(r) for r in result.table.rows):
        return EXIT_FAILED_INPUT
    return EXIT_FAILED_INPUT if result.refused else EXIT_OK


@app.command("infer")
def infer_cmd(
    traces: list[str] = typer.Argument(..., help="Trace files, vendor files or folders."),
    out: Path = typer.Option(..., "--out", "-o", help=OUT_HELP),
    model: str | None = typer.Option(None, "--model", help=MODEL_HELP),
    lattice: float | None = typer.Option(None, "--lattice", help=LATTICE_HELP),
    velocity: float | None = typer.Option(None, "--velocity", help=VELOCITY_HELP),
    temperature: float | None = typer.Option(None, "--temperature", help=TEMPERATURE_HELP),
    calibration: float | None = typer.Option(None, "--calibration", help=CALIBRATION_HELP),
    lines_per_load: int | None = typer.Option(None, "--lines-per-load", help=LPL_HELP),
    loads: str | None = typer.Option(None, "--loads", help=LOADS_HELP),
    plots: Path | None = typer.Option(None, "--plots", help="Folder for per-trace panels."),
    classical: bool = typer.Option(
        True, "--classical/--no-classical",
        help="Add the classical estimator's columns (classical_*) beside a learned model's "
        "(moot with --model classical)."),
    check: bool = typer.Option(
        False, "--check", help="Re-simulate each trace at its estimate and report a goodness "
        "of fit (gof, ppc_flag); with --plots the overlay is drawn."),
    report: Path | None = typer.Option(None, "--report", help=REPORT_HELP),
    split_changes: bool = typer.Option(False, "--split-changes", help=SPLIT_HELP),
    contact: str = typer.Option(ANY_CONTACT, "--contact", help=CONTACT_HELP),
    zero_offset: bool = typer.Option(False, "--zero-offset", help=ZERO_OFFSET_HELP),
) -> None:
    """Estimate <F>, U0, K and eta of every trace, with any estimator.

    One row per trace (and per unreadable input, with its reason): the estimates,
    *_std, the 68 % / 95 % intervals where the estimator gives them, quality, the
    conditions used and where each came from (flag, file, model), provenance.
    Unreadable or refused inputs are reported one line each (one line per file and
    reason for map lines); the others are processed (exit code 1).
    """
    code = run_estimation(
        _estimator(model, contact, zero_offset), traces, out, lattice=lattice,
        velocity=velocity, temperature=temperature, calibration=calibration,
        lines_per_load=lines_per_load, loads=loads, plots=plots, classical=classical,
        check=check, report=report,
        split_changes=split_changes,
    )  # fmt: skip
    raise typer.Exit(code)


@app.command("label")
def label_cmd(
    traces: list[str] = typer.Argument(..., help="Trace files, vendor files or folders."),
    out: Path = typer.Option(..., "--out", "-o", help=OUT_HELP),
    lattice: float | None = typer.Option(None, "--lattice", help=LATTICE_HELP),
    velocity: float | None = typer.Option(None, "--velocity", help=VELOCITY_HELP),
    temperature: float | None = typer.Option(None, "--temperature", help=TEMPERATURE_HELP),
    plots: Path | None = typer.Option(
        None, "--plots", help="Folder for one diagnostic plot per trace (PNG)."),
    calibration: float | None = typer.Option(None, "--calibration", help=CALIBRATION_HELP),
    lines_per_load: int | None = typer.Option(None, "--lines-per-load", help=LPL_HELP),
    loads: str | None = typer.Option(None, "--loads", help=LOADS_HELP),
    report: Path | None = typer.Option(None, "--report", help=REPORT_HELP),
    split_changes: bool = typer.Option(False, "--split-changes", help=SPLIT_HELP),
) -> None:
    """Label traces with the classical stick-slip estimator ('infer --model classical').

    Finds the slips, fits the stick slopes and peak forces, and inverts the
    Prandtl-Tomlinson relations (F_max = pi U0/a, stick slope K eta c/(1 + eta c)),
    correcting the peak for thermal activation at the trace's temperature, velocity and
    lattice. The columns are those of 'infer', plus regime, k_exp_N_m, F_peak_nN,
    n_slips; quality is ok or the reason the values are missing or doubtful.
    """
    code = run_estimation(
        load_estimator("classical"), traces, out, lattice=lattice, velocity=velocity,
        temperature=temperature, calibration=calibration, lines_per_load=lines_per_load,
        loads=loads, plots=plots, classical=False, check=False, report=report,
        split_changes=split_changes,
    )  # fmt: skip
    raise typer.Exit(code)


@app.command("evaluate")
def evaluate_cmd(
    traces: list[str] = typer.Argument(None, help="Labelled trace files or folders, or a "
                                       "simulated sweep (.h5, .zarr) whose truths are inside."),
    out: Path = typer.Option(..., "--out", "-o", help="Output folder."),
    model: str | None = typer.Option(None, "--model", help=MODEL_HELP),
    data: list[str] = typer.Option(None, "--data", help="A simulated sweep (alias)."),
    truth: Path | None = typer.Option(
        None, "--truth", help="Truth table (columns trace,U0_eV,K_N_m,F_mean_nN[,eta]); rows "
        "match result rows by trace name."),
    lattice: float | None = typer.Option(None, "--lattice", help=LATTICE_HELP),
    velocity: float | None = typer.Option(None, "--velocity", help=VELOCITY_HELP),
    temperature: float | None = typer.Option(None, "--temperature", help=TEMPERATURE_HELP),
    calibration: float | None = typer.Option(None, "--calibration", help=CALIBRATION_HELP),
    contact: str = typer.Option(ANY_CONTACT, "--contact", help=CONTACT_HELP),
    zero_offset: bool = typer.Option(False, "--zero-offset", help=ZERO_OFFSET_HELP),
) -> None:
    """Score any estimator on any labelled set: metrics.json, predictions, plots.

    metrics.json holds one object per target (F_mean_nN, U0_eV, K_N_m, eta) with rmse,
    rel_rmse, median_rel, n, answered and, for estimators with intervals, coverage68 and
    coverage95; 'info' holds the estimator, data and conditions; 'domain' how many rows
    the in/out-of-domain verdict put in and out of domain.
    """
    inputs = list(traces or []) + list(data or [])
    if not inputs:
        usage_error("give labelled traces or a sweep (TRACES... or --data SWEEP.h5)")
    if out.exists() and not out.is_dir():
        usage_error(f"{out}: exists and is not a folder")
    _check_conditions(lattice, velocity, temperature)
    est = _estimator(model, contact, zero_offset)
    with progress_bar(inf.count_inputs(inputs), "read", "file") as bar:
        opts = reading_options(calibration, None, None, velocity_nm_per_s=velocity)
        found, errors = inf.read_inputs(inputs, opts, progress=bar)
    result = inf.infer(est, found, errors, lattice_nm=lattice, velocity_nm_per_s=velocity,
                       temperature_K=temperature, classical=False)  # fmt: skip
    for line in result.error_lines():
        error(line)
    try:
        labels = (ev.truth_from_table(truth) if truth is not None
                  else ev.truth_from_traces(result.table, result.traces))  # fmt: skip
    except ev.TruthError as e:
        usage_error(str(e))
    if not labels:
        usage_error("no truths: give --truth TABLE.csv for trace files")
    evaluation = ev.evaluate(result.table, labels)
    for p in evaluation.problems:
        error(p)
    info_doc = {"estimator": est.name, "description": est.describe(), "inputs": inputs,
                "truth": str(truth) if truth else "stored with the traces",
                "left_out": len(evaluation.problems)}  # fmt: skip
    paths = ev.write_evaluation(evaluation, out, info_doc)
    echo(evaluation.summary())
    info(f"wrote {', '.join(p.name for p in paths)} in {out}")
    bad = errors or result.refused or evaluation.problems
    raise typer.Exit(EXIT_FAILED_INPUT if bad else EXIT_OK)


@app.command("train")
def train_cmd(
    out: Path = typer.Option(..., "--out", "-o", help="Model file to write (.pt)."),
    kind: str = typer.Option("line", "--kind", help="line (the default model's kind) or "
                             "window (the reference paper's MLP)."),
    data: list[str] = typer.Option(None, "--data", help="Training data: a sweep (.h5, .zarr), "
                                   "or trace files/folders with --labels. Repeatable."),
    labels: Path | None = typer.Option(None, "--labels", help="Label table for trace files "
                                       "(columns trace,U0_eV,K_N_m,F_mean_nN)."),
    mix: list[str] = typer.Option(None, "--mix", help="Labelled real traces added to simulated "
                                  "training (with --mix-labels, --mix-fraction). Repeatable."),
    mix_labels: Path | None = typer.Option(None, "--mix-labels", help="Label table of --mix."),
    mix_fraction: float = typer.Option(0.01, "--mix-fraction", help="Fraction of training "
                                       "lines that are real (the paper's 1 %: 0.01)."),
    recipe: str | None = typer.Option(None, "--recipe", help="'bundled': simulate (cached in "
                                      "--work) and train on the bundled line model's data."),
    work: Path = typer.Option(Path("build/line-train"), "--work", help="Cache folder of "
                              "--recipe bundled and of the clean expert."),
    features: str = typer.Option("pi", "--features", help="Window kind: raw or pi."),
    epochs: int | None = typer.Option(None, "--epochs", help="Epochs (line 45, window 50)."),
    members: int = typer.Option(3, "--members", help="Line kind: ensemble members."),
    expert: str = typer.Option("none", "--expert", help="Line kind: window model read as "
                               "expert input: none, bundled, clean (bundled recipe), or a file."),
    batch_size: int | None = typer.Option(None, "--batch-size", help="Batch size."),
    lr: float | None = typer.Option(None, "--lr", help="Adam learning rate."),
    window: int = typer.Option(64, "--window", help="Window kind: pixels per window p."),
    train_stride: int = typer.Option(16, "--train-stride", help="Window kind: training stride."),
    noise: float = typer.Option(0.0, "--noise", help="Window kind: white-noise augmentation "
                                "up to NOISE nN (0: the paper's clean training)."),
    families: float = typer.Option(0.0, "--families", help="Line kind: fraction of the "
                                   "non-pristine training lines given a draw of the effect "
                                   "families (the broad nuisance prior; 0: none)."),
    coarse: float | None = typer.Option(None, "--coarse", help="Line kind: fraction of the "
                                        "training lines re-pixelated 1-4x coarser, as larger "
                                        "pixels record them (default: the bundled recipe's "
                                        "with --recipe bundled, else 0)."),
    workers: int = typer.Option(StreamSettings.num_workers, "--workers", help="Line kind: "
                                "loader processes that read and corrupt the batches "
                                "(0: in the training process)."),
    shuffle_rows: int = typer.Option(StreamSettings.shuffle_rows, "--shuffle-rows",
                                     help="Line kind: rows in each loader's shuffle buffer."),
    seed: int = typer.Option(0, "--seed", help="Seed of the split and the optimiser."),
) -> None:
    """Train an estimator: the whole-line ensemble (default) or the paper's window MLP.

    Reproduce the bundled line model with
    'stickslip train --kind line --recipe bundled --expert clean --families 0.5 --seed 102
    --out M.pt', then 'python benchmarks/families.py --line-model M.pt --write M2.pt'
    (its calibration on the effect families).
    """
    if kind not in tr.KINDS:
        usage_error(f"--kind must be one of {', '.join(tr.KINDS)} (got '{kind}')")
    if features not in ("raw", "pi"):
        usage_error(f"--features must be raw or pi (got '{features}')")
    if (epochs is not None and epochs < 1) or (lr is not None and not lr > 0) or noise < 0:
        usage_error("--epochs and --lr must be positive, --noise >= 0")
    if (not 0.0 <= families <= 1.0 or not 0.0 <= (coarse or 0.0) <= 1.0 or workers < 0
            or shuffle_rows < 1):  # fmt: skip
        usage_error("--families and --coarse must be in [0, 1], --workers >= 0, "
                    "--shuffle-rows >= 1")
    check_output_file("--out", out)
    try:
        if recipe == "bundled":
            training = tr.bundled_line_data(work, progress=show_progress())
        elif recipe is not None:
            usage_error(f"--recipe must be 'bundled' (got '{recipe}')")
        else:
            training = tr.read_training_data(data or [], labels, GRAPHITE, echo=info)
        if mix:
            if mix_labels is None:
                usage_error("--mix needs --mix-labels TABLE.csv")
            real = tr.read_training_data(mix, mix_labels, GRAPHITE, echo=info).data
            training = tr.mix_in(training, real, mix_fraction, seed)
    except (tr.TrainingDataError, ev.TruthError) as e:
        usage_error(str(e))
    info(f"training a {kind} model on {training.data.n} lines")
    try:
        if kind == "line":
            if coarse is None:
                coarse = tr.BundledRecipe().coarse_fraction if recipe == "bundled" else 0.0
            cfg = LineTrainConfig(members=members, seed=seed, coarse_fraction=coarse,
                                  **family_settings(families),
                                  **{k: v for k, v in (("epochs", epochs), ("lr", lr),
                                                       ("batch_size", batch_size))
                                     if v is not None})  # fmt: skip
            exp = tr.expert_model(expert, work)
            report = tr.train_line(training, out, cfg, exp, expert, progress=show_progress(),
                                   stream=StreamSettings(workers, shuffle_rows))
            info(tr.line_validation(report))
        else:
            cfg_w = TrainConfig(seed=seed, noise_nN=noise,
                                **{k: v for k, v in (("epochs", epochs), ("lr", lr),
                                                     ("batch_size", batch_size))
                                   if v is not None})  # fmt: skip
            model, _, _ = tr.train_window(training, out, features, cfg_w, window, None,
                                          train_stride, progress=show_progress())  # fmt: skip
            info(tr.window_validation(model))
    except (FeatureError, ValueError, ModelFileError) as e:
        usage_error(str(e))
    info(f"wrote {out}")


@app.command("demo")
def demo_cmd(
    out: Path = typer.Option(Path("stickslip-demo"), "--out", "-o", help="Output folder."),
) -> None:
    """'infer' with the bundled model on the bundled example traces (true values beside)."""
    if out.exists() and not out.is_dir():
        usage_error(f"--out {out} is a file; the demo writes a folder (results.csv, plots/)")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        usage_error(f"--out {out}: cannot make the folder ({e.strerror or e})")
    traces, truth = load_examples()
    info(f"bundled model on {len(traces)} example traces (true values in the last columns)")
    code = run_estimation(
        load_estimator(None), [], out / "results.csv", lattice=None, velocity=None,
        temperature=None, calibration=None, lines_per_load=None, loads=None,
        plots=out / "plots", classical=True, check=True, truth=truth, examples=True,
    )  # fmt: skip
    raise typer.Exit(code)
