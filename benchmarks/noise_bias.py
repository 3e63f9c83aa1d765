"""How white detector noise moves the line model's estimates: median error per noise level.

The line model's members read noisy lines stiff: on clean lines of the training prior,
white noise alone moves their median K up by a few per cent. The location calibration
(``LineEnsemble.location``, fitted on the calibration lines by
:func:`stickslip.estimators.line.training.fit_location`) takes that median off. This
benchmark measures it on lines the calibration never read.

The lines: the trajectories of the evaluation pool of ``benchmarks/families.py``
(``--n-eval`` clean randomised trajectories of the training prior, seed 601, cached
under ``--work``; no training or calibration reads this seed) on a plain substrate (no
modulation, no defects), each at every white-noise level of ``--noise`` (Gaussian,
std in nN; noise from ``numpy.random.default_rng([--seed, level index])``). Nothing
else is added, and every stated condition is right. Each line is predicted as a user
calls it (``stickslip.predict``, the in/out-of-domain verdict on); printed per model
and noise level over the rows answered: n, and the median error (est/true - 1) and
relative RMSE of U0, K and eta.

    python benchmarks/noise_bias.py [--model PATH ...] [--work build/families]
           [--noise 0 0.0125 0.025 0.05] [--seed 7301]

``--model`` may be given several times (``bundled`` for the bundled model): the models
are scored on the same lines in one sitting.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from _machine import machine_line

import stickslip
from stickslip.estimators.load import load_estimator
from stickslip.jobs.train import BundledRecipe
from stickslip.simulators.randomised import RandomisedConfig, cached_randomised_set
from stickslip.traces.trace import Trace
from stickslip.units import eta_from

ROOT = Path(__file__).resolve().parents[1]
EVAL_SEED = 601  # benchmarks/families.py's evaluation pool


def noisy_traces(pool, rows: np.ndarray, sigma_nN: float, rng: np.random.Generator
                 ) -> list[Trace]:  # fmt: skip
    """The pool's lines ``rows`` with white noise of std ``sigma_nN``, stating their true
    lattice, velocity and temperature."""
    p = pool.params
    out = []
    for i in rows:
        force = np.asarray(pool.force_nN[i], float)
        meta = {"lattice_nm": float(p["lattice_nm"][i]),
                "velocity_nm_per_s": float(p["velocity_nm_per_s"][i]),
                "temperature_K": float(p["temperature_K"][i])}  # fmt: skip
        noisy = force + sigma_nN * rng.standard_normal(force.size)
        out.append(Trace(x_nm=np.asarray(pool.x_nm, float), force_nN=noisy,
                         name=f"pool{EVAL_SEED}:{i:04d}", source="noise_bias", meta=meta))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--model", action="append", default=None,
                    help="line-model file, or 'bundled' (repeatable; default: bundled)")
    ap.add_argument("--work", type=Path, default=ROOT / "build" / "families")
    ap.add_argument("--n-eval", type=int, default=400)
    ap.add_argument("--noise", type=float, nargs="+", default=[0.0, 0.0125, 0.025, 0.05])
    ap.add_argument("--seed", type=int, default=7301)
    args = ap.parse_args()
    print(machine_line())
    pool = cached_randomised_set(BundledRecipe().prior(RandomisedConfig(n=args.n_eval,
                                                                        seed=EVAL_SEED)),
                                 args.work)  # fmt: skip
    p = pool.params
    plain = np.flatnonzero((np.asarray(p["mod_amplitude"]) == 0)
                           & (np.asarray(p["defect_count"]) == 0))  # fmt: skip
    truth = {"U0_eV": np.asarray(p["U0_eV"], float), "K_N_m": np.asarray(p["K_N_m"], float),
             "eta": eta_from(p["U0_eV"], p["K_N_m"], p["lattice_nm"])}  # fmt: skip
    print(f"{plain.size} plain-substrate lines of pool {EVAL_SEED}, each at white noise "
          f"{', '.join(f'{s:g}' for s in args.noise)} nN (seed {args.seed})")
    for model in args.model or ["bundled"]:
        est = load_estimator(None if model == "bundled" else Path(model))
        print(f"\nmodel: {model}")
        print(f"  {'noise nN':>8s} {'n':>4s}  " + "  ".join(
            f"{k + ' bias':>11s} {k + ' rRMSE':>11s}" for k in truth))  # fmt: skip
        for k, sigma in enumerate(args.noise):
            traces = noisy_traces(pool, plain, sigma, np.random.default_rng([args.seed, k]))
            rows = stickslip.predict(traces, model=est).rows
            ok = np.array([r.get("quality") == "ok" for r in rows])
            cells = []
            for name, t in truth.items():
                ratio = np.array([r[name] for r, o in zip(rows, ok, strict=True) if o]) \
                    / t[plain[ok]]
                cells.append(f"{100 * (np.median(ratio) - 1):+10.2f}% "
                             f"{100 * np.sqrt(np.mean((ratio - 1) ** 2)):10.2f}%")  # fmt: skip
            print(f"  {sigma:8.4f} {int(ok.sum()):4d}  " + "  ".join(cells))


if __name__ == "__main__":
    main()
