"""Overhead of a sharded Dask sweep: the paper dataset single-process vs ``--dask local``.

Usage: python benchmarks/dask_sweep.py [--n 1600] [--shards 25] [--repeat 1]

Runs the command line twice per repeat, each as a fresh process, so the Dask cluster's
start, the workers' imports and their numba cache loading are all in the wall time:

    stickslip simulate --preset paper --n N --seed 0 --out single.h5
    stickslip simulate --preset paper --n N --seed 0 --out sharded.zarr --dask local --shards K

and prints both wall times, their ratio (target <= 1.3) and whether the two datasets
hold identical traces. Prints the machine and its load average: other jobs on the
machine slow both runs, and the two unequally.
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def machine() -> str:
    cpu = platform.processor() or "unknown CPU"
    try:
        with open("/proc/cpuinfo") as f:
            cpu = next(line.split(":", 1)[1].strip() for line in f if "model name" in line)
    except (OSError, StopIteration):
        pass
    return f"{cpu}, {os.cpu_count()} cores, {platform.system()} {platform.machine()}"


def load() -> str:
    try:
        return " ".join(Path("/proc/loadavg").read_text().split()[:3])
    except OSError:
        return "unknown"


def timed(args: list[str]) -> float:
    """Wall time of ``stickslip ARGS`` in a fresh process."""
    code = "from stickslip.cli.main import main; main()"
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", code, *args], check=True)
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1600)
    ap.add_argument("--shards", type=int, default=25)
    ap.add_argument("--repeat", type=int, default=1)
    args = ap.parse_args()

    from stickslip.traces.dataset import load_dataset

    print(f"machine: {machine()}; load average at start: {load()}")
    base = ["simulate", "--preset", "paper", "--n", str(args.n), "--seed", "0", "--no-progress"]
    single, sharded = [], []
    with tempfile.TemporaryDirectory() as tmp:
        h5, store = Path(tmp, "single.h5"), Path(tmp, "sharded.zarr")
        for _ in range(args.repeat):
            single.append(timed([*base, "--out", str(h5), "--overwrite"]))
            sharded.append(timed([*base, "--out", str(store), "--overwrite", "--dask", "local",
                                  "--shards", str(args.shards)]))  # fmt: skip
        same = np.array_equal(load_dataset(h5).force_nN, load_dataset(store).force_nN)
    print(f"paper preset, {args.n} trajectories, {args.shards} shards, best of {args.repeat}")
    print(f"single process: {min(single):.1f} s  (runs: {', '.join(f'{t:.1f}' for t in single)})")
    print(f"--dask local:   {min(sharded):.1f} s  (runs: "
          f"{', '.join(f'{t:.1f}' for t in sharded)}; cluster start included)")  # fmt: skip
    print(f"ratio: {min(sharded) / min(single):.2f} (target <= 1.3)")
    print(f"traces identical: {same}")
    print(f"load average at end: {load()}")


if __name__ == "__main__":
    main()
