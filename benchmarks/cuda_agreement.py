"""The CUDA backend against the CPU kernel on a real device: how far apart their traces are.

Runs the same trajectories (same seeds, so the same random streams) on the CPU kernel and
on the device in float64 (``cuda``) and float32 (``cuda-float32``), and prints the
largest pixel difference relative to F_max = pi U0 / a for:

- T = 0, three (U0, K) pairs, 0.48 nm at 6e4 nm/s with slips in the window;
- the same with the augmented substrate (barrier modulation and two defects);
- 296 K, eight trajectories of one (U0, K), same seeds: at finite T a rounding
  difference can send a thermally activated slip the other way, so this is also
  given as the difference of the mean force and of the slip count;
- the paper preset at 296 K (11 nm at 60 nm/s, a whole line) on ``--n-paper``
  trajectories of the default sweep.

``tests/simulators/test_cuda.py`` holds the first three to their tolerances on numba's
CUDA simulator; this script is the same comparison on the hardware. Without a device it
says so and exits 0.

Usage: python benchmarks/cuda_agreement.py [--n-paper 64]   (0: skip the paper preset)
"""

from __future__ import annotations

import argparse

import numpy as np
from simulate import machine

from stickslip.simulators import PhysicalSettings, SweepConfig, simulate
from stickslip.simulators.cuda import cuda_available, device_name
from stickslip.simulators.sweep import sweep_table
from stickslip.units import fmax_nN

BACKENDS = ("cpu", "cuda", "cuda-float32")


def _short(temperature_K: float) -> PhysicalSettings:
    return PhysicalSettings(velocity_nm_per_s=6e4, temperature_K=temperature_K, length_nm=0.48,
                            pixels=16, warmup_nm=0.3)  # fmt: skip


def _substrate(n: int):
    mod = (np.full(n, 0.3), np.full(n, 5.0), np.full(n, 0.7))
    dfx = (np.tile([0.45, 0.62], (n, 1)), np.tile([0.3, -0.25], (n, 1)),
           np.tile([0.1, 0.15], (n, 1)))  # fmt: skip
    return mod, dfx


def _report(name: str, runs: dict[str, np.ndarray], fmax: np.ndarray) -> None:
    cpu = runs["cpu"]
    drop = 0.25 * fmax[:, None]
    slips = {b: int((-np.diff(F, axis=1) > drop).sum()) for b, F in runs.items()}
    for b in BACKENDS[1:]:
        d = np.abs(runs[b] - cpu).max(axis=1) / fmax
        dm = np.abs(runs[b].mean(axis=1) - cpu.mean(axis=1)) / fmax
        print(f"  {name:28s} {b:13s} largest |dF| / F_max {d.max():.2g}; mean force "
              f"{dm.max():.2g}; slips {slips[b]} (cpu {slips['cpu']})")  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n-paper", type=int, default=64)
    args = ap.parse_args()
    if not cuda_available():
        print("no CUDA device on this machine; nothing compared")
        return
    print(f"device: {device_name()}; host: {machine()}")
    U0, K = np.array([1.0, 2.0, 3.0]), np.array([10.0, 20.0, 30.0])
    fm = fmax_nN(U0, 0.246)
    mod, dfx = _substrate(3)
    for name, extra in (("T = 0", {}), ("T = 0, modulation + defects",
                                       {"modulation": mod, "defects": dfx})):  # fmt: skip
        runs = {b: simulate(U0, K, _short(0.0), seed=5, backend=b, **extra).force_nN
                for b in BACKENDS}  # fmt: skip
        _report(name, runs, fm)
    u, k = np.full(8, 1.0), np.full(8, 10.0)
    runs = {b: simulate(u, k, _short(296.0), seed=9, backend=b).force_nN for b in BACKENDS}
    _report("296 K, same seeds", runs, fmax_nN(u, 0.246))

    if args.n_paper < 1:
        return
    cfg = SweepConfig(n=args.n_paper, seed=0)
    t = sweep_table(cfg)
    runs = {b: simulate(t["U0_eV"], t["K_N_m"], cfg.physics, seed=cfg.seed, backend=b,
                        lattice_nm=t["lattice_nm"]).force_nN
            for b in BACKENDS}  # fmt: skip
    _report(f"paper preset, {args.n_paper} lines", runs, fmax_nN(t["U0_eV"], t["lattice_nm"]))


if __name__ == "__main__":
    main()
