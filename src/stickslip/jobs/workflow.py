"""The jobs behind the ``train``, ``infer`` and ``demo`` commands (no CLI parsing here)."""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from stickslip.diagnostics.loads import write_load_report
from stickslip.estimators.window.modelfile import TrainedModel, save_model
from stickslip.jobs.report import Evaluation, evaluate_model
from stickslip.jobs.window_results import format_rows, run_inference, write_panels, write_results
from stickslip.traces.dataset import Dataset

Echo = Callable[[str], None]
EXAMPLES = "examples"
MANIFEST = "manifest.json"

# Seeds of the paper-preset sweeps (:func:`sweep_if_missing`) behind the bundled models and
# the benchmarks, in one place so that a new training set can be kept apart from them.
PAPER_TRAIN_SEED = 0  # the bundled window model's training data (the line model's expert)
PAPER_HELDOUT_SEED = 1  # the bundled window model's recorded held-out set
LAB_MLP_SEED = 10  # the lab bench's MLPs trained on clean data
CLEAN_TEST_SEED = 4242  # the benchmarks' clean held-out traces
RESERVED_SEEDS = (PAPER_TRAIN_SEED, PAPER_HELDOUT_SEED, LAB_MLP_SEED, CLEAN_TEST_SEED)


def validate_and_save(
    model: TrainedModel, data: Dataset, val_idx: np.ndarray, out: str | os.PathLike
) -> Evaluation:
    """Evaluate on the validation trajectories, record the metrics in the model, save it."""
    ev = evaluate_model(model, data, val_idx)
    model.metrics["validation"] = ev.metrics
    save_model(model, out)
    return ev


def infer_job(
    model: TrainedModel,
    paths: Sequence[str | os.PathLike],
    out: str | os.PathLike,
    plots: str | os.PathLike | None = None,
    *,
    lattice_nm: float | None = None,
    velocity_nm_per_s: float | None = None,
    temperature_K: float | None = None,
    reader_options: dict[str, Any] | None = None,
    classical: bool = True,
    echo: Echo = print,
    warn: Echo = print,
    note: Echo = print,
    traces: list[Any] | None = None,
    truth: dict[str, dict] | None = None,
    check: bool = False,
) -> int:
    """Read traces, estimate, write the table (and panels); returns the failure count.

    ``model`` is a window model or a line model (:func:`load_any_model`); ``check`` runs
    the posterior predictive check (line models). Every unreadable or too-short trace is
    reported through ``warn`` (one line each) and the others are processed. No
    processable trace at all counts as a failure.
    """
    from stickslip.estimators.line.ensemble import LineEnsemble
    from stickslip.traces.readers import collect_traces

    errors: list[Any] = []
    if traces is None:
        traces, errors = collect_traces(list(paths), **(reader_options or {}))
    for e in errors:
        warn(str(e))
    if isinstance(model, LineEnsemble):
        from stickslip.jobs.line_results import run_line_inference, write_line_panels

        res = run_line_inference(model, traces, lattice_nm, velocity_nm_per_s, temperature_K,
                                 classical=classical, check=check)  # fmt: skip
        panels = write_line_panels
    else:
        res = run_inference(model, traces, lattice_nm, velocity_nm_per_s, temperature_K,
                            classical=classical, keep_windows=plots is not None)  # fmt: skip
        panels = write_panels
    for name, reason in res.failures:
        warn(f"{name}: {reason}")
    for n in res.notes:
        note(f"note: {n}")
    if res.rows:
        write_results(res.rows, out)
        echo(format_rows(res.rows, truth))
        note(f"wrote {out} ({len(res.rows)} traces)")
        by_load = write_load_report(res.rows, out, "network estimates versus load")
        if by_load:
            note(f"wrote {by_load[0]} and {by_load[1]} (per load group)")
        if plots is not None:
            panels(res, traces, plots)
            note(f"wrote {len(res.rows)} panels in {plots}")
        return len(errors) + len(res.failures)
    warn("no trace could be processed; nothing written")
    return len(errors) + len(res.failures) + 1


def examples_dir():
    """The bundled example traces (a Traversable inside the installed package)."""
    from importlib.resources import files

    return files("stickslip").joinpath("resources", EXAMPLES)


def load_examples() -> tuple[list[Any], dict[str, dict]]:
    """Bundled example traces (with lattice/velocity in ``meta``) and their true values."""
    from stickslip.traces.formats.text import read_text

    root = examples_dir()
    manifest = json.loads(root.joinpath(MANIFEST).read_text())
    traces, truth = [], {}
    from importlib.resources import as_file

    for item in manifest:
        with as_file(root.joinpath(item["file"])) as p:
            (t,) = read_text(Path(p))
        t.name = Path(item["file"]).stem
        t.meta.update({k: item[k] for k in ("lattice_nm", "velocity_nm_per_s") if k in item})
        traces.append(t)
        truth[t.name] = item
    return traces, truth


def demo_job(out: str | os.PathLike, echo: Echo = print, warn: Echo = print,
             note: Echo = print) -> int:  # fmt: skip
    """The main job on the embedded defaults: bundled model, bundled example traces."""
    from stickslip.estimators.line.modelfile import load_any_model

    model = load_any_model(None)
    traces, truth = load_examples()
    out = Path(out)
    kind = (f"{model.features.recipe} recipe, window {model.features.window} px"
            if isinstance(model, TrainedModel)
            else f"whole-line CNN ensemble of {len(model.members)} with 68/95 % intervals")
    note(f"bundled model: {kind}; {len(traces)} example traces (true values in the last "
         "columns)")  # fmt: skip
    return infer_job(model, [], out / "results.csv", out / "plots", traces=traces, truth=truth,
                     echo=echo, warn=warn, note=note, check=True)  # fmt: skip


def sweep_if_missing(
    path: str | os.PathLike, n: int, seed: int, physics: Any = "paper"
) -> Path:
    """Simulate a sweep of ``n`` trajectories into ``path`` unless it is already there.

    ``physics`` is a preset name or a :class:`~stickslip.simulators.PhysicalSettings`.
    An existing file is reused only if it was made with the same settings, size and seed.
    """
    from stickslip.simulators import PRESETS, SweepConfig, run_sweep
    from stickslip.traces.dataset import read_attrs

    preset = physics if isinstance(physics, str) else "custom"
    ph = PRESETS[physics] if isinstance(physics, str) else physics
    cfg = SweepConfig(physics=ph, n=n, seed=seed, preset=preset)
    path = Path(path)
    if path.exists() and read_attrs(path).get("config") == cfg.to_json():
        return path
    return run_sweep(cfg, path)


def clean_window_model(path: str | os.PathLike, train_path: str | os.PathLike, n: int,
                       seed: int, recipe: str = "pi", epochs: int = 50,
                       progress: bool = True) -> TrainedModel:  # fmt: skip
    """The paper's MLP for ``recipe`` (window 64, stride 64, train stride 16) trained on
    ``n`` clean paper-preset trajectories of ``seed``, without noise augmentation.

    The trajectories are simulated into ``train_path`` if missing (:func:`sweep_if_missing`);
    the model is cached in ``path`` and reused while its training data is the same.
    """
    from stickslip.estimators.window.modelfile import load_model
    from stickslip.estimators.window.training import TrainConfig, spec_for_dataset, train_model
    from stickslip.traces.dataset import load_dataset

    train = load_dataset(sweep_if_missing(train_path, n, seed))
    path = Path(path)
    if path.exists():
        model = load_model(path)
        if model.dataset_fingerprint == train.fingerprint():
            return model
    spec = spec_for_dataset(train, recipe, 64, 64, 16)
    model, _, _ = train_model(train, spec, TrainConfig(epochs=epochs, seed=0), progress=progress)
    save_model(model, path)
    return model
