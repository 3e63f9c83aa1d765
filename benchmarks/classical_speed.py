"""Throughput of the classical estimator: lines of 512 pixels and long recordings.

Prints lines per second on simulated paper-preset lines (512 pixels, 296 K, white
noise 0.05 nN) and samples per second on long stick-slip recordings (a sawtooth of
4,000 samples per slip on a wandering baseline, 1e6 samples; and the real macro
recording of shared/data when it is there), each the best of ``--repeat`` runs after
one warm-up call (compilation excluded), with the machine it ran on.

To compare two versions in one sitting, run it from each checkout in turn, e.g.
``git worktree add /tmp/old <commit>`` and
``PYTHONPATH=/tmp/old/src python benchmarks/classical_speed.py``.

    python benchmarks/classical_speed.py [--lines 2000] [--repeat 3] [--threads 2]
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path

import numpy as np

import stickslip
from stickslip.estimators.classical import estimate_array
from stickslip.simulators.config import PhysicalSettings
from stickslip.simulators.simulate import simulate

SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
MACRO = SHARED_DATA / "macro-stickslip" / "k1002Nm_v42.mat"


def best_time(fn, repeat: int) -> float:
    fn()  # compile / warm caches
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def long_sawtooth(n: int, per_slip: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    i = np.arange(n)
    drop = 1.0
    F = drop * (i % per_slip) / per_slip
    F += 3.0 * drop * np.sin(2 * np.pi * i / n * 1.5)  # wander of a few drops
    F += 0.02 * drop * rng.standard_normal(n)
    return i * 1.0, F


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lines", type=int, default=2000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--threads", type=int, default=None)
    args = ap.parse_args()
    print(f"stickslip {stickslip.__version__} from {Path(stickslip.__file__).parent}")
    print(f"machine: {platform.platform()}, {platform.processor() or platform.machine()}, "
          f"{os.cpu_count()} cores, threads={args.threads or 'default'}")
    rng = np.random.default_rng(11)
    n_sim = min(args.lines, 400)
    U, K = rng.uniform(0.5, 4.0, n_sim), rng.uniform(5.0, 40.0, n_sim)
    r = simulate(U, K, PhysicalSettings(), seed=12)
    reps = int(np.ceil(args.lines / n_sim))
    F = np.tile(r.force_nN, (reps, 1))[: args.lines]
    F = F + rng.normal(0.0, 0.05, F.shape)
    t = best_time(lambda: estimate_array(r.x_nm, F, threads=args.threads), args.repeat)
    print(f"lines of 512 px: {F.shape[0] / t:,.0f} lines/s ({F.shape[0]} lines in {t:.3f} s)")
    x, G = long_sawtooth(1_000_000, 4000, 13)
    t = best_time(lambda: estimate_array([x], [G], temperature_K=0.0), args.repeat)
    print(f"long sawtooth, 1e6 samples, 4,000 per slip: {G.size / t:,.0f} samples/s")
    x, G = long_sawtooth(1_000_000, 50, 14)
    t = best_time(lambda: estimate_array([x], [G], temperature_K=0.0), args.repeat)
    print(f"long sawtooth, 1e6 samples, 50 per slip: {G.size / t:,.0f} samples/s")
    if MACRO.is_file():
        from scipy.io import loadmat

        d = loadmat(MACRO)
        tt, fn = d["t"].ravel(), d["Fnorm"].ravel()
        xm, Fm = 42e3 * (tt - tt[0]), fn * 0.0307 * 9.81 * 1e9
        t = best_time(lambda: estimate_array([xm], [Fm], temperature_K=0.0), args.repeat)
        print(f"real macro recording, {Fm.size:,} samples: {Fm.size / t:,.0f} samples/s")


if __name__ == "__main__":
    main()
