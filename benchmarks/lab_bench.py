"""The laboratory test bench: every estimator on clean simulations and on the bench.

The bench (src/stickslip/simulators/bench.py) is simulated traces that carry the
real-world effects of ../shared/PHYSICS.md, with ground truth: graphite, MoS2 and WS2
lattices, 30 nm/s, barrier modulation and defects, precursor softening, detector
low-pass, white and 1/f noise, offset drift, 16-bit digitisation. Seeds are disjoint
from every training seed.

Estimators: the five-line baseline, the classical estimator, the reference paper's
MLPs (raw and pi recipes, trained here on 1600 clean paper-preset trajectories) and the
whole-line CNN ensemble with uncertainty (``--line-model``, default: the bundled one).
Data sets: clean paper-preset simulations, the bench, and held-out lines from the line
model's own training distribution (a randomised set of another seed, with the training
detector effects). Prints, per data set, RMSE of <F> and relative RMSE of U0, K
(1.5 <= eta <= 40), and the coverage of the 68 % / 95 % intervals; writes summary.json
and reliability plots. Every estimator is called through the one interface
(``predict`` -> ResultTable) and scored through :mod:`stickslip.jobs.evaluate`.

Usage: python benchmarks/lab_bench.py [--work build/lab-bench] [--n-per-material 200]
       [--n-clean 300] [--n-randomised 600] [--line-model PATH] [--epochs 50]
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path
from typing import Any

import numpy as np

from stickslip.diagnostics.calibration import reliability, reliability_plot
from stickslip.estimators.classical.baseline import FiveLineEstimator
from stickslip.estimators.classical.estimator import ClassicalEstimator
from stickslip.estimators.line.estimator import LineEstimator
from stickslip.estimators.line.modelfile import load_line_model
from stickslip.estimators.line.training import LineTrainConfig
from stickslip.estimators.table import ResultTable
from stickslip.estimators.window.estimator import WindowEstimator
from stickslip.jobs.cache import CLEAN_TEST_SEED, LAB_MLP_SEED, clean_window_model, sweep_if_missing
from stickslip.jobs.evaluate import evaluate, truth_from_traces
from stickslip.simulators.bench import MATERIALS, BenchConfig, bench_if_missing, in_eta_window
from stickslip.simulators.instrument import EffectsMixture, InstrumentEffects, apply_instrument
from stickslip.simulators.randomised import RandomisedConfig, cached_randomised_set
from stickslip.traces.dataset import Dataset, dataset_traces, load_dataset

ROOT = Path(__file__).resolve().parents[1]


def window_model(work: Path, recipe: str, epochs: int):
    """The paper's MLP for a recipe, trained on clean paper-preset data (cached)."""
    return clean_window_model(work / f"mlp_{recipe}.pt", work / "train.h5", 1600, LAB_MLP_SEED,
                              recipe, epochs, progress=False)  # fmt: skip


def randomised_heldout(
    work: Path, n: int, seed: int = 201, effects: InstrumentEffects | EffectsMixture | None = None
) -> Dataset:
    """Held-out lines from the line model's own training distribution (cached).

    A randomised set (other seed than any training set) with the training detector
    effects (or ``effects``: ``TRAIN_EFFECTS`` for the broad ranges alone), one fixed
    draw, the same fraction left clean. Truth of <F>: the clean mean.
    """
    ds = cached_randomised_set(RandomisedConfig(n=n, seed=seed), work)
    rng = np.random.default_rng([seed, 77])
    clean = ds.force_nN.astype(float)
    F, _ = apply_instrument(clean, effects or LineTrainConfig().effects, rng)
    keep = rng.random(ds.n) < LineTrainConfig.clean_fraction
    F[keep] = clean[keep]
    return Dataset(F, ds.x_nm, ds.params, {**ds.attrs, "kind": "randomised-heldout"})


def groups(set_name: str, ds: Dataset, ok: np.ndarray) -> dict[str, np.ndarray]:
    """Masks scored for a data set: the whole set, and each material on the bench."""
    out = {set_name: ok}
    if set_name == "bench":
        for m, mat in enumerate(MATERIALS):
            out[f"bench {mat}"] = ok & (ds.params["material"] == m)
    return out


def scores(table: ResultTable, truth: dict[str, dict[str, float]]) -> dict[str, Any]:
    """The metrics of :func:`stickslip.jobs.evaluate.evaluate` (all targets)."""
    return evaluate(table, truth).metrics


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", type=Path, default=ROOT / "build" / "lab-bench")
    ap.add_argument("--n-per-material", type=int, default=200)
    ap.add_argument("--n-clean", type=int, default=300)
    ap.add_argument("--n-randomised", type=int, default=600)
    ap.add_argument("--line-model", type=Path, default=None)
    ap.add_argument("--epochs", type=int, default=50)
    args = ap.parse_args()
    args.work.mkdir(parents=True, exist_ok=True)
    print(f"machine: {platform.processor() or platform.machine()}, {platform.system()}, "
          f"python {platform.python_version()}")  # fmt: skip

    line = LineEstimator(load_line_model(args.line_model), str(args.line_model or "bundled"))
    estimators = {"five-line": FiveLineEstimator(), "classical": ClassicalEstimator(),
                  **{f"MLP {r}": WindowEstimator(window_model(args.work, r, args.epochs),
                                                 f"MLP {r}") for r in ("raw", "pi")},
                  "line CNN": line}  # fmt: skip
    bench_path = bench_if_missing(BenchConfig(n_per_material=args.n_per_material),
                                  args.work / f"bench_{args.n_per_material}.h5")  # fmt: skip
    clean = sweep_if_missing(args.work / "clean.h5", args.n_clean, CLEAN_TEST_SEED)
    sets = {"clean": load_dataset(clean),
            "bench": load_dataset(bench_path),
            "randomised held-out": randomised_heldout(args.work, args.n_randomised)}  # fmt: skip
    summary: dict = {}
    for set_name, ds in sets.items():
        traces = dataset_traces(ds, name=set_name.replace(" ", "-"))
        ok = in_eta_window(ds.params["eta"])
        tables, seconds = {}, {}
        for name, est in estimators.items():
            t0 = time.perf_counter()
            tables[name] = est.predict(traces)
            seconds[name] = time.perf_counter() - t0
        truth = truth_from_traces(tables["line CNN"], traces)
        names = [t.name for t in traces]
        for g, mask in groups(set_name, ds, ok).items():
            truth_g = {n: truth[n] for n, m in zip(names, mask, strict=True) if m}
            print(f"\n{g}: {int(mask.sum())} traces with 1.5 <= eta <= 40")
            print(f"{'estimator':<12}{'<F> RMSE nN':>13}{'U0 rel RMSE':>13}{'K rel RMSE':>12}"
                  f"{'U0 RMSE eV':>12}{'K RMSE N/m':>12}{'cov68 U0/K':>13}{'cov95 U0/K':>13}"
                  f"{'answered':>10}")  # fmt: skip
            for name, table in tables.items():
                m = scores(table, truth_g)
                summary.setdefault(g, {})[name] = m
                u, k = m["U0_eV"], m["K_N_m"]
                cov = " " * 26
                if "coverage68" in u:
                    cov = (f"{u['coverage68']:>8.2f}/{k['coverage68']:.2f}"
                           f"{u['coverage95']:>8.2f}/{k['coverage95']:.2f}")  # fmt: skip
                print(f"{name:<12}{m['F_mean_nN']['rmse']:>13.4f}{u['rel_rmse']:>13.2%}"
                      f"{k['rel_rmse']:>12.2%}{u['rmse']:>12.3f}{k['rmse']:>12.2f}{cov}"
                      f"{u['answered']:>6}/{u['n']}")  # fmt: skip
        print(f"line CNN predict() incl. mapping: {ds.n / seconds['line CNN']:.0f} traces/s")
        # the model's own interval shape: calibrated std times z_at(level), per target
        table = tables["line CNN"]
        curves = {}
        for j, (k, log) in enumerate((("F_mean_nN", False), ("U0_eV", True), ("K_N_m", True),
                                      ("eta", True))):  # fmt: skip
            mid, hi = table.column(k), table.column(f"{k}_hi95")
            loc = np.log(mid) if log else mid
            sig = ((np.log(hi) if log else hi) - loc) / line.ensemble.z_at(0.95)[j]
            true = ds.params[k]
            curves[k] = reliability(true[ok], loc[ok], sig[ok], log,
                                    z_of_level=lambda q, j=j: line.ensemble.z_at(q)[j])  # fmt: skip
        reliability_plot(curves, f"line CNN calibration: {set_name}",
                         args.work / f"calibration_{set_name.replace(' ', '_')}.png")  # fmt: skip
    (args.work / "summary.json").write_text(json.dumps(summary, indent=2, default=float) + "\n")
    print(f"\nwrote {args.work / 'summary.json'} and calibration plots")


if __name__ == "__main__":
    main()
