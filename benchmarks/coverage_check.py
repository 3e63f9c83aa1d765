"""Interval coverage of the bundled line model on several populations, with error bars.

lab_bench.py measures coverage on one bench draw and 583 held-out lines. This checks
whether those figures are the population's or the draw's, on populations that go from
the training distribution to the bench:

1. randomised held-out: --n-randomised new trajectories of the training distribution
   (seed 301), one fixed draw of the training detector effects (20 % left clean, as in
   training and lab_bench.py); then the same trajectories with effects from the broad
   ranges alone (line_training.TRAIN_EFFECTS: the training prior's tail);
2. laboratory prior: the training parameters, lattices and velocities on the bench's
   substrate (randomised.lab_config, seed 401), with the bench's LAB detector effects;
3. benches: the lab bench (evaluation.bench) with its own seed and two others.

Seeds are apart from every training seed. Traces with 1.5 <= eta <= 40 are scored. For
each population: 95 % and 68 % coverage of <F>, U0, K, eta with their binomial standard
error, and U0 and K relative RMSE; for the laboratory prior, 95 % coverage per scan
velocity as well. Writes summary.json into --work; simulated sets are cached there.

Usage: python benchmarks/coverage_check.py [--work build/coverage-check]
       [--n-randomised 2000] [--n-lab 1200] [--n-per-material 200] [--line-model PATH]
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
from pathlib import Path

import numpy as np

from stickslip.diagnostics.calibration import coverage
from stickslip.estimators.line.ensemble import predict_raw_lines
from stickslip.estimators.line.modelfile import load_line_model
from stickslip.estimators.line.training import TRAIN_EFFECTS
from stickslip.simulators.bench import BENCH_SEED, BenchConfig, bench_if_missing, in_eta_window
from stickslip.simulators.instrument import LAB, apply_instrument
from stickslip.simulators.randomised import cached_randomised_set, lab_config
from stickslip.traces.dataset import Dataset, load_dataset

sys.path.insert(0, str(Path(__file__).resolve().parent))  # lab_bench.py beside this file
from lab_bench import randomised_heldout  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
KEYS = ("F_mean_nN", "U0_eV", "K_N_m", "eta")
RANDOMISED_SEED, LAB_SEED = 301, 401
BENCH_SEEDS = (BENCH_SEED, BENCH_SEED + 7919, BENCH_SEED + 15838)


def lab_prior(work: Path, n: int) -> Dataset:
    """Laboratory-prior lines: lab_config trajectories with one draw of the LAB effects."""
    ds = cached_randomised_set(lab_config(n, LAB_SEED), work)
    F, _ = apply_instrument(ds.force_nN.astype(float), LAB, np.random.default_rng([LAB_SEED, 77]))
    return Dataset(F, ds.x_nm, ds.params, {**ds.attrs, "kind": "lab-prior"})


def bench(work: Path, seed: int, n_per_material: int) -> Dataset:
    """A lab bench drawn with ``seed`` (cached)."""
    config = BenchConfig(n_per_material=n_per_material, seed=seed)
    return load_dataset(bench_if_missing(config, work / f"bench_{n_per_material}_{seed}.h5"))


def scored(ds: Dataset, model) -> dict:
    """Coverage (with binomial standard errors) and relative RMSE on one population."""
    p = ds.params
    lp = predict_raw_lines(model, [ds.x_nm] * ds.n, list(ds.force_nN.astype(float)),
                           p["lattice_nm"], p["velocity_nm_per_s"])  # fmt: skip
    ok = in_eta_window(p["eta"])
    n = int(ok.sum())
    out: dict = {"n": n}
    for level, lo, hi in (("95", lp.lo95, lp.hi95), ("68", lp.lo68, lp.hi68)):
        cov = {k: coverage(p[k][ok], lo[k][ok], hi[k][ok]) for k in KEYS}
        out[f"coverage{level}"] = cov
        out[f"se{level}"] = {k: float(np.sqrt(c * (1 - c) / n)) for k, c in cov.items()}
    for k in ("U0_eV", "K_N_m"):
        out[f"{k}_rel_rmse"] = float(np.sqrt(np.mean((lp.values[k] / p[k] - 1)[ok] ** 2)))
    v = p["velocity_nm_per_s"]
    out["coverage95_by_velocity"] = {}
    for u in np.unique(v):
        m = ok & (v == u)
        out["coverage95_by_velocity"][f"{u:g}"] = {
            "n": int(m.sum()),
            **{k: coverage(p[k][m], lp.lo95[k][m], lp.hi95[k][m]) for k in ("U0_eV", "K_N_m")},
        }
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", type=Path, default=ROOT / "build" / "coverage-check")
    ap.add_argument("--n-randomised", type=int, default=2000)
    ap.add_argument("--n-lab", type=int, default=1200)
    ap.add_argument("--n-per-material", type=int, default=200)
    ap.add_argument("--line-model", type=Path, default=None, help="default: the bundled one")
    args = ap.parse_args()
    args.work.mkdir(parents=True, exist_ok=True)
    model = load_line_model(args.line_model)
    populations = {
        f"randomised held-out (seed {RANDOMISED_SEED})":
            lambda: randomised_heldout(args.work, args.n_randomised, seed=RANDOMISED_SEED),
        "the same, broad effects only":
            lambda: randomised_heldout(args.work, args.n_randomised, seed=RANDOMISED_SEED,
                                       effects=TRAIN_EFFECTS),
        f"laboratory prior (seed {LAB_SEED})": lambda: lab_prior(args.work, args.n_lab),
        **{f"bench (seed {s})": (lambda s=s: bench(args.work, s, args.n_per_material))
           for s in BENCH_SEEDS},
    }  # fmt: skip
    print(f"machine: {platform.processor() or platform.machine()}, {platform.system()}, "
          f"python {platform.python_version()}")  # fmt: skip
    print(f"line model: {args.line_model or 'bundled'}; traces with 1.5 <= eta <= 40\n")
    head = "<F>/U0/K/eta"
    print(f"{'population':34s} {'n':>5s}  {'cov95 ' + head:31s} {'+- (1 se)':22s} "
          f"{'cov68 ' + head:27s} U0 rel  K rel")  # fmt: skip
    summary = {}
    for name, load in populations.items():
        r = scored(load(), model)
        summary[name] = r

        def row(d: dict) -> str:
            return "/".join(f"{d[k]:.3f}" for k in KEYS)

        print(f"{name:34s} {r['n']:5d}  {row(r['coverage95']):31s} {row(r['se95']):22s} "
              f"{row(r['coverage68']):27s} {r['U0_eV_rel_rmse']:6.2%} "
              f"{r['K_N_m_rel_rmse']:6.2%}")  # fmt: skip
    lab = summary[f"laboratory prior (seed {LAB_SEED})"]["coverage95_by_velocity"]
    print("\nlaboratory prior, 95 % coverage per scan velocity (U0/K):")
    for v, d in lab.items():
        print(f"  {v:>3s} nm/s  n={d['n']:4d}  {d['U0_eV']:.3f}/{d['K_N_m']:.3f}")
    (args.work / "summary.json").write_text(json.dumps(summary, indent=1))
    print(f"\nwrote {args.work / 'summary.json'}")


if __name__ == "__main__":
    main()
