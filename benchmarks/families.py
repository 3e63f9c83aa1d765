"""Interval coverage on lines that carry the effect families, and leave-one-family-out.

How the sets are made (independently of training and of each other):

- two pools of clean randomised trajectories (the line model's training distribution,
  :mod:`stickslip.simulators.randomised`), cached under ``--work``: calibration
  (``--n-cal`` trajectories, seed 501) and evaluation (``--n-eval``, seed 601); no
  training set uses these seeds;
- calibration lines: ``--draws`` draws per calibration trajectory of the nuisance
  prior (:mod:`stickslip.simulators.effects`) with the ``"train"`` implementation of
  every family (seed 5101), each line's constant offset then drawn afresh from the
  documented offset prior (:func:`~stickslip.estimators.line.families.restate_offsets`,
  in every calibration, leave-one-family-out included); with ``--contacts N`` (default
  :data:`BUNDLED_CONTACTS`), the multi-asperity lines of ``contact_set(320, "multi",
  5111)``, ``contact_set(320, "multi", 5112)``, ... that one PT describes join the
  calibration trajectories, their truth the effective PT
  (:func:`~stickslip.estimators.line.families.contact_lines`);
- evaluation sets, all with the ``"eval"`` implementations (other functional forms
  over the same documented ranges), one draw per evaluation trajectory: ``clean`` (no
  effect), ``all`` (every family at its documented probability, seed 6101) and, per
  family f, ``with f`` (the same prior with f on every line, seed 6200 + index of f);
- trace/retrace pairs (seed 6401): per evaluation trajectory a trace and a retrace row
  with the same crosstalk term (its sign flipped on the retrace row, as the map readers
  store it) and every other family drawn per direction; scored as single rows and as
  the pair's ``friction_pair_nN`` (:mod:`stickslip.estimators.pairs`); once with every
  family, once lab-like (the lab bench's detector effects and the crosstalk only,
  :func:`lab_prior`).

Calibrations compared:

- ``shipped``: the model's calibration as loaded (for the bundled model: the
  ``families`` calibration below, written with ``--write``);
- ``families``: :func:`stickslip.estimators.line.families.calibrate_on_families` on the
  calibration lines, every family in the prior (``--calibrate-on f ...``: only those
  families; ``--calibrate-on`` with none: no family, the members' training effects
  alone, a careful measurement's prior);
- ``LOFO``: the same without family f (:meth:`NuisancePrior.without`), scored on
  ``with f``: an effect the calibration never saw.

Printed before the families' table: the in-sample U0 and K coverage of the calibration
lines that carry each family (``"train"`` implementations; <F> is left out there, its
interval's offset and compression terms being added after that calibration).

Every set is scored through the estimator (``LineEstimator.predict``, the in/out-of-domain
verdict and its widening included, as ``stickslip infer`` does) and
:func:`stickslip.jobs.evaluate.evaluate`, on lines with 1.5 <= eta <= 40. Printed per
set: 95 % coverage of <F>, U0, K, eta (binomial se about 0.011 at 0.95 on 380 lines),
U0 and K relative RMSE, <F> RMSE, and the fraction in domain.

``--write PATH`` saves the model calibrated on every family (the bundled model's
calibration is made this way: ``--write src/stickslip/resources/line_model.pt``).

``--eval-seed S`` (default 601) evaluates on another pool, with every evaluation draw's
seed moved by 1000 (S - 601): a second evaluation independent of the first. ``--only f
...`` limits the "with f" sets and leave-one-family-out to those families.

Usage: python benchmarks/families.py [--work build/families] [--n-cal 600] [--n-eval 400]
       [--draws 4] [--n-bench 120] [--line-model PATH] [--no-lofo] [--write PATH]
       [--threads 2] [--eval-seed 601] [--only FAMILY ...] [--no-pairs]
       [--calibrate-on [FAMILY ...]]
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import json
import platform
from pathlib import Path

import numpy as np
import torch

from stickslip.atomic import write_text_atomic
from stickslip.estimators.line.estimator import LineEstimator
from stickslip.estimators.line.families import (
    FamilyCalibration,
    calibrate_on_families,
    contact_lines,
    draw_family_lines,
)
from stickslip.estimators.line.modelfile import (
    BUNDLED,
    line_metadata,
    load_line_model,
    save_line_model,
)
from stickslip.estimators.pairs import pair_friction, pair_parameters
from stickslip.estimators.table import TARGETS, domain_verdict, has_estimate
from stickslip.estimators.window.modelfile import load_bundled
from stickslip.jobs.evaluate import evaluate, truth_from_traces
from stickslip.jobs.train import BundledRecipe
from stickslip.simulators import effects as fx
from stickslip.simulators.bench import (
    BENCH_SEED,
    MATERIALS,
    BenchConfig,
    bench_if_missing,
    in_eta_window,
)
from stickslip.simulators.instrument import LAB
from stickslip.simulators.randomised import RandomisedConfig, cached_randomised_set
from stickslip.traces.dataset import Dataset, dataset_traces, load_dataset

ROOT = Path(__file__).resolve().parents[1]
KEYS = TARGETS  # <F>, U0, K, eta
CAL_SEED, EVAL_SEED = 501, 601
#: multi-asperity lines drawn for the bundled model's calibration (issue 40): those one
#: PT describes join the calibration trajectories (FamilyCalibration.contacts)
BUNDLED_CONTACTS = 640
CAL_DRAW_SEED, ALL_SEED, WITH_SEED, PAIR_SEED = 5101, 6101, 6200, 6401


def score(estimator: LineEstimator, data: Dataset) -> dict:
    """Coverage, errors and in-domain fraction of ``estimator`` on one set."""
    traces = dataset_traces(data)
    table = estimator.predict(traces)
    truth = truth_from_traces(table, traces)
    ok = in_eta_window(data.params["eta"])
    names = [t.name for t, m in zip(traces, ok, strict=True) if m]
    m = evaluate(table, {n: truth[n] for n in names}).metrics
    rows = {r["trace"]: r for r in table.rows}
    inside = [n for n in names if domain_verdict(rows[n]) is True]
    # the rows in domain alone: the out-of-domain rows' intervals are widened on purpose
    m_in = evaluate(table, {n: truth[n] for n in inside}).metrics if inside else None
    return {"n": len(names), "coverage95": {k: m[k]["coverage95"] for k in KEYS},
            "coverage68": {k: m[k]["coverage68"] for k in KEYS},
            "U0_rel_rmse": m["U0_eV"]["rel_rmse"], "K_rel_rmse": m["K_N_m"]["rel_rmse"],
            "F_rmse_nN": m["F_mean_nN"]["rmse"], "in_domain": len(inside) / len(names),
            "n_in_domain": len(inside),
            "interval_score95": {k: m[k].get("interval_score95") for k in KEYS},
            "rel_halfwidth95": {k: m[k].get("rel_halfwidth95") for k in KEYS},
            "sharpness95": {k: m[k].get("sharpness95") for k in KEYS},
            "coverage95_in_domain": {k: m_in[k]["coverage95"] if m_in else None
                                     for k in KEYS}}  # fmt: skip


def line(name: str, r: dict) -> str:
    cov = " ".join(f"{r['coverage95'][k]:.3f}" for k in KEYS)
    sharp = " ".join(f"{r['sharpness95'][k]:5.2f}" for k in ("U0_eV", "K_N_m"))
    return (f"  {name:26s} {r['n']:4d}  {cov}   {r['U0_rel_rmse']:6.2%} {r['K_rel_rmse']:6.2%} "
            f"{r['F_rmse_nN']:.3f}  {r['in_domain']:.2f}  {sharp}")  # fmt: skip


def pair_rows(pool: Dataset, prior: fx.NuisancePrior, seed: int) -> tuple[Dataset, Dataset]:
    """Trace and retrace rows of every evaluation trajectory with a crosstalk term on
    both: the same term, entering the retrace row (read sign-flipped, as the map readers
    store it) with the opposite sign; every other family drawn independently per
    direction (``"eval"`` implementation). <F> truths: each row's contact force mean."""
    prior = prior.replace("crosstalk", p=1.0)
    x, clean = pool.x_nm, np.asarray(pool.force_nN, float)
    v = pool.params["velocity_nm_per_s"]
    out = []
    rng = np.random.default_rng([seed, 0])
    term = fx.crosstalk_term(fx.draw(prior, pool.n, rng, "eval"), x, rng)
    for k, sign in ((1, 1.0), (2, -1.0)):
        rng = np.random.default_rng([seed, k])
        d = fx.draw(prior, pool.n, rng, "eval")
        force, said = fx.apply(d, x, clean, v, rng, crosstalk_nN=sign * term)
        params = {**pool.params, "velocity_nm_per_s": said.velocity_nm_per_s,
                  "F_mean_nN": fx.contact_force(d, clean).mean(axis=1)}  # fmt: skip
        out.append(Dataset(force, x, params, pool.attrs))
    return out[0], out[1]


def lab_prior(prior: fx.NuisancePrior) -> fx.NuisancePrior:
    """Lab-like lines: the lab bench's detector effects (:data:`~stickslip.simulators.
    instrument.LAB`) on every line and no other family (crosstalk is added by
    :func:`pair_rows`)."""
    lab = fx.Detector.from_effects(LAB, p=1.0)
    return dataclasses.replace(prior.only("detector", "crosstalk"), detector=lab)


def score_pairs(estimator: LineEstimator, trace: Dataset, retrace: Dataset) -> dict:
    """<F> of single rows and of the pairs (:func:`stickslip.estimators.pairs.pair_friction`)
    against their truths, and U0 and K of single rows and of the pairs
    (:func:`~stickslip.estimators.pairs.pair_parameters`), on trajectories in the eta
    window."""
    ok = in_eta_window(trace.params["eta"])
    rows = [estimator.predict(dataset_traces(d)).rows for d in (trace, retrace)]
    truth = 0.5 * (trace.params["F_mean_nN"] + retrace.params["F_mean_nN"])
    single, pair, covered = [], [], []
    logs: dict[str, list] = {k: [[], [], [], []] for k in ("U0", "K")}  # single, pair, covs
    refused = 0
    for i in np.flatnonzero(ok):
        rt, rr = rows[0][i], rows[1][i]
        if not (has_estimate(rt) and has_estimate(rr)):  # a refusal has no numbers to score
            refused += 1
            continue
        single += [rt["F_mean_nN"] - trace.params["F_mean_nN"][i],
                   rr["F_mean_nN"] - retrace.params["F_mean_nN"][i]]  # fmt: skip
        cols = pair_friction(rt, rr)
        pair.append(cols["friction_pair_nN"] - truth[i])
        covered.append(cols["friction_pair_nN_lo95"] <= truth[i] <= cols["friction_pair_nN_hi95"])
        params = pair_parameters(rt, rr)
        for k, key, name in (("U0", "U0_eV", "U0_pair_eV"), ("K", "K_N_m", "K_pair_N_m")):
            t = trace.params[key][i]
            s_err, p_err, s_cov, p_cov = logs[k]
            s_err += [np.log(rt[key] / t), np.log(rr[key] / t)]
            s_cov += [r[f"{key}_lo95"] <= t <= r[f"{key}_hi95"] for r in (rt, rr)]
            p_err.append(np.log(params[name] / t))
            p_cov.append(params[f"{name}_lo95"] <= t <= params[f"{name}_hi95"])
    out = {"n_pairs": int(ok.sum()) - refused, "refused_pairs": refused,
           "single_rmse_nN": float(np.sqrt(np.mean(np.square(single)))),
           "pair_rmse_nN": float(np.sqrt(np.mean(np.square(pair)))),
           "pair_coverage95": float(np.mean(covered))}  # fmt: skip
    for k, (s_err, p_err, s_cov, p_cov) in logs.items():
        out[f"{k}_single_rel_rmse"] = float(np.sqrt(np.mean(np.square(s_err))))
        out[f"{k}_pair_rel_rmse"] = float(np.sqrt(np.mean(np.square(p_err))))
        out[f"{k}_single_coverage95"] = float(np.mean(s_cov))
        out[f"{k}_pair_coverage95"] = float(np.mean(p_cov))
    return out


HEAD = (f"  {'set':26s} {'n':>4s}  95 % cov <F>  U0    K     eta     U0 rel  K rel  <F> nN  in dom"
        "  sharpness U0 K")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", type=Path, default=ROOT / "build" / "families")
    ap.add_argument("--n-cal", type=int, default=600)
    ap.add_argument("--n-eval", type=int, default=400)
    ap.add_argument("--draws", type=int, default=FamilyCalibration.draws)
    ap.add_argument("--training-draws", type=int, default=FamilyCalibration.training_draws,
                    help="draws of the members' own training effects mixed into calibration")
    ap.add_argument("--line-model", type=Path, default=None, help="default: the bundled one")
    ap.add_argument("--no-lofo", action="store_true", help="skip leave-one-family-out")
    ap.add_argument("--write", type=Path, default=None,
                    help="save the model calibrated on every family here")
    ap.add_argument("--contacts", type=int, default=BUNDLED_CONTACTS,
                    help="multi-asperity lines drawn for the calibration (those one PT "
                         "describes kept; 0: none)")  # fmt: skip
    ap.add_argument("--n-bench", type=int, default=120,
                    help="lab-bench lines per material (0: no bench)")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--eval-seed", type=int, default=EVAL_SEED,
                    help="seed of the evaluation pool; another one also moves every "
                         "evaluation draw's seed (a second, independent evaluation)")  # fmt: skip
    ap.add_argument("--only", nargs="+", choices=fx.FAMILIES, default=None,
                    help="the 'with f' sets and leave-one-family-out for these families only")
    ap.add_argument("--no-pairs", action="store_true", help="skip the trace/retrace pairs")
    ap.add_argument("--calibrate-on", nargs="*", choices=fx.FAMILIES, default=None,
                    metavar="FAMILY",
                    help="the families the calibration's prior holds (default: every one; "
                         "none named: no family, so that the members' training effects "
                         "alone size the intervals)")  # fmt: skip
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    # evaluation draws: the documented seeds for the documented pool, others beside them
    shift = 1000 * (args.eval_seed - EVAL_SEED)
    all_seed, with_seed, pair_seed = ALL_SEED + shift, WITH_SEED + shift, PAIR_SEED + shift
    families = args.only or list(fx.FAMILIES)
    args.work.mkdir(parents=True, exist_ok=True)
    print(f"machine: {platform.processor() or platform.machine()}, {platform.system()}, "
          f"python {platform.python_version()}; torch threads {args.threads}")  # fmt: skip
    # the pools follow the training prior: its dynamics and acquisition where it has them
    pool = BundledRecipe().prior
    cal_pool = cached_randomised_set(pool(RandomisedConfig(n=args.n_cal, seed=CAL_SEED)),
                                     args.work)  # fmt: skip
    eval_pool = cached_randomised_set(pool(RandomisedConfig(n=args.n_eval, seed=args.eval_seed)),
                                      args.work)  # fmt: skip
    contacts = None
    if args.contacts:
        contacts = contact_lines(FamilyCalibration(contacts=args.contacts), args.work)
    prior = fx.NuisancePrior()
    sets = {"clean": eval_pool,
            "all families": draw_family_lines(eval_pool, prior, all_seed).data}  # fmt: skip
    for j, f in enumerate(fx.FAMILIES):
        if f in families:
            sets[f"with {f}"] = draw_family_lines(eval_pool, prior.replace(f, p=1.0),
                                                  with_seed + j).data  # fmt: skip
    if args.n_bench:
        # the lab bench (older lab effects, three materials) with a seed of its own
        cfg = BenchConfig(n_per_material=args.n_bench, seed=BENCH_SEED + 3)
        bench = load_dataset(bench_if_missing(cfg, args.work / f"bench_{cfg.n_per_material}_"
                                                               f"{cfg.seed}.h5"))  # fmt: skip
        for m, mat in enumerate(MATERIALS):
            rows = np.flatnonzero(bench.params["material"] == m)
            sets[f"bench {mat}"] = Dataset(bench.force_nN[rows], bench.x_nm,
                                           {k: v[rows] for k, v in bench.params.items()},
                                           bench.attrs)  # fmt: skip
    shipped = load_line_model(args.line_model)
    source = str(args.line_model or "bundled")
    summary: dict = {"shipped": {}, "families": {}, "lofo": {}}
    for label, ens in (("shipped", shipped), ("families", None)):
        if ens is None:
            ens = copy.deepcopy(shipped)
            cal_prior = prior if args.calibrate_on is None else prior.only(*args.calibrate_on)
            settings = FamilyCalibration(prior=cal_prior, draws=args.draws,
                                         training_draws=args.training_draws,
                                         contacts=args.contacts)  # fmt: skip
            report = calibrate_on_families(ens, cal_pool, settings, contacts)
            families_ens, families_report = ens, report
        if label == "families":
            # in-sample: the calibration lines ("train" implementations) that carry f
            print("\ncalibration lines that carry each family (\"train\" implementations), "
                  "in-sample 95 % coverage U0 / K")  # fmt: skip
            for f, g in report.get("val_per_group", {}).items():
                cov = " ".join(f"{g['coverage95'][k]:.3f}" for k in ("log_U0_ref", "log_K_ref"))
                print(f"  with {f:21s} {g['n']:4d}  {cov}")
            summary["calibration_per_family"] = report.get("val_per_group", {})
        print(f"\ncalibration: {label} ({source})\n{HEAD}")
        est = LineEstimator(ens, source)
        for name, data in sets.items():
            r = score(est, data)
            summary[label][name] = r
            print(line(name, r), flush=True)
    pair_sets = () if args.no_pairs else (("pairs", prior), ("lab_pairs", lab_prior(prior)))
    for name, pair_prior in pair_sets:
        t_rows, r_rows = pair_rows(eval_pool, pair_prior, pair_seed)
        pairs = score_pairs(LineEstimator(families_ens, source), t_rows, r_rows)
        summary[name] = pairs
        what = ("every family" if name == "pairs" else
                "a careful measurement's detector effects (the lab bench's) only")  # fmt: skip
        print(f"\ntrace/retrace pairs with crosstalk on both and {what} (calibrated on the "
              f"families): {pairs['n_pairs']} pairs scored ({pairs['refused_pairs']} with a "
              f"refused row left out); <F> RMSE single rows "
              f"{pairs['single_rmse_nN']:.3f} nN, friction_pair_nN {pairs['pair_rmse_nN']:.3f} "
              f"nN, its 95 % coverage {pairs['pair_coverage95']:.3f}")  # fmt: skip
        for k in ("U0", "K"):
            print(f"  {k}: relative RMSE (of ln) single rows {pairs[f'{k}_single_rel_rmse']:.3f}"
                  f", pair {pairs[f'{k}_pair_rel_rmse']:.3f}; 95 % coverage single rows "
                  f"{pairs[f'{k}_single_coverage95']:.3f}, pair "
                  f"{pairs[f'{k}_pair_coverage95']:.3f}")  # fmt: skip
    if not args.no_lofo:
        print(f"\nleave-one-family-out: calibrated without f, scored on 'with f'\n{HEAD}")
        for f in families:
            ens = copy.deepcopy(shipped)
            calibrate_on_families(ens, cal_pool,
                                  FamilyCalibration(prior=prior.without(f), draws=args.draws,
                                                    training_draws=args.training_draws,
                                                    contacts=args.contacts), contacts)  # fmt: skip
            r = score(LineEstimator(ens, source), sets[f"with {f}"])
            summary["lofo"][f] = r
            print(line(f"with {f}", r), flush=True)
    # one file per evaluation pool, for benchmarks/coverage_band.py to pool them
    summary["eval_seed"] = args.eval_seed
    out = args.work / f"summary_{args.eval_seed}.json"
    write_text_atomic(out, json.dumps(summary, indent=1))
    print(f"\nwrote {out}")
    if args.write is not None:
        meta = (line_metadata(args.line_model) if args.line_model
                else load_bundled(BUNDLED, line_metadata))  # fmt: skip
        metrics = {**meta["metrics"], "family_calibration": families_report}
        save_line_model(families_ens, args.write, tuple(meta["train_config"]["channels"]),
                        meta["train_config"], meta["dataset"], metrics)  # fmt: skip
        print(f"wrote {args.write}")


if __name__ == "__main__":
    main()
