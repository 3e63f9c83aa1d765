"""The reference paper's Table 1, every row, with the lab bench standing in for "Exp".

The paper (Shabani et al., ../shared/PHYSICS.md) trains its MLP on 1600 MD traces
("MD") or on 1298 AFM traces labelled by a classical slip-detection algorithm ("Exp"),
and evaluates each on the other. Here "MD" is the paper preset
(:func:`stickslip.jobs.cache.sweep_if_missing`: an independently seeded training
sweep and test sweep), and "Exp" is the project's lab bench
(:mod:`stickslip.simulators.bench`: graphite, MoS2 and WS2 lattices at 30 nm/s, barrier
modulation and defects, precursor softening, detector low-pass, white and 1/f noise,
offset drift, 16-bit digitisation). The bench is labelled two ways:

- ``truth``: its simulated parameters (the labels the paper could not have);
- ``classical``: as the paper did, by the classical estimator
  (``ClassicalEstimator().predict``), rows with ``quality`` ok only.

Rows (the paper's recipe throughout: the MLP 256-128, Adam 5e-4, batch 300, window 64,
inference stride 64, train stride 16, 80/20 train/validation split by trajectory;
"NN" = raw input, "PI-NN" = the physics-informed input):

- NN MD->MD: raw MLP trained on the MD sweep, tested on the MD test sweep;
- NN MD->Exp: the same model on the held-out 20 % of the bench lines (below);
- NN Exp->Exp: raw MLP trained (:func:`stickslip.jobs.train.train_window`) on
  :func:`~stickslip.jobs.train.labelled_dataset` of 80 % of the bench lines (mapped onto
  the graphite lattice with their labels), tested on the other 20 %;
- NN Exp->MD: that model on the MD test sweep;
- PI-NN MD->Exp: pi MLP trained on the MD sweep, on the held-out 20 % (PI-NN MD->MD is
  printed too);
- NN MD+1% Exp->Exp: raw MLP trained on the MD sweep with labelled lines of the bench's
  80 % mixed in as 1 % of the training lines (:func:`~stickslip.jobs.train.mix_in`; the
  paper's SI III, not given here: its figures print as "-"), tested on the 20 %.

Every "->Exp" row is scored on the same held-out 20 % (so the rows compare); the
MD-trained models are also scored on every bench line, as the paper scored them on all
its experimental traces.

Scored through :mod:`stickslip.jobs.evaluate` only. "<F>" is the network's own
estimate (``F_mean_net``, as the paper's NN); "<F> mean" the result table's
``F_mean_nN``, the trace's own mean, for comparison. Models and MD sweeps are cached in
--work, the bench in lab_bench.py's file (build/lab-bench/bench_200.h5, or --bench);
writes summary.json and one evaluation folder per row into --work.

Usage: python benchmarks/paper_table.py [--work build/paper-table] [--n-train 1600]
       [--n-test 400] [--n-per-material 200] [--bench PATH] [--epochs 50]
       [--mix-fraction 0.01]
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import time
from pathlib import Path

import numpy as np
import torch

from stickslip.conditions import GRAPHITE
from stickslip.estimators.classical.estimator import ClassicalEstimator
from stickslip.estimators.table import OK, TARGETS, ResultTable
from stickslip.estimators.window.estimator import WindowEstimator
from stickslip.estimators.window.modelfile import TrainedModel, load_model
from stickslip.estimators.window.training import TrainConfig
from stickslip.jobs.cache import LAB_MLP_SEED, sweep_if_missing
from stickslip.jobs.evaluate import evaluate, truth_from_traces, write_evaluation
from stickslip.jobs.train import (
    TrainingData,
    labelled_dataset,
    mix_in,
    read_training_data,
    train_window,
)
from stickslip.simulators.bench import BenchConfig, bench_if_missing
from stickslip.traces.dataset import dataset_traces, load_dataset, read_attrs
from stickslip.traces.trace import Trace

ROOT = Path(__file__).resolve().parents[1]
WINDOW, STRIDE, TRAIN_STRIDE = 64, 64, 16
# the MD->MD sweeps of docs/explanation/learned-model.md
MD_TRAIN_SEED, MD_TEST_SEED = LAB_MLP_SEED, 11
SPLIT_SEED, MIX_SEED = 3, 0
# the paper's Table 1 (RMSE of <F> nN, U0 eV, K N/m); None: not in the main text
PAPER = {
    "NN MD->MD": (0.16, 0.18, 0.84),
    "NN MD->Exp": (0.31, 1.78, 26.62),
    "NN Exp->Exp": (0.13, 0.68, 2.97),
    "NN Exp->MD": (0.42, 1.54, 23.33),
    "PI-NN MD->MD": None,
    "PI-NN MD->Exp": (0.18, 1.33, 4.33),
    "NN MD+1% Exp->Exp": None,
}
STAND_IN = {"MD": "paper-preset sweep", "Exp": "lab bench"}
MD_TEST, EXP_HELD, EXP_ALL = "MD test", "Exp held-out", "Exp all"
Labels = dict[str, dict[str, float]]


def machine() -> str:
    load = f", load average {os.getloadavg()[0]:.1f}" if hasattr(os, "getloadavg") else ""
    return (f"{platform.processor() or platform.machine()}, {platform.system()}, "
            f"{os.cpu_count()} cores{load}, python {platform.python_version()}, "
            f"torch {torch.__version__}")  # fmt: skip


def window_model(path: Path, training: TrainingData, recipe: str, epochs: int) -> TrainedModel:
    """The paper's MLP trained with :func:`train_window` (cached in ``path`` while its
    training data, recipe and epochs are the same)."""
    if path.exists():
        model = load_model(path)
        if (model.dataset_fingerprint == training.data.fingerprint()
                and model.features.recipe == recipe
                and model.train_config.get("epochs") == epochs):  # fmt: skip
            return model
    model, _, _ = train_window(training, path, recipe, TrainConfig(epochs=epochs), WINDOW, STRIDE,
                               TRAIN_STRIDE, progress=False)  # fmt: skip
    return model


def classical_labels(traces: list[Trace]) -> Labels:
    """The classical estimator's <F>, U0, K, eta per trace name, rows with quality ok."""
    table = ClassicalEstimator().predict(traces)
    return {r["trace"]: {k: float(r[k]) for k in TARGETS}
            for r in table.rows if r.get("quality") == OK}  # fmt: skip


def network_friction(table: ResultTable) -> ResultTable:
    """The table with the network's own <F> (``F_mean_net``) as ``F_mean_nN``."""
    rows = [{**r, "F_mean_nN": r.get("F_mean_net")} for r in table.rows]
    return ResultTable(rows=rows, estimator=table.estimator, intervals=table.intervals)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", type=Path, default=ROOT / "build" / "paper-table")
    ap.add_argument("--n-train", type=int, default=1600, help="MD training trajectories")
    ap.add_argument("--n-test", type=int, default=400, help="MD test trajectories")
    ap.add_argument("--n-per-material", type=int, default=200,
                    help="bench lines per material (three materials)")
    ap.add_argument("--bench", type=Path, default=None,
                    help="bench file (cache; default: the lab bench's, "
                    "build/lab-bench/bench_N.h5 for N per material)")
    ap.add_argument("--epochs", type=int, default=50)
    ap.add_argument("--mix-fraction", type=float, default=0.01)
    args = ap.parse_args()
    args.work.mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()
    print(f"date: {datetime.date.today().isoformat()}")
    print(f"machine: {machine()}")

    # data: MD training and test sweeps, the bench (Exp) and its 80/20 split
    md_path = sweep_if_missing(args.work / "md_train.h5", args.n_train, MD_TRAIN_SEED)
    md_test = load_dataset(sweep_if_missing(args.work / "md_test.h5", args.n_test, MD_TEST_SEED))
    bench_cfg = BenchConfig(n_per_material=args.n_per_material)
    bench_path = args.bench or ROOT / "build" / "lab-bench" / f"bench_{args.n_per_material}.h5"
    if bench_path.exists() and read_attrs(bench_path).get("config") != bench_cfg.to_json():
        ap.error(f"{bench_path} was made with another bench config; give --bench")
    bench = load_dataset(bench_if_missing(bench_cfg, bench_path))
    perm = np.random.default_rng(SPLIT_SEED).permutation(bench.n)
    n_fit = int(round(0.8 * bench.n))
    exp_fit, exp_test = np.sort(perm[:n_fit]), np.sort(perm[n_fit:])
    md_traces = dataset_traces(md_test, name="md")
    bench_traces = dataset_traces(bench, name="bench")
    fit_traces = [bench_traces[i] for i in exp_fit]
    test_names = {bench_traces[i].name for i in exp_test}
    t0 = time.perf_counter()
    labels: dict[str, Labels] = {
        "truth": {t.name: {k: float(t.meta[k]) for k in TARGETS} for t in bench_traces},
        "classical": classical_labels(bench_traces),
    }
    classical_s = time.perf_counter() - t0
    print(f"MD: train {args.n_train} trajectories (seed {MD_TRAIN_SEED}), test {md_test.n} "
          f"(seed {MD_TEST_SEED}); Exp: lab bench, {bench.n} lines ({args.n_per_material} per "
          f"material, seed {bench_cfg.seed}), {len(fit_traces)} to train on / {len(test_names)} "
          "held out")  # fmt: skip
    print(f"classical labels: {len(labels['classical'])} of {bench.n} bench lines ok "
          f"({classical_s:.0f} s); {args.epochs} epochs; mixing fraction {args.mix_fraction:g}")

    # models: MD-trained (raw, pi), and per labelling Exp-trained and MD + mixed-in Exp
    md = read_training_data([md_path], None, GRAPHITE)
    models = {f"md_{r}": window_model(args.work / f"md_{r}.pt", md, r, args.epochs)
              for r in ("raw", "pi")}  # fmt: skip
    for how, lab in labels.items():
        exp = TrainingData(labelled_dataset(fit_traces, lab, GRAPHITE, bench.force_nN.shape[1]),
                           [{"bench": bench_cfg.to_json(), "labels": how}])  # fmt: skip
        models[f"exp_{how}"] = window_model(args.work / f"exp_{how}_raw.pt", exp, "raw",
                                            args.epochs)  # fmt: skip
        mixed = mix_in(md, exp.data, args.mix_fraction, MIX_SEED)
        mixed_rows = mixed.parts[-1]["mixed_real_rows"]
        models[f"mix_{how}"] = window_model(args.work / f"mix_{how}_raw.pt", mixed, "raw",
                                            args.epochs)  # fmt: skip
    seconds = {k: m.train_config.get("train_seconds", float("nan")) for k, m in models.items()}
    print(f"mixing: {mixed_rows} labelled bench lines (of the {len(fit_traces)} to train on) "
          f"added to {md.data.n} MD lines")  # fmt: skip
    print("training seconds: " + ", ".join(f"{k} {s:.0f}" for k, s in seconds.items()))

    # each row: (name, model, test traces, truths of the rows scored, labelling, test set)
    md_truth = None  # truths stored with the MD traces
    rows = [("NN MD->MD", "md_raw", md_traces, md_truth, "truth", MD_TEST),
            ("PI-NN MD->MD", "md_pi", md_traces, md_truth, "truth", MD_TEST)]
    for how, lab in labels.items():
        held = {k: v for k, v in lab.items() if k in test_names}
        rows += [
            ("NN MD->Exp", "md_raw", bench_traces, held, how, EXP_HELD),
            ("NN Exp->Exp", f"exp_{how}", bench_traces, held, how, EXP_HELD),
            ("NN Exp->MD", f"exp_{how}", md_traces, md_truth, how, MD_TEST),
            ("PI-NN MD->Exp", "md_pi", bench_traces, held, how, EXP_HELD),
            ("NN MD+1% Exp->Exp", f"mix_{how}", bench_traces, held, how, EXP_HELD),
            ("NN MD->Exp", "md_raw", bench_traces, lab, how, EXP_ALL),
            ("PI-NN MD->Exp", "md_pi", bench_traces, lab, how, EXP_ALL),
        ]
    tables: dict[tuple[str, int], ResultTable] = {}
    results = []
    for name, key, traces, truth, how, scope in rows:
        cache = (key, id(traces))
        if cache not in tables:
            tables[cache] = WindowEstimator(models[key], key).predict(traces)
        table = tables[cache]
        truth = truth if truth is not None else truth_from_traces(table, traces)
        ev = evaluate(network_friction(table), truth)
        mean_f = evaluate(table, truth).metrics["F_mean_nN"]
        slug = (f"{name}_{how}_{scope}".replace(" ", "_").replace("->", "-to-")
                .replace("%", "pc"))  # fmt: skip
        write_evaluation(ev, args.work / "rows" / slug, {"row": name, "labels": how,
                                                          "model": key, "test": scope})  # fmt: skip
        results.append({"row": name, "labels": how, "model": key, "test": scope,
                        "metrics": ev.metrics, "F_mean_trace_mean": mean_f})  # fmt: skip

    order = list(PAPER)
    results.sort(key=lambda r: (r["test"] == EXP_ALL, order.index(r["row"]),
                                r["labels"] != "truth"))  # fmt: skip
    print("\nRMSE per row: ours (<F> = the network's own estimate; <F> mean = the trace's "
          "mean) and the paper's Table 1")
    head = f"{'row':<19}{'Exp labels':<11}{'test':<13}{'n':>4}"
    print(f"{head}{'<F> nN':>7}{'U0 eV':>7}{'K N/m':>7}{'<F> mean':>9}  {'paper <F>/U0/K':<17}"
          "stand-ins")  # fmt: skip
    for i, r in enumerate(results):
        if r["test"] == EXP_ALL and (i == 0 or results[i - 1]["test"] != EXP_ALL):
            print("the MD-trained models on every bench line (as the paper: all its Exp traces):")
        m = r["metrics"]
        paper = PAPER[r["row"]]
        ptxt = "/".join(f"{v:g}" for v in paper) if paper else "-"
        exp = "Exp" in r["row"]
        used = [f"MD = {STAND_IN['MD']}"] if "MD" in r["row"] else []
        used += [f"Exp = {STAND_IN['Exp']}"] if exp else []
        print(f"{r['row']:<19}{r['labels'] if exp else '-':<11}{r['test']:<13}"
              f"{m['U0_eV']['answered']:>4}{m['F_mean_nN']['rmse']:>7.3f}{m['U0_eV']['rmse']:>7.3f}"
              f"{m['K_N_m']['rmse']:>7.2f}{r['F_mean_trace_mean']['rmse']:>9.3f}  {ptxt:<17}"
              f"{', '.join(used)}")  # fmt: skip
    print("\nthe same rows: median relative error and bias of U0 and K, eta RMSE")
    print(f"{head}{'U0 med':>8}{'K med':>8}{'U0 bias':>9}{'K bias':>8}{'eta':>7}")
    for r in results:
        m = r["metrics"]
        u, k = m["U0_eV"], m["K_N_m"]
        print(f"{r['row']:<19}{r['labels'] if 'Exp' in r['row'] else '-':<11}{r['test']:<13}"
              f"{u['answered']:>4}{u['median_rel']:>8.1%}{k['median_rel']:>8.1%}"
              f"{u['bias']:>9.3f}{k['bias']:>8.2f}{m['eta']['rmse']:>7.2f}")  # fmt: skip
    wall = time.perf_counter() - t_start
    summary = {"machine": machine(), "date": datetime.date.today().isoformat(),
               "args": {k: str(v) for k, v in vars(args).items()},
               "train_seconds": seconds, "rows": results, "wall_seconds": wall}  # fmt: skip
    (args.work / "summary.json").write_text(json.dumps(summary, indent=1, default=float) + "\n")
    print(f"\nExp labels: truth = the bench's simulated parameters; classical = the classical "
          "estimator's (quality ok). test: MD test = the MD test sweep; Exp held-out = the "
          "20 % of bench lines no model trained on; Exp all = every bench line. n = lines "
          f"scored. Wrote {args.work / 'summary.json'} ({wall:.0f} s in all)")  # fmt: skip


if __name__ == "__main__":
    main()
