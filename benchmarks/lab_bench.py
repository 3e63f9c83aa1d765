"""The laboratory test bench: every estimator on clean simulations and on the bench.

The bench (src/stickslip/evaluation/bench.py) is simulated traces that carry the
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
and reliability plots.

Usage: python benchmarks/lab_bench.py [--work build/lab-bench] [--n-per-material 200]
       [--n-clean 300] [--n-randomised 600] [--line-model PATH] [--epochs 50]
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np

from stickslip.diagnostics.calibration import coverage, reliability, reliability_plot
from stickslip.estimators.classical import estimate_array
from stickslip.estimators.classical import estimator as E
from stickslip.estimators.classical.baseline import five_line_estimate
from stickslip.estimators.line.ensemble import predict_raw_lines
from stickslip.estimators.line.training import LineTrainConfig
from stickslip.estimators.window.inference import predict_traces
from stickslip.jobs.workflow import (
    CLEAN_TEST_SEED,
    LAB_MLP_SEED,
    clean_window_model,
    sweep_if_missing,
)
from stickslip.simulators.bench import MATERIALS, BenchConfig, bench_if_missing, in_eta_window
from stickslip.simulators.instrument import EffectsMixture, InstrumentEffects, apply_instrument
from stickslip.simulators.randomised import RandomisedConfig, cached_randomised_set
from stickslip.traces.dataset import Dataset, load_dataset
from stickslip.traces.trace import Trace

ROOT = Path(__file__).resolve().parents[1]
KEYS = ("F_mean_nN", "U0_eV", "K_N_m")


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


def predictions(ds, line_model, mlps) -> dict[str, dict[str, np.ndarray]]:
    """Each estimator's <F>, U0, K (and intervals for the line model) on a data set."""
    p, F, x = ds.params, ds.force_nN.astype(float), ds.x_nm
    a, v = p["lattice_nm"], p["velocity_nm_per_s"]
    out = {"five-line": five_line_estimate(x, F, a)}
    tab = estimate_array(x, F, a, p["temperature_K"], v)
    out["classical"] = {"F_mean_nN": tab[:, E.F_MEAN], "U0_eV": tab[:, E.U0],
                        "K_N_m": tab[:, E.K_]}  # fmt: skip
    traces = [Trace(x, f, f"t{i}", meta={"lattice_nm": float(ai)})
              for i, (f, ai) in enumerate(zip(F, a, strict=True))]  # fmt: skip
    for name, model in mlps.items():
        est, _ = predict_traces(model, traces)
        out[name] = {k: np.array([e.values[k] for e in est]) for k in KEYS}
    t0 = time.perf_counter()
    lp = predict_raw_lines(line_model, [x] * len(F), list(F), a, v)
    out["line CNN"] = {**lp.values, "_lp": lp, "_seconds": time.perf_counter() - t0}
    return out


def score(truth, pred, mask) -> dict[str, float]:
    r = {"F_rmse": float(np.sqrt(np.nanmean((pred["F_mean_nN"] - truth["F_mean_nN"])[mask] ** 2)))}
    for k in ("U0_eV", "K_N_m"):
        rel = (pred[k] / truth[k] - 1)[mask]
        r[f"{k}_rel_rmse"] = float(np.sqrt(np.nanmean(rel**2)))
        r[f"{k}_rmse"] = float(np.sqrt(np.nanmean((pred[k] - truth[k])[mask] ** 2)))
        r[f"{k}_failed"] = int(np.sum(~np.isfinite(rel)))
    lp = pred.get("_lp")
    if lp is not None:
        for k in ("F_mean_nN", "U0_eV", "K_N_m", "eta"):
            r[f"{k}_cov68"] = coverage(truth[k][mask], lp.lo68[k][mask], lp.hi68[k][mask])
            r[f"{k}_cov95"] = coverage(truth[k][mask], lp.lo95[k][mask], lp.hi95[k][mask])
    return r


def groups(set_name: str, ds, ok: np.ndarray) -> dict[str, np.ndarray]:
    """Masks scored for a data set: the whole set, and each material on the bench."""
    out = {set_name: ok}
    if set_name == "bench":
        for m, mat in enumerate(MATERIALS):
            out[f"bench {mat}"] = ok & (ds.params["material"] == m)
    return out


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

    from stickslip.estimators.line.modelfile import load_line_model

    line_model = load_line_model(args.line_model)
    mlps = {f"MLP {r}": window_model(args.work, r, args.epochs) for r in ("raw", "pi")}
    bench_path = bench_if_missing(BenchConfig(n_per_material=args.n_per_material),
                                  args.work / f"bench_{args.n_per_material}.h5")  # fmt: skip
    clean = sweep_if_missing(args.work / "clean.h5", args.n_clean, CLEAN_TEST_SEED)
    sets = {"clean": load_dataset(clean),
            "bench": load_dataset(bench_path),
            "randomised held-out": randomised_heldout(args.work, args.n_randomised)}  # fmt: skip
    summary: dict = {}
    for set_name, ds in sets.items():
        truth = {k: ds.params[k] for k in ("F_mean_nN", "U0_eV", "K_N_m", "eta")}
        ok = in_eta_window(truth["eta"])
        preds = predictions(ds, line_model, mlps)
        for g, mask in groups(set_name, ds, ok).items():
            print(f"\n{g}: {int(mask.sum())} traces with 1.5 <= eta <= 40")
            print(f"{'estimator':<12}{'<F> RMSE nN':>13}{'U0 rel RMSE':>13}{'K rel RMSE':>12}"
                  f"{'U0 RMSE eV':>12}{'K RMSE N/m':>12}{'cov68 U0/K':>13}{'cov95 U0/K':>13}")
            for est, pred in preds.items():
                s = score(truth, pred, mask)
                summary.setdefault(g, {})[est] = s
                cov = ""
                if "U0_eV_cov68" in s:
                    cov = (f"{s['U0_eV_cov68']:>6.2f}/{s['K_N_m_cov68']:.2f}"
                           f"{s['U0_eV_cov95']:>8.2f}/{s['K_N_m_cov95']:.2f}")  # fmt: skip
                print(f"{est:<12}{s['F_rmse']:>13.4f}{s['U0_eV_rel_rmse']:>13.2%}"
                      f"{s['K_N_m_rel_rmse']:>12.2%}{s['U0_eV_rmse']:>12.3f}{s['K_N_m_rmse']:>12.2f}"
                      f"   {cov}")  # fmt: skip
        lp = preds["line CNN"]["_lp"]
        rate = len(ds.force_nN) / preds["line CNN"]["_seconds"]
        print(f"line CNN inference incl. mapping: {rate:.0f} traces/s")
        curves = {}
        for j, (k, log) in enumerate((("F_mean_nN", False), ("U0_eV", True), ("K_N_m", True),
                                      ("eta", True))):  # fmt: skip
            # the model's own interval shape: calibrated std times z_at(level)
            loc = np.log(lp.values[k]) if log else lp.values[k]
            sig = ((np.log(lp.hi95[k]) if log else lp.hi95[k]) - loc) / line_model.z_at(0.95)[j]
            curves[k] = reliability(truth[k][ok], loc[ok], sig[ok], log,
                                    z_of_level=lambda q, j=j: line_model.z_at(q)[j])  # fmt: skip
        reliability_plot(curves, f"line CNN calibration: {set_name}",
                         args.work / f"calibration_{set_name.replace(' ', '_')}.png")  # fmt: skip
    (args.work / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    print(f"\nwrote {args.work / 'summary.json'} and calibration plots")


if __name__ == "__main__":
    main()
