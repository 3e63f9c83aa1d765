"""Integrate over the contact's damping, or not: a factor held out of training (issue 41).

Damping and tip mass are on no trace's label, so the bundled line model integrates
over them: its training prior draws them (0.1-10x and 0.3-3x the preset,
:data:`stickslip.simulators.randomised.DYNAMICS_PRIOR`) and the members are not told.
This benchmark tests that choice the way the issue asks: two small line models are
trained on the bundled model's own training data (``build/line-train``, made by
``scripts/train_line_model.py``), one on every line and one without the lines of the
low-damping third (damping below 0.1 x 100^(1/3) = 0.46x the preset), with the same
settings otherwise (``--members``, ``--epochs``; each calibrated on its own validation
split, without the family calibration). Both are scored on the held-out damping set of
``benchmarks/acquisition.py`` (seed 41001, never used to fit anything), per level.

If integrating over damping works, the model that never saw low damping is worse there
(it has nothing to integrate over) and the one that saw it is not worse elsewhere.

Usage: python benchmarks/dynamics_ablation.py [--work build/line-train] [--members 1]
       [--epochs 12] [--threads 2]
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))

from acquisition import Draw, cached_set, score_set, set_specs  # noqa: E402

from stickslip.estimators.line.ensemble import LineSpec  # noqa: E402
from stickslip.estimators.line.estimator import LineEstimator  # noqa: E402
from stickslip.estimators.line.training import (  # noqa: E402
    TYPICAL_FRACTION,
    LineTrainConfig,
    family_settings,
    train_line_ensemble,
    training_effects,
)
from stickslip.jobs.train import BundledRecipe, bundled_line_data, expert_model  # noqa: E402
from stickslip.simulators.config import PhysicalSettings  # noqa: E402
from stickslip.traces.dataset import ArrayRows  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
#: the top of the low-damping third of the prior's log range (0.1-10x the preset)
LOW_THIRD = 0.1 * 100.0 ** (1.0 / 3.0)


def train_small(force: ArrayRows, x_nm: np.ndarray, params: dict, cfg: LineTrainConfig,
                expert) -> LineEstimator:  # fmt: skip
    """A line model trained and calibrated on these rows (spec as the bundled model's)."""
    spec = LineSpec.for_temperatures(params["temperature_K"])
    ens, _ = train_line_ensemble(force, x_nm, params, cfg, spec=spec, progress=False,
                                 expert=expert)  # fmt: skip
    return LineEstimator(ens, "ablation")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", type=Path, default=ROOT / "build" / "line-train")
    ap.add_argument("--cache", type=Path, default=ROOT / "build" / "acquisition")
    ap.add_argument("--members", type=int, default=1)
    ap.add_argument("--epochs", type=int, default=12)
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    print(f"machine: {platform.platform()}, {platform.machine()}, "
          f"python {platform.python_version()}, torch threads {args.threads}")  # fmt: skip
    recipe = BundledRecipe()
    data = bundled_line_data(args.work, recipe, progress=False)
    expert = expert_model("clean", args.work, recipe)
    d = data.data
    damping = np.asarray(d.params["damping_per_s"]) / PhysicalSettings().damping_per_s
    cfg = LineTrainConfig(members=args.members, epochs=args.epochs, seed=recipe.seeds[0],
                          effects=training_effects(TYPICAL_FRACTION), coarse_fraction=0.3,
                          **family_settings(0.5))  # fmt: skip
    damping_set = cached_set(set_specs()["damping"], Draw(), args.cache)
    arms = {"every line": np.ones(d.n, bool), "without damping < 0.46x": damping >= LOW_THIRD}
    results = {}
    for name, keep in arms.items():
        rows = np.flatnonzero(keep)
        force = ArrayRows(d.force_nN.take(rows) if hasattr(d.force_nN, "take")
                          else np.asarray(d.force_nN)[rows])  # fmt: skip
        params = {k: np.asarray(v)[rows] for k, v in d.params.items()}
        t0 = time.perf_counter()
        est = train_small(force, d.x_nm, params, cfg, expert)
        print(f"\n{name}: {rows.size} training lines, trained in "
              f"{time.perf_counter() - t0:.0f} s")  # fmt: skip
        groups, _ = score_set(damping_set, est)
        results[name] = groups
        print(f"  {'level':16s} {'U0 rRMSE':>9s} {'U0 bias':>8s} {'U0 cov95':>9s} "
              f"{'K rRMSE':>8s} {'K bias':>7s} {'K cov95':>8s}")  # fmt: skip
        for g, m in groups.items():
            u, k = m["answered"]["U0_eV"], m["answered"]["K_N_m"]
            print(f"  {g:16s} {u['rel_rmse']:9.3f} {u['bias_median']:+8.3f} "
                  f"{u['coverage95']:9.3f} {k['rel_rmse']:8.3f} {k['bias_median']:+7.3f} "
                  f"{k['coverage95']:8.3f}")  # fmt: skip


if __name__ == "__main__":
    main()
