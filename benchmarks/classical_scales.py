"""The classical estimator from about 5 to 10,000 samples per slip.

Prints, per slice of the real macro recording (paper on paper, 2 kHz, spring 1002 N/m):
samples, slips found, the stick slope k_exp and its error against the spring (or the
quality flag that refuses it); per simulated scale (paper preset, 296 K, resampled to
that many samples per lattice spacing, white noise and a linear drift): the fraction
answered ``ok`` and the relative RMSE of K over those; and the machine.

    python benchmarks/classical_scales.py [--noise 0.03] [--seed 3]
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path

import numpy as np

from stickslip.estimators.classical import estimate_array, estimate_trace
from stickslip.estimators.classical import estimator as E
from stickslip.estimators.mapping import resample_to_pixel
from stickslip.simulators.config import PhysicalSettings
from stickslip.simulators.simulate import simulate
from stickslip.units import eta_from, fmax_nN

SHARED_DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
MACRO = SHARED_DATA / "macro-stickslip" / "k1002Nm_v42.mat"
SPRING_N_M = 1002.0
A = 0.246
U0 = np.array([1.0, 2.0, 3.0, 0.8, 1.5, 4.0, 0.6, 5.0])
K = np.array([10.0, 20.0, 15.0, 5.0, 30.0, 40.0, 12.0, 10.0])
SCALES = (5, 10, 20, 100, 1000, 10_000)


def resample(x: np.ndarray, F: np.ndarray, per_a: float) -> tuple[np.ndarray, np.ndarray]:
    """``per_a`` samples per lattice spacing."""
    return resample_to_pixel(x, F, A / per_a)


def real_slices() -> None:
    if not MACRO.is_file():
        print(f"real recording missing: {MACRO}")
        return
    from scipy.io import loadmat

    d = loadmat(MACRO)
    t, fnorm = d["t"].ravel(), d["Fnorm"].ravel()
    x = 42e3 * (t - t[0])  # nm at 42 um/s
    F = fnorm * 0.0307 * 9.81 * 1e9  # nN: the stick slope comes out in N/m
    print(f"real: {MACRO.name}, {x.size} samples, spring {SPRING_N_M:g} N/m")
    slices = [(start, length) for length in (50_000, 100_000, 200_000, 400_000)
              for start in (0, 100_000, 300_000, 500_000) if start + length <= x.size]
    for start, length in [*slices, (0, x.size)]:  # then the whole file
        sl = slice(start, start + length)
        est = estimate_trace(x[sl], F[sl], temperature_K=0)
        err = 100 * (est.k_exp_N_m / SPRING_N_M - 1)
        res = (f"k_exp {est.k_exp_N_m:7.1f} N/m  error {err:+5.1f} %"
               if est.quality == "ok" else f"refused: {est.quality}")  # fmt: skip
        print(f"  start {start:7d}  samples {length:7d}  slips {est.n_slips:4d}  {res}")


def simulated(noise: float, seed: int) -> None:
    s = PhysicalSettings(pixels=4096, length_nm=5.0)
    t0 = time.perf_counter()
    sim = simulate(U0, K, s, seed=seed)
    eta = eta_from(U0, K, A)
    print(f"simulated {U0.size} traces (paper preset, 296 K, eta {eta.min():.1f}..{eta.max():.1f}, "
          f"{s.length_nm:g} nm) in {time.perf_counter() - t0:.1f} s; noise {noise:g} F_max "
          f"per sample, drift F_max/2 over the line")  # fmt: skip
    rng = np.random.default_rng(seed)
    for per_a in SCALES:
        xs, Fs = [], []
        for i in range(U0.size):
            xn, Fn = resample(sim.x_nm, sim.force_nN[i], per_a)
            fm = float(fmax_nN(U0[i], A))
            drift = 0.5 * fm * (xn - xn[0]) / (xn[-1] - xn[0])
            Fn = Fn + rng.normal(0.0, noise * fm, Fn.size) + drift
            xs.append(xn)
            Fs.append(Fn)
        t0 = time.perf_counter()
        est = estimate_array(xs, Fs)
        dt = time.perf_counter() - t0
        ok = est[:, E.STATUS] == 0
        rel = est[ok, E.K_] / K[ok] - 1
        rmse = f"{100 * np.sqrt(np.mean(rel**2)):5.1f} %" if ok.any() else "   --"
        print(f"  {per_a:6d} samples/a ({xs[0].size:7d} samples): answered {ok.sum()}/{ok.size}, "
              f"K relative RMSE {rmse}, slips {est[:, E.N_SLIPS].astype(int).tolist()}, "
              f"{dt:.2f} s")  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--noise", type=float, default=0.03, help="white noise per sample, in F_max")
    ap.add_argument("--seed", type=int, default=3)
    args = ap.parse_args()
    estimate_array(np.arange(512.0), np.zeros((1, 512)))  # compile / load the numba cache
    real_slices()
    simulated(args.noise, args.seed)
    print(f"machine: {platform.platform()}, {platform.processor() or platform.machine()}, "
          f"{os.cpu_count()} cores, python {platform.python_version()}")  # fmt: skip


if __name__ == "__main__":
    main()
