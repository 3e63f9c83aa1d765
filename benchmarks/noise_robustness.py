"""Accuracy of a model on held-out simulated traces with white detector noise added.

Usage: python benchmarks/noise_robustness.py [--model PATH] [--n 800] [--seed 1]
       [--levels 0,0.05,0.1,0.2]
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import numpy as np

from stickslip.estimators.window.modelfile import load_model
from stickslip.jobs.report import evaluate_model
from stickslip.jobs.workflow import sweep_if_missing
from stickslip.traces.dataset import load_dataset

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--work", type=Path, default=ROOT / "build" / "default-model")
    parser.add_argument("--model", default=None)
    parser.add_argument("--n", type=int, default=800)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--levels", default="0,0.05,0.1,0.2")
    args = parser.parse_args()
    model = load_model(args.model)
    test = load_dataset(sweep_if_missing(args.work / "heldout.h5", args.n, args.seed))
    rng = np.random.default_rng(2)
    print(f"{'noise nN':>9}{'U0 RMSE':>9}{'rel med':>9}{'K RMSE':>9}{'rel med':>9}")
    for level in (float(v) for v in args.levels.split(",")):
        noisy = test.force_nN + level * rng.standard_normal(test.force_nN.shape)
        m = evaluate_model(model, replace(test, force_nN=noisy)).metrics
        u, k = m["U0_eV"], m["K_N_m"]
        print(f"{level:>9.3g}{u['rmse']:>9.4f}{u['rel_median_abs']:>9.2%}{k['rmse']:>9.3f}"
              f"{k['rel_median_abs']:>9.2%}")


if __name__ == "__main__":
    main()
