"""Accuracy and speed of the classical estimator on simulated paper-preset traces.

Prints the median and 95th-percentile relative errors of U0, K and eta (traces with
1.5 <= eta <= 40 of the default range, 296 K), clean and with 0.05 nN white noise per
pixel, writes a parity plot, and measures traces/s on 512-pixel traces.

    python benchmarks/classical.py [--n 300] [--seed 1] [--out classical_parity.png]
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np

from stickslip.diagnostics.plots_classical import parity_plot
from stickslip.estimators.classical import estimate_array
from stickslip.estimators.classical import estimator as E
from stickslip.simulators.bench import in_eta_window
from stickslip.simulators.config import PhysicalSettings
from stickslip.simulators.simulate import simulate
from stickslip.units import eta_from


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=300)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--noise", type=float, default=0.05)
    ap.add_argument("--out", default="classical_parity.png")
    args = ap.parse_args()
    s = PhysicalSettings()
    rng = np.random.default_rng(args.seed)
    U, K = rng.uniform(0.3, 6.0, 30 * args.n), rng.uniform(1.0, 50.0, 30 * args.n)
    e = eta_from(U, K, s.lattice_nm)
    keep = in_eta_window(e)
    U, K, eta = U[keep][: args.n], K[keep][: args.n], e[keep][: args.n]
    t0 = time.perf_counter()
    sim = simulate(U, K, s, seed=args.seed)
    print(f"simulated {U.size} paper-preset traces (296 K) in {time.perf_counter() - t0:.1f} s")
    truths = {"U0_eV": U, "K_N_m": K, "eta": eta}
    estimate_array(sim.x_nm, sim.force_nN[:2])  # compile / load the numba cache
    for label, noise in (("clean", 0.0), (f"noise {args.noise:g} nN", args.noise)):
        F = sim.force_nN + np.random.default_rng(7).normal(0.0, noise, sim.force_nN.shape)
        est = estimate_array(sim.x_nm, F, s.lattice_nm, s.temperature_K, s.velocity_nm_per_s)
        ok = est[:, E.STATUS] == 0
        print(f"{label}: {ok.sum()}/{ok.size} labelled ok")
        got = {"U0_eV": est[:, E.U0], "K_N_m": est[:, E.K_], "eta": est[:, E.ETA]}
        for name in truths:
            rel = np.abs(got[name][ok] / truths[name][ok] - 1)
            print(f"  {name:6s} median {100 * np.median(rel):5.2f} %   "
                  f"95th percentile {100 * np.percentile(rel, 95):5.2f} %")  # fmt: skip
        if noise == 0.0:
            parity_plot(args.out, truths, got, "classical estimator, paper preset, 296 K")
            print(f"  parity plot: {args.out}")
    reps = max(1, 4000 // U.size)
    F = np.tile(sim.force_nN, (reps, 1))
    t0 = time.perf_counter()
    estimate_array(sim.x_nm, F)
    dt = time.perf_counter() - t0
    print(f"speed: {F.shape[0] / dt:.0f} traces/s ({F.shape[0]} traces of {F.shape[1]} pixels)")
    print(f"machine: {platform.platform()}, {platform.processor() or platform.machine()}, "
          f"{os.cpu_count()} cores, python {platform.python_version()}")  # fmt: skip


if __name__ == "__main__":
    main()
