"""The classical estimator on lab-like simulated lines: how many it answers, how well.

Sets (independent of anything the estimator was tuned on, unless ``--tune`` is given):

- ``all families``: the clean randomised evaluation pool of ``benchmarks/families.py``
  (``--n-eval`` trajectories, seed 601, cached under ``--work``) with one draw of every
  effect family at its documented probability (``"eval"`` implementations, seed 6101);
- ``with f``: the same pool with family f on every line (seed 6200 + index of f), as
  ``benchmarks/families.py`` makes them (``--no-families`` skips them);
- ``lab bench``: ``build/lab-bench/bench_200.h5`` (the bench of ``benchmarks/lab_bench.py``,
  simulated first if missing).

``--tune`` scores the sets the estimator's thresholds were tuned on instead: a pool of
``--n-tune`` trajectories of seed 501 (the calibration pool of ``benchmarks/families.py``)
with effect draws of seed 5555, and the bench of seed ``BENCH_SEED + 3``.

Lines with 1.5 <= eta <= 40 are scored through :class:`ClassicalEstimator` ``.predict``
(as ``stickslip infer`` runs it). Printed per set: lines, the fraction answered
(``quality`` ok, with numbers), the fraction in domain, K and U0 relative RMSE over the
answered lines (and their 95th-percentile relative error), and the refusal reasons.

Usage: python benchmarks/classical_lab.py [--work build/families] [--n-eval 400]
       [--bench build/lab-bench/bench_200.h5] [--no-families] [--tune] [--n-tune 600]
"""

from __future__ import annotations

import argparse
import collections
import os
import platform
import time
from pathlib import Path

import numpy as np

from stickslip.estimators.classical.estimator import ClassicalEstimator
from stickslip.estimators.line.families import draw_family_lines
from stickslip.estimators.table import domain_verdict
from stickslip.simulators import effects as fx
from stickslip.simulators.bench import BENCH_SEED, BenchConfig, bench_if_missing, in_eta_window
from stickslip.simulators.randomised import RandomisedConfig, cached_randomised_set
from stickslip.traces.dataset import Dataset, dataset_traces, load_dataset

ROOT = Path(__file__).resolve().parents[1]
EVAL_SEED, ALL_SEED, WITH_SEED = 601, 6101, 6200  # as benchmarks/families.py
TUNE_SEED, TUNE_DRAW_SEED, TUNE_WITH_SEED = 501, 5555, 5600


def score(data: Dataset, estimator: ClassicalEstimator | None = None) -> dict:
    """Answered fraction, in-domain fraction and relative errors on one set.

    Parameters
    ----------
    data : Dataset
        Lines with their truths (``U0_eV``, ``K_N_m``, ``eta`` in ``params``).
    estimator : ClassicalEstimator, optional
        Default: a new one with the paper preset's mass and damping.

    Returns
    -------
    dict
        ``n``, ``answered``, ``in_domain`` (fractions of the lines with
        1.5 <= eta <= 40), ``K_rel_rmse``, ``U0_rel_rmse``, ``K_p95``, ``U0_p95`` (over
        the answered lines) and ``reasons`` (refusal counts).
    """
    est = estimator or ClassicalEstimator()
    ok = in_eta_window(data.params["eta"])
    rows = est.predict(dataset_traces(data)).rows
    rows = [r for r, m in zip(rows, ok, strict=True) if m]
    answered = np.array([r["quality"] == "ok" for r in rows], dtype=bool)
    out: dict = {
        "n": len(rows),
        "answered": float(answered.mean()) if rows else np.nan,
        "in_domain": float(np.mean([domain_verdict(r) is True for r in rows])),
    }
    for key, name in (("K_N_m", "K"), ("U0_eV", "U0")):
        got = np.array([r[key] if a else np.nan for r, a in zip(rows, answered, strict=True)],
                       dtype=float)  # fmt: skip
        rel = got[answered] / np.asarray(data.params[key], float)[ok][answered] - 1.0
        out[f"{name}_rel_rmse"] = float(np.sqrt(np.mean(rel**2))) if rel.size else np.nan
        out[f"{name}_p95"] = float(np.percentile(np.abs(rel), 95)) if rel.size else np.nan
    out["reasons"] = dict(collections.Counter(r["quality"] for r in rows if r["quality"] != "ok"))
    return out


def line(name: str, r: dict) -> str:
    """One printed row of :func:`score`'s result."""
    reasons = ", ".join(f"{k} {v}" for k, v in sorted(r["reasons"].items()))
    return (f"  {name:26s} {r['n']:4d}  {r['answered']:6.3f}  {r['in_domain']:6.3f}  "
            f"{r['K_rel_rmse']:7.2%} {r['K_p95']:7.2%}  {r['U0_rel_rmse']:7.2%} "
            f"{r['U0_p95']:7.2%}  {reasons}")  # fmt: skip


def sets(args: argparse.Namespace) -> dict[str, Dataset]:
    """The scored sets (see the module docstring)."""
    pool_seed, draw_seed, with_seed = ((TUNE_SEED, TUNE_DRAW_SEED, TUNE_WITH_SEED) if args.tune
                                       else (EVAL_SEED, ALL_SEED, WITH_SEED))  # fmt: skip
    n = args.n_tune if args.tune else args.n_eval
    pool = cached_randomised_set(RandomisedConfig(n=n, seed=pool_seed, chunk=100), args.work)
    prior = fx.NuisancePrior()
    out = {"all families": draw_family_lines(pool, prior, draw_seed).data}
    if not args.no_families:
        for j, f in enumerate(fx.FAMILIES):
            out[f"with {f}"] = draw_family_lines(pool, prior.replace(f, p=1.0),
                                                 with_seed + j).data  # fmt: skip
    if args.tune:
        cfg = BenchConfig(n_per_material=120, seed=BENCH_SEED + 3)
        path = args.work / f"bench_{cfg.n_per_material}_{cfg.seed}.h5"
    else:
        cfg, path = BenchConfig(n_per_material=200), args.bench
    out["lab bench"] = load_dataset(bench_if_missing(cfg, path))
    return out


def main() -> None:
    """Command line entry (see the module docstring)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--work",
        type=Path,
        default=ROOT / "build" / "families",
        help="cache of the randomised pools (shared with benchmarks/families.py)",
    )
    ap.add_argument("--n-eval", type=int, default=400)
    ap.add_argument("--bench", type=Path, default=ROOT / "build" / "lab-bench" / "bench_200.h5")
    ap.add_argument("--no-families", action="store_true", help="skip the per-family sets")
    ap.add_argument(
        "--tune",
        action="store_true",
        help="score the tuning sets (seeds 501/5555, bench seed + 3) instead",
    )
    ap.add_argument("--n-tune", type=int, default=600)
    args = ap.parse_args()
    args.work.mkdir(parents=True, exist_ok=True)
    print(f"machine: {platform.platform()}, {platform.processor() or platform.machine()}, "
          f"{os.cpu_count()} cores, python {platform.python_version()}, numba threads "
          f"{os.environ.get('NUMBA_NUM_THREADS', 'default')}")  # fmt: skip
    data = sets(args)
    est = ClassicalEstimator()
    print(f"\n  {'set (1.5 <= eta <= 40)':26s} {'n':>4s}  answer  in dom  K rRMSE   K p95  "
          f"U0 rRMSE  U0 p95  refusals")  # fmt: skip
    t0 = time.perf_counter()
    for name, d in data.items():
        print(line(name, score(d, est)), flush=True)
    print(f"\n{time.perf_counter() - t0:.1f} s")


if __name__ == "__main__":
    main()
