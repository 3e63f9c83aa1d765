"""Cached simulated sets and models shared by the training recipes and the benchmarks.

The seeds of the paper-preset sweeps behind the bundled models and the benchmarks are
named here once, so a new training set can be kept apart from them.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from stickslip.estimators.window.modelfile import TrainedModel, load_model, save_model
from stickslip.estimators.window.training import TrainConfig, spec_for_dataset, train_model
from stickslip.simulators import PRESETS, SweepConfig, run_sweep
from stickslip.simulators.sweep import partial_path
from stickslip.traces.dataset import DatasetError, load_dataset, read_attrs

PAPER_TRAIN_SEED = 0  # the bundled window model's training data (the line model's expert)
PAPER_HELDOUT_SEED = 1  # the bundled window model's recorded held-out set
LAB_MLP_SEED = 10  # the lab bench's MLPs trained on clean data
CLEAN_TEST_SEED = 4242  # the benchmarks' clean held-out traces
RESERVED_SEEDS = (PAPER_TRAIN_SEED, PAPER_HELDOUT_SEED, LAB_MLP_SEED, CLEAN_TEST_SEED)


def sweep_if_missing(
    path: str | os.PathLike, n: int, seed: int, physics: Any = "paper"
) -> Path:
    """Simulate a sweep of ``n`` trajectories into ``path`` unless it is already there.

    ``physics`` is a preset name or a :class:`~stickslip.simulators.PhysicalSettings`.
    An existing file is reused only if it was made with the same settings, size and seed.
    A ``.partial`` left by an interrupted run is resumed when it was started with the same
    settings (its finished trajectories are kept), and replaced otherwise.
    """
    preset = physics if isinstance(physics, str) else "custom"
    ph = PRESETS[physics] if isinstance(physics, str) else physics
    cfg = SweepConfig(physics=ph, n=n, seed=seed, preset=preset)
    path = Path(path)
    if path.exists() and read_attrs(path).get("config") == cfg.to_json():
        return path
    if partial_path(path).exists():
        try:
            return run_sweep(cfg, path, resume=True)
        except DatasetError:  # another run's leftover: a cache may replace it
            return run_sweep(cfg, path, overwrite=True)
    return run_sweep(cfg, path)


def clean_window_model(path: str | os.PathLike, train_path: str | os.PathLike, n: int,
                       seed: int, recipe: str = "pi", epochs: int = 50,
                       progress: bool = True) -> TrainedModel:  # fmt: skip
    """The paper's MLP for ``recipe`` (window 64, stride 64, train stride 16) trained on
    ``n`` clean paper-preset trajectories of ``seed``, without noise augmentation.

    The trajectories are simulated into ``train_path`` if missing (:func:`sweep_if_missing`);
    the model is cached in ``path`` and reused while its training data is the same.
    """
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
