"""Learning curve of the line model: accuracy and 95 % coverage against training-set size.

Training data: domain-randomised sets (:mod:`stickslip.simulators.randomised`, the
bundled recipe's distribution) of ``--set-size`` trajectories each, seeds ``--seeds``
(no evaluation set uses them), cached under ``--work``; a size of ``n`` trajectories
trains on the first ``n`` rows of their concatenation, so the sets are nested (every
row is an independent draw). Training uses the bundled recipe's settings
(:class:`~stickslip.estimators.line.training.LineTrainConfig` defaults: 3 members, 45
epochs, the detector effects' prior; 10 % of the trajectories, at most 2,000, held out
for the validation and the first calibration) and its expert (``--expert``, the clean pi MLP,
cached in ``--work``). Unlike the bundled model, no typical-substrate or paper-preset
set is added: the size is that of one randomised set.

``--family-sizes`` also trains, at those sizes, with the effect families in the training
batches (``LineTrainConfig.families``: the broad nuisance prior, ``"train"``
implementation, on a ``--family-fraction`` of the non-pristine lines);
``--lofo-family-sizes`` the same with the held-out family (``--held-out``) left out of
that prior, so that it is held out of training too, not only of the calibration.

Every model is then calibrated on the effect families exactly as the bundled model is
(:func:`~stickslip.estimators.line.families.calibrate_on_families`, default settings, on
the calibration pool of ``benchmarks/families.py``: 600 trajectories, seed 501, cached
in ``--pools``) and scored through the estimator (``LineEstimator.predict``, as
``stickslip infer``) on lines with 1.5 <= eta <= 40 of:

- ``clean``: the evaluation pool (400 trajectories, seed 601), no effect;
- ``bench``: the lab bench (``--n-bench`` lines per material, cached in ``--bench``);
- ``all families``: the evaluation pool with every family at its documented
  probability, ``"eval"`` implementation (seed 6101);
- ``held-out <f>`` (``--held-out``, default precursor): the evaluation pool with f on
  every line (seed 6200 + index of f), scored after a calibration without f (the
  leave-one-family-out check of ``benchmarks/families.py``).

The bundled model (``src/stickslip/resources/line_model.pt``: a randomised set, a
typical-substrate set and paper-preset lines, with the families; its training size is
read from its file) is scored the same way as a reference point. Models (trained, and
calibrated on the families: ``*_cal.pt``) and their scores are cached in ``--work``
(a score is reused while the model file and the sets are unchanged, whatever the
library's code: delete ``*.scores.json`` to re-score after changing the estimator or
the calibration). Prints the table, writes ``learning_curve.json`` and
``learning_curve.png`` in ``--work``.

Usage: python benchmarks/learning_curve.py [--sizes 250 500 1000] [--family-sizes N ...]
       [--family-fraction 0.5] [--lofo-family-sizes N ...]
       [--seeds 7301 7302 ...] [--set-size 500] [--train-seed S]
       [--expert clean|bundled|none] [--held-out precursor] [--n-bench 200]
       [--work build/learning-curve] [--pools build/families] [--bench build/lab-bench]
       [--threads 1] [--workers 0] [--no-bundled] [--reference PATH] [--train-only]
"""

from __future__ import annotations

import argparse
import copy
import hashlib
import json
import os
import platform
from pathlib import Path

import numpy as np
import torch

from stickslip.estimators.line.estimator import LineEstimator
from stickslip.estimators.line.families import FamilyCalibration, calibrate_on_families
from stickslip.estimators.line.families import draw_family_lines as family_lines
from stickslip.estimators.line.modelfile import (
    BUNDLED,
    line_metadata,
    load_line_model,
    save_line_model,
)
from stickslip.estimators.line.streaming import StreamSettings
from stickslip.estimators.line.training import LineTrainConfig, training_families
from stickslip.estimators.window.modelfile import load_bundled
from stickslip.jobs.evaluate import evaluate, truth_from_traces
from stickslip.jobs.train import BundledRecipe, TrainingData, expert_model, train_line
from stickslip.simulators import effects as fx
from stickslip.simulators.bench import BenchConfig, bench_if_missing, in_eta_window
from stickslip.simulators.randomised import RandomisedConfig, cached_randomised_set
from stickslip.traces.dataset import Dataset, concat_datasets, dataset_traces, load_dataset

ROOT = Path(__file__).resolve().parents[1]
KEYS = ("F_mean_nN", "U0_eV", "K_N_m")
#: Pools and seeds of benchmarks/families.py (calibration, evaluation, "all", "with f").
CAL_POOL, EVAL_POOL = (600, 501), (400, 601)
ALL_SEED, WITH_SEED = 6101, 6200


def set_metrics(estimator: LineEstimator, data: Dataset) -> dict:
    """Errors and 95 % coverage of ``estimator`` on the lines of ``data`` in the eta window."""
    traces = dataset_traces(data)
    table = estimator.predict(traces)
    ok = in_eta_window(data.params["eta"])
    kept = {t.name for t, m in zip(traces, ok, strict=True) if m}
    truth = {k: v for k, v in truth_from_traces(table, traces).items() if k in kept}
    m = evaluate(table, truth).metrics
    return {"n": len(kept), "U0_rel_rmse": m["U0_eV"]["rel_rmse"],
            "K_rel_rmse": m["K_N_m"]["rel_rmse"], "F_rmse_nN": m["F_mean_nN"]["rmse"],
            "coverage95": {k: m[k]["coverage95"] for k in KEYS}}  # fmt: skip


def eval_sets(args: argparse.Namespace) -> tuple[Dataset, dict[str, Dataset]]:
    """The calibration pool and the scored sets (see the module notes)."""
    cal = cached_randomised_set(RandomisedConfig(n=CAL_POOL[0], seed=CAL_POOL[1], chunk=100),
                                args.pools)  # fmt: skip
    pool = cached_randomised_set(RandomisedConfig(n=EVAL_POOL[0], seed=EVAL_POOL[1], chunk=100),
                                 args.pools)  # fmt: skip
    prior = fx.NuisancePrior()
    sets = {"clean": pool}
    if args.n_bench:
        bench = bench_if_missing(BenchConfig(n_per_material=args.n_bench),
                                 args.bench / f"bench_{args.n_bench}.h5")  # fmt: skip
        sets["bench"] = load_dataset(bench)
    sets["all families"] = family_lines(pool, prior, ALL_SEED).data
    f = args.held_out
    sets[f"held-out {f}"] = family_lines(pool, prior.replace(f, p=1.0),
                                         WITH_SEED + fx.FAMILIES.index(f)).data  # fmt: skip
    return cal, sets


def training_data(args: argparse.Namespace, n: int) -> TrainingData:
    """The first ``n`` rows of the randomised sets of ``args.seeds`` (simulated if missing)."""
    need = -(-n // args.set_size)
    if need > len(args.seeds):
        raise SystemExit(f"{n} trajectories need {need} seeds of {args.set_size} (--seeds)")
    parts = [cached_randomised_set(RandomisedConfig(n=args.set_size, seed=s), args.work)
             for s in args.seeds[:need]]  # fmt: skip
    d = concat_datasets(parts, sorted(parts[0].params)) if need > 1 else parts[0]
    sub = Dataset(np.asarray(d.force_nN[:n]), d.x_nm, {k: v[:n] for k, v in d.params.items()},
                  dict(d.attrs))  # fmt: skip
    card = [{"config": p.config_json, "fingerprint": p.fingerprint()} for p in parts]
    return TrainingData(sub, [*card, {"first_rows": n, "fingerprint": sub.fingerprint()}])


def trained(args: argparse.Namespace, n: int, families: bool | str, expert) -> Path:
    """The model of ``n`` trajectories (with the effect families if ``families``; all but
    the held-out one if ``"lofo"``), trained into ``args.work`` unless there already."""
    tag = f"_fam{round(100 * args.family_fraction)}" if families else ""
    without = (args.held_out,) if families == "lofo" else ()
    tag += "".join(f"-no-{f}" for f in without)
    seed = args.seeds[0] if args.train_seed is None else args.train_seed
    tag += f"_s{seed}" if seed != args.seeds[0] else ""
    out = args.work / f"line_{n}{tag}.pt"
    if out.exists():
        return out
    prior = fx.NuisancePrior().without(*without) if families else None
    cfg = LineTrainConfig(seed=seed, families=prior,
                          family_fraction=args.family_fraction)  # fmt: skip
    stream = StreamSettings(num_workers=args.workers)
    report = train_line(training_data(args, n), out, cfg, expert, args.expert, progress=False,
                        stream=stream)  # fmt: skip
    print(f"trained {out.name}: {report['train_seconds']:.0f} s, {report['n_train']} "
          f"training trajectories", flush=True)  # fmt: skip
    return out


def scored(args: argparse.Namespace, model: Path | None, cal: Dataset,
           sets: dict[str, Dataset], name: str | None = None) -> dict:  # fmt: skip
    """Calibrate ``model`` (None: the bundled one) on the families, score it on ``sets``
    (cached beside the model in ``--work`` under ``name``, default the file's stem), and
    save the calibrated model (not for the reference, ``name`` "bundled")."""
    name = name or (model.stem if model else "bundled")
    raw = model.read_bytes() if model else load_bundled(BUNDLED, lambda p: Path(p).read_bytes())
    digest = hashlib.sha256(raw).hexdigest()[:16]
    key = {"model": digest, "sets": sorted(sets), "n_bench": args.n_bench}
    meta = line_metadata(model) if model else load_bundled(BUNDLED, line_metadata)
    prior, _ = training_families(meta["train_config"])
    variant = ("plain" if prior is None else "families" if args.held_out in prior.enabled()
               else f"families without {args.held_out}")  # fmt: skip
    cache = args.work / f"{name}.scores.json"
    if cache.exists() and json.loads(cache.read_text()).get("key") == key:
        return {**json.loads(cache.read_text()), "variant": variant}
    base = load_line_model(model)
    ens = copy.deepcopy(base)
    cal_report = calibrate_on_families(ens, cal, FamilyCalibration())
    est = LineEstimator(ens, name)
    out = {"key": key, "model": name, "train_seconds": meta["metrics"].get("train_seconds"),
           "n_train": meta["metrics"].get("n_train"),
           "variant": variant, "sets": {}}  # fmt: skip
    held = f"held-out {args.held_out}"
    for s, data in sets.items():
        if s != held:
            out["sets"][s] = set_metrics(est, data)
    lofo = copy.deepcopy(base)
    calibrate_on_families(lofo, cal, FamilyCalibration(prior=fx.NuisancePrior().without(
        args.held_out)))  # fmt: skip
    out["sets"][held] = set_metrics(LineEstimator(lofo, name), sets[held])
    if model is not None and name != "bundled":
        save_line_model(ens, args.work / f"{name}_cal.pt", tuple(meta["train_config"]["channels"]),
                        meta["train_config"], meta["dataset"],
                        {**meta["metrics"], "family_calibration": cal_report})  # fmt: skip
    cache.write_text(json.dumps(out, indent=1))
    return out


HEAD = (f"{'model':24s} {'train n':>7s} {'train s':>7s}  {'set':20s} {'n':>4s}  "
        f"{'U0 rel':>6s} {'K rel':>6s} {'<F> nN':>6s}  cov95 <F>   U0     K")  # fmt: skip


def table_rows(r: dict) -> list[str]:
    """Printed rows of one model's scores."""
    n = str(r["n_train"]) if r.get("n_train") else "-"
    secs = f"{r['train_seconds']:.0f}" if r["train_seconds"] else "-"
    label = r["model"]
    rows = []
    for s, m in r["sets"].items():
        cov = "  ".join(f"{m['coverage95'][k]:.3f}" for k in KEYS)
        rows.append(f"{label:24s} {n:>7s} {secs:>7s}  {s:20s} {m['n']:4d}  "
                    f"{m['U0_rel_rmse']:6.1%} {m['K_rel_rmse']:6.1%} {m['F_rmse_nN']:6.3f}  "
                    f"    {cov}")  # fmt: skip
        label, n, secs = "", "", ""
    return rows


def plot(results: list[dict], path: Path) -> None:
    """Errors (top) and 95 % coverage (bottom) against training trajectories, per set."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 3, figsize=(16, 7.5))
    curves = [r for r in results if r["model"] != "bundled"]
    sets = list(results[0]["sets"])
    styles = dict(zip(dict.fromkeys(r["variant"] for r in curves), ("o-", "s--", "^:", "v-."),
                      strict=False))  # fmt: skip
    colours = dict(zip(sets, plt.rcParams["axes.prop_cycle"].by_key()["color"], strict=False))
    panels = [("U0_rel_rmse", "U0 rel. RMSE"), ("K_rel_rmse", "K rel. RMSE"),
              ("F_rmse_nN", "<F> RMSE [nN]")] + [
        (("coverage95", k), f"95 % coverage {k}") for k in KEYS]  # fmt: skip
    for ax, (key, title) in zip(axes.flat, panels, strict=True):

        def value(m: dict, key=key) -> float:
            return m[key[0]][key[1]] if isinstance(key, tuple) else m[key]

        for variant, style in styles.items():
            rs = sorted((r for r in curves if r["variant"] == variant),
                        key=lambda r: r["n_train"])  # fmt: skip
            for s in sets:
                if rs:
                    ax.plot([r["n_train"] for r in rs], [value(r["sets"][s]) for r in rs], style,
                            color=colours[s], mfc="none" if variant != "plain" else None,
                            label=s if variant == "plain" else f"{s} ({variant})")  # fmt: skip
        for r in results:
            if r["model"] == "bundled" and r["n_train"]:
                for s in sets:
                    ax.plot(r["n_train"], value(r["sets"][s]), "*", ms=11, color=colours[s])
        if isinstance(key, tuple):
            ax.axhline(0.95, color="k", lw=0.8)
            ax.axhspan(0.90, 0.98, color="0.9", zorder=0)  # the trust issue's target band
        ax.set_xscale("log")
        ax.set_xlabel("training trajectories (validation share held out)")
        ax.set_title(title)
    handles, labels = axes[0, 0].get_legend_handles_labels()
    # below the panels, so that they keep the figure's whole width
    fig.legend(handles, labels, loc="lower center", ncol=min(len(labels), 4), fontsize=8,
               title="stars: bundled model", title_fontsize=8)  # fmt: skip
    fig.tight_layout(rect=(0, 0.04 + 0.025 * -(-len(labels) // 4), 1, 1))
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--sizes",
        type=int,
        nargs="*",
        default=[250, 500, 1000],
        help="training trajectories (before the validation split; none: score the bundled model)",
    )
    ap.add_argument(
        "--family-sizes",
        type=int,
        nargs="*",
        default=[],
        help="sizes also trained with the effect families in the batches",
    )
    ap.add_argument(
        "--family-fraction",
        type=float,
        default=0.5,
        help="fraction of non-pristine training lines given the families",
    )
    ap.add_argument(
        "--lofo-family-sizes",
        type=int,
        nargs="*",
        default=[],
        help="sizes also trained with the families but without the held-out one",
    )
    ap.add_argument("--seeds", type=int, nargs="+", default=list(range(7301, 7317)))
    ap.add_argument(
        "--train-seed",
        type=int,
        default=None,
        help="seed of the split, the optimiser and the batches (default: the first data seed)",
    )
    ap.add_argument("--set-size", type=int, default=500, help="trajectories per seed")
    ap.add_argument("--expert", default="clean", help="clean, bundled, none, or a file")
    ap.add_argument(
        "--held-out",
        default="precursor",
        choices=fx.FAMILIES,
        help="family left out of the calibration and scored on",
    )
    ap.add_argument("--n-bench", type=int, default=200, help="bench lines per material (0: none)")
    ap.add_argument("--work", type=Path, default=ROOT / "build" / "learning-curve")
    ap.add_argument(
        "--pools",
        type=Path,
        default=ROOT / "build" / "families",
        help="where the calibration and evaluation pools are cached",
    )
    ap.add_argument("--bench", type=Path, default=ROOT / "build" / "lab-bench")
    ap.add_argument("--threads", type=int, default=1, help="torch threads")
    ap.add_argument("--workers", type=int, default=0, help="training batch loader workers")
    ap.add_argument("--no-bundled", action="store_true", help="do not score the bundled model")
    ap.add_argument("--reference", type=Path, default=None,
                    help="line model file scored as the reference point (stars) in place of "
                         "the bundled one (e.g. a copy of an earlier bundled model)")
    ap.add_argument("--train-only", action="store_true", help="train (cache) models, no scores")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    for d in (args.work, args.pools, args.bench):
        d.mkdir(parents=True, exist_ok=True)
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"{platform.system()}, python {platform.python_version()}, torch "
          f"{torch.__version__}; torch threads {args.threads}, NUMBA_NUM_THREADS "
          f"{os.environ.get('NUMBA_NUM_THREADS', 'unset')}", flush=True)  # fmt: skip
    expert = expert_model(args.expert, args.work, BundledRecipe())
    runs = [(n, False) for n in args.sizes] + [(n, True) for n in args.family_sizes]
    runs += [(n, "lofo") for n in args.lofo_family_sizes]
    models = [trained(args, n, fam, expert) for n, fam in runs]
    if args.train_only:
        return
    cal, sets = eval_sets(args)
    results = [] if args.no_bundled else [scored(args, args.reference, cal, sets, "bundled")]
    results += [scored(args, m, cal, sets) for m in models]
    print(HEAD)
    for r in results:
        print("\n".join(table_rows(r)))
    (args.work / "learning_curve.json").write_text(json.dumps(results, indent=1))
    plot(results, args.work / "learning_curve.png")
    print(f"wrote {args.work / 'learning_curve.json'} and {args.work / 'learning_curve.png'}")
    for m in models:
        cal_file = args.work / f"{m.stem}_cal.pt"
        print(f"{cal_file}: {cal_file.stat().st_size / 1e6:.2f} MB")


if __name__ == "__main__":
    main()
