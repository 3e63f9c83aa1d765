"""Train the bundled default model (reproducible from the seeds below).

1. Simulate the paper preset: 1600 training trajectories (seed 0) and an
   independently seeded held-out set (800 trajectories, seed 1).
2. Train the reference paper's MLP (256-128, Adam 5e-4, batch 300, 50 epochs) on the
   physics-informed (``pi``) recipe, 80/20 split by trajectory, with white-noise
   augmentation (sigma uniform in [0, 0.1] nN per window, redrawn every epoch): the
   clean-trained network's K error grows ~40x at 0.05 nN of detector noise.
3. Evaluate on the held-out set, clean and with 0.05 nN white noise added, record
   those metrics in the model file, and save it
   as src/stickslip/resources/default_model.pt (< 5 MB); loss curve and parity plots
   go to the work folder.

Usage: python scripts/train_default_model.py [--work build/default-model] [--epochs 50]
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import numpy as np

from stickslip.diagnostics.plots import loss_curve
from stickslip.estimators.window.modelfile import DEFAULT_MODEL_NAME, save_model
from stickslip.estimators.window.training import TrainConfig, spec_for_dataset, train_model
from stickslip.jobs.report import evaluate_model, write_evaluation
from stickslip.jobs.workflow import PAPER_HELDOUT_SEED, PAPER_TRAIN_SEED, sweep_if_missing
from stickslip.traces.dataset import load_dataset

ROOT = Path(__file__).resolve().parents[1]
RESOURCES = ROOT / "src" / "stickslip" / "resources"

# the defaults chosen by validation (docs/learning.md)
RECIPE, WINDOW, STRIDE, TRAIN_STRIDE, NOISE_NN = "pi", 64, 64, 16, 0.1
TRAIN_SEED, TEST_SEED, N_TRAIN, N_TEST = PAPER_TRAIN_SEED, PAPER_HELDOUT_SEED, 1600, 800
TEST_NOISE_NN, TEST_NOISE_SEED = 0.05, 2


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--work", type=Path, default=ROOT / "build" / "default-model")
    parser.add_argument("--epochs", type=int, default=50)
    parser.add_argument("--out", type=Path, default=RESOURCES / DEFAULT_MODEL_NAME)
    args = parser.parse_args()
    train_path = sweep_if_missing(args.work / "train.h5", N_TRAIN, TRAIN_SEED)
    test_path = sweep_if_missing(args.work / "heldout.h5", N_TEST, TEST_SEED)
    data = load_dataset(train_path)
    spec = spec_for_dataset(data, RECIPE, WINDOW, STRIDE, TRAIN_STRIDE)
    cfg = TrainConfig(epochs=args.epochs, seed=0, noise_nN=NOISE_NN)
    model, hist, val_idx = train_model(data, spec, cfg)
    val = evaluate_model(model, data, val_idx)
    test = load_dataset(test_path)
    held = evaluate_model(model, test)
    rng = np.random.default_rng(TEST_NOISE_SEED)
    noise = TEST_NOISE_NN * rng.standard_normal(test.force_nN.shape)
    noisy = evaluate_model(model, replace(test, force_nN=test.force_nN + noise))
    model.metrics = {
        "validation": val.metrics,
        "held_out": held.metrics,
        f"held_out_noise_{TEST_NOISE_NN}nN": noisy.metrics,
        "held_out_dataset": {"n": test.n, "seed": TEST_SEED, "fingerprint": test.fingerprint()},
    }
    save_model(model, args.out)
    loss_curve(hist.train_loss, hist.val_loss, args.work / "loss.png")
    write_evaluation(held, args.work / "heldout-eval")
    print(f"trained in {hist.seconds:.0f} s; held-out ({test.n} trajectories, seed {TEST_SEED}):")
    print(held.summary())
    print(f"same, with {TEST_NOISE_NN} nN white noise added:")
    print(noisy.summary())
    print(f"wrote {args.out} ({args.out.stat().st_size / 1e6:.2f} MB)")


if __name__ == "__main__":
    main()
