"""The reference paper's MD->MD row, for both input recipes.

Simulates a fresh paper-preset training set (1600 trajectories) and a second,
independently seeded test set, trains the paper's MLP on the ``raw`` and the ``pi``
recipe (80/20 split by trajectory, 50 epochs), and evaluates both on the test set.
Prints RMSE and relative errors per target beside the paper's row and the target
(half the paper's RMSE), and writes JSON/CSV/parity plots per recipe.

Usage: python benchmarks/paper_table.py [--work build/paper-table] [--train-seed 10]
       [--test-seed 11] [--n-test 800] [--epochs 50]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from stickslip.diagnostics.metrics import PAPER_MD_MD_RMSE, TARGET_RMSE
from stickslip.estimators.window.training import TrainConfig, spec_for_dataset, train_model
from stickslip.jobs.report import evaluate_model, write_evaluation
from stickslip.jobs.workflow import sweep_if_missing
from stickslip.traces.dataset import load_dataset

ROOT = Path(__file__).resolve().parents[1]
WINDOW, STRIDE, TRAIN_STRIDE = 64, 64, 16
SHOW = (("F_mean_net", "F_mean_nN"), ("F_mean_nN", "F_mean_nN"), ("U0_eV", "U0_eV"),
        ("K_N_m", "K_N_m"), ("eta", None))  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--work", type=Path, default=ROOT / "build" / "paper-table")
    parser.add_argument("--train-seed", type=int, default=10)
    parser.add_argument("--test-seed", type=int, default=11)
    parser.add_argument("--n-train", type=int, default=1600)
    parser.add_argument("--n-test", type=int, default=800)
    parser.add_argument("--epochs", type=int, default=50)
    args = parser.parse_args()
    train = load_dataset(sweep_if_missing(args.work / "train.h5", args.n_train, args.train_seed))
    test = load_dataset(sweep_if_missing(args.work / "test.h5", args.n_test, args.test_seed))
    summary = {}
    print(f"{'recipe':<7}{'target':<12}{'RMSE':>9}{'paper':>8}{'goal':>8}{'rel mean':>10}"
          f"{'rel med':>9}{'train s':>9}")  # fmt: skip
    for recipe in ("raw", "pi"):
        spec = spec_for_dataset(train, recipe, WINDOW, STRIDE, TRAIN_STRIDE)
        model, hist, _ = train_model(train, spec, TrainConfig(epochs=args.epochs), progress=False)
        ev = evaluate_model(model, test)
        write_evaluation(ev, args.work / recipe)
        summary[recipe] = {"metrics": ev.metrics, "train_seconds": hist.seconds}
        for key, ref in SHOW:
            m = ev.metrics[key]
            paper = PAPER_MD_MD_RMSE.get(ref, float("nan")) if ref else float("nan")
            goal = TARGET_RMSE.get(ref, float("nan")) if ref else float("nan")
            print(f"{recipe:<7}{key:<12}{m['rmse']:>9.4f}{paper:>8.2f}{goal:>8.2f}"
                  f"{m['rel_mean_abs']:>10.2%}{m['rel_median_abs']:>9.2%}{hist.seconds:>9.0f}")
    (args.work / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    print("F_mean_nN = the trace's own mean (exact on clean traces); F_mean_net = the network's")


if __name__ == "__main__":
    main()
