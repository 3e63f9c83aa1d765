"""What each domain-randomisation effect buys: leave-one-out on the lab bench.

Trains one-member line models (same data, seed and schedule) with the training
effects of ``line_training.TRAIN_EFFECTS``, with each effect removed in turn, and with
none at all (clean training), then scores them on the lab bench (1.5 <= eta <= 40).
Substrate augmentation and lattice/velocity randomisation are in the simulated set
itself and are not varied here. Each model is scored as a ``LineEstimator`` through
:mod:`stickslip.jobs.evaluate`.

Usage: python benchmarks/dr_ablation.py [--epochs 15] [--work build/line-train]
       [--bench build/lab-bench/bench_200.h5]
"""

from __future__ import annotations

import argparse
import platform
from pathlib import Path

import numpy as np

from stickslip.estimators.line.estimator import LineEstimator
from stickslip.estimators.line.training import TRAIN_EFFECTS, LineTrainConfig, train_line_ensemble
from stickslip.jobs.evaluate import evaluate_dataset
from stickslip.simulators.bench import BenchConfig, bench_if_missing, in_eta_window
from stickslip.simulators.randomised import RandomisedConfig, cached_randomised_set
from stickslip.traces.dataset import load_dataset

ROOT = Path(__file__).resolve().parents[1]
EFFECTS = ("white_nN", "pink_nN", "lowpass_px", "drift_nN", "softening")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--epochs", type=int, default=15)
    ap.add_argument("--work", type=Path, default=ROOT / "build" / "line-train")
    ap.add_argument("--bench", type=Path, default=ROOT / "build" / "lab-bench" / "bench_200.h5")
    args = ap.parse_args()
    print(f"machine: {platform.processor() or platform.machine()}, {platform.system()}, "
          f"python {platform.python_version()}")  # fmt: skip
    # the setup of the recorded ablation (docs/explanation/): seed-101 set with no lines
    # on the reference lattice, no pristine oversampling
    rcfg = RandomisedConfig(seed=101, reference_fraction=0.0)
    data = cached_randomised_set(rcfg, args.work)
    bench = load_dataset(bench_if_missing(BenchConfig(), args.bench))
    ok = np.flatnonzero(in_eta_window(bench.params["eta"]))
    variants = {"all effects": (TRAIN_EFFECTS, 0.2), "none (clean training)": (TRAIN_EFFECTS, 1.0)}
    for name in EFFECTS:
        variants[f"all but {name}"] = (TRAIN_EFFECTS.replace(**{name: (0.0, 0.0)}), 0.2)
    variants["all but 16-bit"] = (TRAIN_EFFECTS.replace(bits=0), 0.2)
    print(f"{'training effects':<24}{'<F> RMSE nN':>13}{'U0 rel RMSE':>13}{'K rel RMSE':>12}")
    for name, (effects, clean) in variants.items():
        cfg = LineTrainConfig(members=1, epochs=args.epochs, seed=rcfg.seed, effects=effects,
                              clean_fraction=clean, pristine_fraction=0.0)  # fmt: skip
        ens, _ = train_line_ensemble(data.force_nN.astype(float), data.x_nm, data.params, cfg,
                                     progress=False)  # fmt: skip
        m = evaluate_dataset(LineEstimator(ens, name), bench, ok, name="bench").metrics
        print(f"{name:<24}{m['F_mean_nN']['rmse']:>13.4f}{m['U0_eV']['rel_rmse']:>13.2%}"
              f"{m['K_N_m']['rel_rmse']:>12.2%}", flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
