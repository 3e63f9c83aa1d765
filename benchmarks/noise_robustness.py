"""Accuracy of an estimator on held-out simulated traces with white detector noise added.

The held-out set is the bundled window model's (paper preset, 800 trajectories, seed 1,
cached in --work). ``--model`` takes anything ``load_estimator`` does: ``window`` (the
default, the bundled paper MLP: docs/explanation/learned-model.md's table), ``default`` (the bundled
line model), ``classical`` or a model file. Scored through :mod:`stickslip.jobs.evaluate`.

Usage: python benchmarks/noise_robustness.py [--model window] [--n 800] [--seed 1]
       [--levels 0,0.05,0.1,0.2]
"""

from __future__ import annotations

import argparse
import platform
from dataclasses import replace
from pathlib import Path

import numpy as np

from stickslip.estimators.load import load_estimator
from stickslip.jobs.cache import PAPER_HELDOUT_SEED, sweep_if_missing
from stickslip.jobs.evaluate import evaluate_dataset
from stickslip.traces.dataset import load_dataset

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--work", type=Path, default=ROOT / "build" / "default-model")
    parser.add_argument("--model", default="window",
                        help="window (bundled paper MLP), default (bundled line model), "
                        "classical, or a model file")  # fmt: skip
    parser.add_argument("--n", type=int, default=800)
    parser.add_argument("--seed", type=int, default=PAPER_HELDOUT_SEED)
    parser.add_argument("--levels", default="0,0.05,0.1,0.2")
    args = parser.parse_args()
    print(f"machine: {platform.processor() or platform.machine()}, {platform.system()}, "
          f"python {platform.python_version()}")  # fmt: skip
    estimator = load_estimator(args.model)
    print(f"estimator: {estimator.describe()}")
    args.work.mkdir(parents=True, exist_ok=True)
    test = load_dataset(sweep_if_missing(args.work / "heldout.h5", args.n, args.seed))
    rng = np.random.default_rng(2)
    print(f"{'noise nN':>9}{'answered':>9}{'U0 RMSE':>9}{'rel med':>9}{'K RMSE':>9}{'rel med':>9}")
    for level in (float(v) for v in args.levels.split(",")):
        noisy = test.force_nN + level * rng.standard_normal(test.force_nN.shape)
        m = evaluate_dataset(estimator, replace(test, force_nN=noisy)).metrics
        u, k = m["U0_eV"], m["K_N_m"]
        print(f"{level:>9.3g}{u['answered']:>9}{u['rmse']:>9.4f}{u['median_rel']:>9.2%}"
              f"{k['rmse']:>9.3f}{k['median_rel']:>9.2%}")


if __name__ == "__main__":
    main()
