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
3. benches: the lab bench (simulators.bench) with its own seed and two others.

Seeds are apart from every training seed. Traces with 1.5 <= eta <= 40 are scored. For
each population: 95 % and 68 % coverage of <F>, U0, K, eta with their binomial standard
error, and U0 and K relative RMSE; for the laboratory prior, 95 % coverage per scan
velocity as well. Writes summary.json into --work; simulated sets are cached there.
The model is called as a ``LineEstimator`` and scored through :mod:`stickslip.jobs.evaluate`.

Usage: python benchmarks/coverage_check.py [--work build/coverage-check]
       [--n-randomised 2000] [--n-lab 1200] [--n-per-material 200] [--line-model PATH]
"""

from __future__ import annotations

import argparse
import json
import platform
from pathlib import Path

import numpy as np

from stickslip.estimators.line.estimator import LineEstimator
from stickslip.estimators.line.modelfile import load_line_model
from stickslip.estimators.line.training import TRAIN_EFFECTS, LineTrainConfig
from stickslip.estimators.table import TARGETS, ResultTable
from stickslip.jobs.evaluate import evaluate, truth_from_traces
from stickslip.simulators.bench import BENCH_SEED, BenchConfig, bench_if_missing, in_eta_window
from stickslip.simulators.instrument import (
    LAB,
    EffectsMixture,
    InstrumentEffects,
    apply_instrument,
)
from stickslip.simulators.randomised import RandomisedConfig, cached_randomised_set, lab_config
from stickslip.traces.dataset import Dataset, dataset_traces, load_dataset

ROOT = Path(__file__).resolve().parents[1]
KEYS = TARGETS  # <F>, U0, K, eta
RANDOMISED_SEED, LAB_SEED = 301, 401
BENCH_SEEDS = (BENCH_SEED, BENCH_SEED + 7919, BENCH_SEED + 15838)


def randomised_heldout(
    work: Path, n: int, seed: int, effects: InstrumentEffects | EffectsMixture | None = None
) -> Dataset:
    """Held-out lines from the line model's own training distribution (cached).

    A randomised set (other seed than any training set) with the training detector
    effects (or ``effects``: ``TRAIN_EFFECTS`` for the broad ranges alone), one fixed
    draw, the same fraction left clean (as lab_bench.py). Truth of <F>: the clean mean.
    """
    ds = cached_randomised_set(RandomisedConfig(n=n, seed=seed), work)
    rng = np.random.default_rng([seed, 77])
    clean = ds.force_nN.astype(float)
    F, _ = apply_instrument(clean, effects or LineTrainConfig().effects, rng)
    keep = rng.random(ds.n) < LineTrainConfig.clean_fraction
    F[keep] = clean[keep]
    return Dataset(F, ds.x_nm, ds.params, {**ds.attrs, "kind": "randomised-heldout"})


def lab_prior(work: Path, n: int) -> Dataset:
    """Laboratory-prior lines: lab_config trajectories with one draw of the LAB effects."""
    ds = cached_randomised_set(lab_config(n, LAB_SEED), work)
    F, _ = apply_instrument(ds.force_nN.astype(float), LAB, np.random.default_rng([LAB_SEED, 77]))
    return Dataset(F, ds.x_nm, ds.params, {**ds.attrs, "kind": "lab-prior"})


def bench(work: Path, seed: int, n_per_material: int) -> Dataset:
    """A lab bench drawn with ``seed`` (cached)."""
    config = BenchConfig(n_per_material=n_per_material, seed=seed)
    return load_dataset(bench_if_missing(config, work / f"bench_{n_per_material}_{seed}.h5"))


def metrics(table: ResultTable, truth: dict, names: list[str], mask: np.ndarray) -> dict:
    """Evaluation metrics of the rows in ``mask`` (:func:`stickslip.jobs.evaluate.evaluate`)."""
    return evaluate(table, {n: truth[n] for n, m in zip(names, mask, strict=True) if m}).metrics


def scored(ds: Dataset, estimator: LineEstimator) -> dict:
    """Coverage (with binomial standard errors) and relative RMSE on one population."""
    traces = dataset_traces(ds)
    table = estimator.predict(traces)
    truth, names = truth_from_traces(table, traces), [t.name for t in traces]
    ok = in_eta_window(ds.params["eta"])
    m = metrics(table, truth, names, ok)
    n = m["U0_eV"]["n"]
    out: dict = {"n": n}
    for level in ("95", "68"):
        cov = {k: m[k][f"coverage{level}"] for k in KEYS}
        out[f"coverage{level}"] = cov
        out[f"se{level}"] = {k: float(np.sqrt(c * (1 - c) / n)) for k, c in cov.items()}
    for k in ("U0_eV", "K_N_m"):
        out[f"{k}_rel_rmse"] = m[k]["rel_rmse"]
    v = ds.params["velocity_nm_per_s"]
    out["coverage95_by_velocity"] = {}
    for u in np.unique(v):
        mv = metrics(table, truth, names, ok & (v == u))
        out["coverage95_by_velocity"][f"{u:g}"] = {
            "n": mv["U0_eV"]["n"], **{k: mv[k]["coverage95"] for k in ("U0_eV", "K_N_m")}}
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
    estimator = LineEstimator(load_line_model(args.line_model), str(args.line_model or "bundled"))
    populations = {
        f"randomised held-out (seed {RANDOMISED_SEED})":
            lambda: randomised_heldout(args.work, args.n_randomised, RANDOMISED_SEED),
        "the same, broad effects only":
            lambda: randomised_heldout(args.work, args.n_randomised, RANDOMISED_SEED,
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
        r = scored(load(), estimator)
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
