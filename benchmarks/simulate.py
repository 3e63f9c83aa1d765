"""Simulator speed: particle-steps/s, wall time of the paper dataset, peak memory.

Usage: python benchmarks/simulate.py [--n 1600] [--threads N] [--backend cpu|cuda|cuda-float32]
                                    [--gpu-n 100000]

With --backend cuda: the device name, the kernel rate on --gpu-n trajectories and the
paper dataset's wall time on the GPU; without a CUDA device it says so and exits 0.

The paper dataset is the default sweep (1600 trajectories of the paper preset: 11 nm
recorded at 60 nm/s after a warm-up of max(1 nm, F_max/K + 4a), dt = 10 ns), written to a
temporary HDF5 file exactly as `stickslip simulate --preset paper --n 1600` does.
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import tempfile
import time

import numba
import numpy as np
from _machine import cpu_model


def machine() -> str:
    return (f"{cpu_model()}, {os.cpu_count()} cores, {platform.system()} {platform.machine()}, "
            f"Python {platform.python_version()}, numba {numba.__version__}, "
            f"numba threads {numba.get_num_threads()}")  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1600)
    ap.add_argument("--threads", type=int, default=None)
    ap.add_argument("--backend", default="cpu", choices=["cpu", "cuda", "cuda-float32"])
    ap.add_argument("--gpu-n", type=int, default=100_000, help="trajectories for the GPU rate")
    args = ap.parse_args()
    if args.backend != "cpu":
        return bench_gpu(args.backend, args.n, args.gpu_n)
    if args.threads:
        numba.set_num_threads(args.threads)

    from stickslip.simulators import PhysicalSettings, SweepConfig, simulate

    print(f"machine: {machine()}")
    t0 = time.perf_counter()
    simulate([1.0], [10.0], PhysicalSettings(length_nm=0.05, pixels=8))
    print(f"first call (numba compile or cache load): {time.perf_counter() - t0:.2f} s")

    # kernel rate on uniform lanes
    n, s = 256, PhysicalSettings(length_nm=2.0, pixels=64, warmup_nm=1.0)
    t0 = time.perf_counter()
    simulate(np.full(n, 2.0), np.full(n, 10.0), s)
    dt = time.perf_counter() - t0
    steps = n * 3.0 / (s.velocity_nm_per_s * s.dt_s)
    print(f"kernel, {n} trajectories x {steps / n:.3g} steps: {steps / dt:.3g} particle-steps/s")

    # numpy reference for comparison (short run)
    n_ref, s_ref = 256, PhysicalSettings(length_nm=0.02, pixels=8, warmup_nm=0.0)
    t0 = time.perf_counter()
    simulate(np.full(n_ref, 2.0), np.full(n_ref, 10.0), s_ref, backend="numpy")
    dt = time.perf_counter() - t0
    steps = n_ref * 0.02 / (s_ref.velocity_nm_per_s * s_ref.dt_s)
    print(f"numpy reference (vectorised over trajectories): {steps / dt:.3g} particle-steps/s")

    cfg = SweepConfig(n=args.n, seed=0)
    ph = cfg.physics
    total_steps, travel, wall = time_sweep(cfg)
    print(f"paper dataset: {args.n} trajectories, {total_steps:.3g} particle-steps "
          f"(mean travel {travel:.2f} nm incl. warm-up)")  # fmt: skip
    print(f"paper dataset wall time: {wall:.1f} s  ->  {total_steps / wall:.3g} particle-steps/s")
    equiv = args.n * 12.0 / (ph.velocity_nm_per_s * ph.dt_s)
    print(f"  (12 nm per trajectory, {equiv:.3g} particle-steps, would take "
          f"{equiv / (total_steps / wall):.1f} s at this rate)")  # fmt: skip
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"peak memory (max RSS): {peak:.0f} MiB")


def time_sweep(cfg) -> tuple[float, float, float]:
    """Run the sweep ``cfg`` into a temporary file: its particle-steps, its trajectories'
    mean travel (nm, warm-up included) and the wall time (s)."""
    from stickslip.simulators import run_sweep
    from stickslip.simulators.config import warmup_nm_for
    from stickslip.simulators.sweep import sweep_table

    table = sweep_table(cfg)
    ph = cfg.physics
    warm = warmup_nm_for(table["U0_eV"], table["K_N_m"], table["lattice_nm"], ph.warmup_nm)
    total_steps = float(np.sum((warm + ph.length_nm) / (ph.velocity_nm_per_s * ph.dt_s)))
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        run_sweep(cfg, os.path.join(tmp, "sweep.h5"), progress=False)
        wall = time.perf_counter() - t0
    return total_steps, float(np.mean(warm) + ph.length_nm), wall


def bench_gpu(backend: str, n_paper: int, n_rate: int) -> None:
    """Kernel rate and the paper dataset's wall time on the CUDA device."""
    from numba.core import config as numba_config

    from stickslip.simulators import PhysicalSettings, SweepConfig, simulate
    from stickslip.simulators.cuda import cuda_available, device_name

    if numba_config.ENABLE_CUDASIM:
        print(f"backend {backend}: the CUDA simulator is on; it is not a device, nothing timed")
        return
    if not cuda_available():
        print(f"backend {backend}: no CUDA device on this machine; nothing measured")
        return
    print(f"device: {device_name()}, backend {backend}; host: {machine()}")
    t0 = time.perf_counter()
    simulate([1.0], [10.0], PhysicalSettings(length_nm=0.05, pixels=8), backend=backend)
    print(f"first call (kernel compile): {time.perf_counter() - t0:.2f} s")

    # kernel rate on uniform lanes: 1 nm of support travel each (1.67e6 steps)
    s = PhysicalSettings(length_nm=0.5, pixels=16, warmup_nm=0.5)
    steps = n_rate * 1.0 / (s.velocity_nm_per_s * s.dt_s)
    t0 = time.perf_counter()
    simulate(np.full(n_rate, 2.0), np.full(n_rate, 10.0), s, backend=backend)
    dt = time.perf_counter() - t0
    print(f"kernel, {n_rate} trajectories x {steps / n_rate:.3g} steps: {dt:.2f} s, "
          f"{steps / dt:.3g} particle-steps/s")  # fmt: skip

    total_steps, _, wall = time_sweep(SweepConfig(n=n_paper, seed=0, backend=backend))
    print(f"paper dataset: {n_paper} trajectories, {total_steps:.3g} particle-steps")
    print(f"paper dataset wall time: {wall:.1f} s  ->  {total_steps / wall:.3g} particle-steps/s")


if __name__ == "__main__":
    main()
