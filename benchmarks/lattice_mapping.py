"""Error of the lattice mapping on simulated traces at another lattice and velocity.

The estimator (default: the bundled window model, trained at a = 0.246 nm, v = 60 nm/s,
296 K) reads traces simulated at a = 0.316 nm and v = 30 nm/s (MoS2 in the reference
paper's experiments) through the lattice mapping of :mod:`stickslip.estimators.mapping`.
Two controls separate the causes: a = 0.316 nm at the training velocity (lattice
mapping alone) and a = 0.246 nm at 30 nm/s (velocity alone, no mapping). "unmapped"
reads the MoS2 traces as if they were graphene (``lattice_nm=0.246`` given to
``predict``) for comparison. Scored through :mod:`stickslip.jobs.evaluate`.

Usage: python benchmarks/lattice_mapping.py [--n 400] [--seed 21] [--model window]
"""

from __future__ import annotations

import argparse
import platform
from pathlib import Path

from stickslip.conditions import GRAPHITE
from stickslip.estimators.load import load_estimator
from stickslip.jobs.cache import sweep_if_missing
from stickslip.jobs.evaluate import evaluate_dataset
from stickslip.simulators import PhysicalSettings
from stickslip.traces.dataset import load_dataset

ROOT = Path(__file__).resolve().parents[1]
CASES = [
    ("a=0.316 v=30 (MoS2)", 0.316, 30.0, True),
    ("a=0.316 v=30 unmapped", 0.316, 30.0, False),
    ("a=0.316 v=60", 0.316, 60.0, True),
    ("a=0.246 v=30", 0.246, 30.0, True),
    ("a=0.246 v=60 (training)", 0.246, 60.0, True),
]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--work", type=Path, default=ROOT / "build" / "lattice-mapping")
    parser.add_argument("--n", type=int, default=400)
    parser.add_argument("--seed", type=int, default=21)
    parser.add_argument("--model", default="window",
                        help="window (bundled paper MLP), default (bundled line model), "
                        "classical, or a model file")  # fmt: skip
    args = parser.parse_args()
    print(f"machine: {platform.processor() or platform.machine()}, {platform.system()}, "
          f"python {platform.python_version()}")  # fmt: skip
    estimator = load_estimator(args.model)
    print(f"estimator: {estimator.describe()}")
    args.work.mkdir(parents=True, exist_ok=True)
    print(f"{'case':<26}{'U0 RMSE':>9}{'rel med':>9}{'bias':>8}{'K RMSE':>9}{'rel med':>9}"
          f"{'bias':>8}{'eta rel med':>12}")  # fmt: skip
    for label, a, v, mapped in CASES:
        ph = PhysicalSettings(lattice_nm=a, velocity_nm_per_s=v)
        path = sweep_if_missing(args.work / f"a{a}_v{v:g}.h5", args.n, args.seed, ph)
        # unmapped: the lattice given as graphene's, so the trace is read as it is
        lattice = None if mapped else GRAPHITE.lattice_nm
        m = evaluate_dataset(estimator, load_dataset(path), lattice_nm=lattice).metrics
        u, k, e = m["U0_eV"], m["K_N_m"], m["eta"]
        print(f"{label:<26}{u['rmse']:>9.3f}{u['median_rel']:>9.1%}{u['bias']:>8.3f}"
              f"{k['rmse']:>9.3f}{k['median_rel']:>9.1%}{k['bias']:>8.3f}"
              f"{e['median_rel']:>12.1%}")


if __name__ == "__main__":
    main()
