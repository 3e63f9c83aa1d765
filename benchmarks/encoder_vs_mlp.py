"""The whole-line CNN against the paper's window MLPs trained on the same randomised data.

The lab bench (benchmarks/lab_bench.py) compares the line CNN, trained with domain
randomisation, with the paper's MLPs trained on clean paper-preset traces. This
benchmark trains the MLPs (raw and pi recipes, the paper's network and optimiser, p =
64, stride 64, train stride 16, as lab_bench.py) on the line model's own training set
instead: the domain-randomised set mapped onto the reference lattice, labels in the
reference frame, corrupted with the line model's detector effects (20 % left clean),
several independent corruption replicas per trajectory
(stickslip.estimators.window.randomised). Replicas of a trajectory stay on one side of
the train/validation split.

All estimators are scored as in lab_bench.py on its clean held-out set (300 paper-preset
traces, seed 4242) and on the bench (600 traces, three materials), for traces with
1.5 <= eta <= 40. The clean-trained MLPs are included when build/lab-bench/mlp_*.pt
exist. "<F> net" is the MLPs' own window estimate of <F> (their "<F>" column is the
trace's mean, as in lab_bench.py). Every estimator is called through ``predict`` and
scored through :mod:`stickslip.jobs.evaluate`. Writes summary.json into --work.

Usage: python benchmarks/encoder_vs_mlp.py [--work build/encoder-vs-mlp] [--replicas 3]
       [--epochs 50] [--seeds 102 103]   (the bundled line model's training sets)
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np

from stickslip.estimators.classical.baseline import FiveLineEstimator
from stickslip.estimators.classical.estimator import ClassicalEstimator
from stickslip.estimators.line.estimator import LineEstimator
from stickslip.estimators.line.modelfile import load_line_model
from stickslip.estimators.table import ResultTable
from stickslip.estimators.window.estimator import WindowEstimator
from stickslip.estimators.window.modelfile import load_model, save_model
from stickslip.estimators.window.randomised import randomised_window_set, split_by_group
from stickslip.estimators.window.training import TrainConfig, spec_for_dataset, train_model
from stickslip.jobs.cache import CLEAN_TEST_SEED, sweep_if_missing
from stickslip.jobs.evaluate import evaluate, truth_from_traces
from stickslip.simulators.bench import MATERIALS, BenchConfig, bench_if_missing, in_eta_window
from stickslip.simulators.randomised import RandomisedConfig, cached_randomised_set
from stickslip.traces.dataset import concat_datasets, dataset_traces, load_dataset

ROOT = Path(__file__).resolve().parents[1]
LAB = ROOT / "build" / "lab-bench"


def dr_window_model(train, work: Path, recipe: str, epochs: int, replicas: int):
    """The paper's MLP for a recipe trained on the randomised window set (cached)."""
    path = work / f"mlp_{recipe}_dr_r{replicas}_e{epochs}.pt"
    if path.exists():
        model = load_model(path)
        if model.dataset_fingerprint == train.fingerprint():
            return model
    cfg = TrainConfig(epochs=epochs)
    tr, va = split_by_group(train.params["trajectory"], cfg.val_fraction, cfg.seed)
    spec = spec_for_dataset(train, recipe, 64, 64, 16)
    model, _, _ = train_model(train, spec, cfg, progress=False, train_idx=tr, val_idx=va)
    save_model(model, path)
    return model


def network_friction(table: ResultTable) -> ResultTable:
    """The table with a window model's own <F> (``F_mean_net``) as ``F_mean_nN``."""
    rows = [{**r, "F_mean_nN": r.get("F_mean_net")} for r in table.rows]
    return ResultTable(rows=rows, estimator=table.estimator, intervals=table.intervals)


def groups(set_name: str, ds, ok: np.ndarray) -> dict[str, np.ndarray]:
    """Masks scored for a data set: the whole set, and each material on the bench."""
    out = {set_name: ok}
    if set_name == "bench":
        for m, mat in enumerate(MATERIALS):
            out[f"bench {mat}"] = ok & (ds.params["material"] == m)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", type=Path, default=ROOT / "build" / "encoder-vs-mlp")
    ap.add_argument("--replicas", type=int, default=3)
    ap.add_argument("--epochs", type=int, default=50)
    ap.add_argument("--seeds", type=int, nargs="+", default=[102, 103])
    ap.add_argument("--n", type=int, default=4000)
    args = ap.parse_args()
    t_start = time.perf_counter()
    args.work.mkdir(parents=True, exist_ok=True)
    machine = (f"{platform.processor() or platform.machine()}, {platform.system()}, "
               f"python {platform.python_version()}")  # fmt: skip
    print(f"machine: {machine}")

    source = concat_datasets([
        cached_randomised_set(RandomisedConfig(n=args.n, seed=s), ROOT / "build" / "line-train")
        for s in args.seeds])  # fmt: skip
    t0 = time.perf_counter()
    train = randomised_window_set(source, replicas=args.replicas)
    build_s = time.perf_counter() - t0
    print(f"randomised window set: {train.n} rows ({args.replicas} replicas of "
          f"{train.n // args.replicas} trajectories), {train.force_nN.shape[1]} reference "
          f"pixels, {np.mean(train.params['clean']):.1%} clean, "
          f"built in {build_s:.1f} s")  # fmt: skip

    mlps = {}
    for r in ("raw", "pi"):
        if (LAB / f"mlp_{r}.pt").exists():
            mlps[f"MLP {r} (clean)"] = load_model(LAB / f"mlp_{r}.pt")
    training = {}
    for r in ("raw", "pi"):
        t0 = time.perf_counter()
        model = dr_window_model(train, args.work, r, args.epochs, args.replicas)
        tc = model.train_config
        training[f"MLP {r} (DR)"] = {k: tc.get(k) for k in (
            "train_seconds", "best_epoch", "n_train_trajectories", "n_val_trajectories",
            "n_train_windows")}  # fmt: skip
        print(f"MLP {r} (DR): {tc.get('n_train_windows')} training windows, best epoch "
              f"{tc.get('best_epoch')}/{args.epochs}, trained in {tc.get('train_seconds', 0):.0f} s"
              f" ({time.perf_counter() - t0:.0f} s here incl. loading)")  # fmt: skip
        mlps[f"MLP {r} (DR)"] = model
    estimators = {"five-line": FiveLineEstimator(), "classical": ClassicalEstimator(),
                  **{name: WindowEstimator(m, name) for name, m in mlps.items()},
                  "line CNN": LineEstimator(load_line_model(None), "bundled")}  # fmt: skip

    bench_path = bench_if_missing(BenchConfig(n_per_material=200), LAB / "bench_200.h5")
    sets = {"clean": load_dataset(sweep_if_missing(LAB / "clean.h5", 300, CLEAN_TEST_SEED)),
            "bench": load_dataset(bench_path)}  # fmt: skip
    summary: dict = {"machine": machine, "args": {k: str(v) for k, v in vars(args).items()},
                     "training": training, "scores": {}}  # fmt: skip
    for set_name, ds in sets.items():
        traces = dataset_traces(ds, name=set_name)
        tables = {name: est.predict(traces) for name, est in estimators.items()}
        truth = truth_from_traces(tables["line CNN"], traces)
        names = [t.name for t in traces]
        ok = in_eta_window(ds.params["eta"])
        for g, mask in groups(set_name, ds, ok).items():
            truth_g = {n: truth[n] for n, m in zip(names, mask, strict=True) if m}
            print(f"\n{g}: {int(mask.sum())} traces with 1.5 <= eta <= 40")
            print(f"{'estimator':<18}{'<F> RMSE nN':>13}{'U0 rel RMSE':>13}{'K rel RMSE':>12}"
                  f"{'U0 RMSE eV':>12}{'K RMSE N/m':>12}{'<F> net nN':>12}")  # fmt: skip
            for est, table in tables.items():
                m = evaluate(table, truth_g).metrics
                s = {"metrics": m}
                net = ""
                if est in mlps:
                    f_net = evaluate(network_friction(table), truth_g).metrics["F_mean_nN"]
                    s["F_net_rmse"] = f_net["rmse"]
                    net = f"{f_net['rmse']:>12.4f}"
                summary["scores"].setdefault(g, {})[est] = s
                u, k = m["U0_eV"], m["K_N_m"]
                print(f"{est:<18}{m['F_mean_nN']['rmse']:>13.4f}{u['rel_rmse']:>13.2%}"
                      f"{k['rel_rmse']:>12.2%}{u['rmse']:>12.3f}{k['rmse']:>12.2f}{net}")
    summary["wall_seconds"] = time.perf_counter() - t_start
    (args.work / "summary.json").write_text(json.dumps(summary, indent=2, default=float) + "\n")
    print(f"\nwrote {args.work / 'summary.json'} ({summary['wall_seconds']:.0f} s in all)")


if __name__ == "__main__":
    main()
