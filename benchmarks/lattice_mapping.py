"""Error of the lattice mapping on simulated traces at another lattice and velocity.

The model (default: the bundled one, trained at a = 0.246 nm, v = 60 nm/s, 296 K) reads
traces simulated at a = 0.316 nm and v = 30 nm/s (MoS2 in the reference paper's
experiments) through the lattice mapping of :mod:`stickslip.estimators.window.inference`. Two
controls separate the causes: a = 0.316 nm at the training velocity (lattice mapping
alone) and a = 0.246 nm at 30 nm/s (velocity alone, no mapping). "unmapped" reads the
MoS2 traces as if they were graphene (no mapping) for comparison.

Usage: python benchmarks/lattice_mapping.py [--n 400] [--seed 21] [--model PATH]
"""

from __future__ import annotations

import argparse
from pathlib import Path

from stickslip.estimators.window.modelfile import load_model
from stickslip.jobs.report import evaluate_model
from stickslip.jobs.workflow import sweep_if_missing
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
    parser.add_argument("--model", default=None)
    args = parser.parse_args()
    model = load_model(args.model)
    print(f"{'case':<26}{'U0 RMSE':>9}{'rel med':>9}{'bias':>8}{'K RMSE':>9}{'rel med':>9}"
          f"{'bias':>8}{'eta rel med':>12}")  # fmt: skip
    for label, a, v, mapped in CASES:
        ph = PhysicalSettings(lattice_nm=a, velocity_nm_per_s=v)
        path = sweep_if_missing(args.work / f"a{a}_v{v:g}.h5", args.n, args.seed, ph)
        m = evaluate_model(model, load_dataset(path), lattice_mapping=mapped).metrics
        u, k, e = m["U0_eV"], m["K_N_m"], m["eta"]
        print(f"{label:<26}{u['rmse']:>9.3f}{u['rel_median_abs']:>9.1%}{u['bias']:>8.3f}"
              f"{k['rmse']:>9.3f}{k['rel_median_abs']:>9.1%}{k['bias']:>8.3f}"
              f"{e['rel_median_abs']:>12.1%}")


if __name__ == "__main__":
    main()
