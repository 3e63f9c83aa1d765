"""Peak memory of line-model training streamed from disk, at two dataset sizes.

Writes cheap synthetic sets in the project's sweep layout (sawtooth-plus-sine lines, no
simulator) under ``build/train_memory/``, then trains on each in a fresh subprocess
through the ``train`` job (:func:`stickslip.jobs.train.read_training_data` and
:func:`~stickslip.jobs.train.train_line`, as ``stickslip train --kind line --data SET.h5``
does) for a fixed number of steps, and prints each run's peak resident memory (the
child's ``ru_maxrss`` from ``wait4``: the larger of the trainer and its loader workers),
their ratio, wall times and the machine. Streaming keeps the ratio near 1: only the
validation rows (capped), the parameter table and a shuffle buffer are in memory.

    .venv/bin/python benchmarks/train_memory.py                 # 1e4 vs 1e5 lines
    .venv/bin/python benchmarks/train_memory.py --sizes 2000 20000 --steps 5
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from stickslip.traces.dataset import create_dataset_file, write_rows

OUT = Path("build/train_memory")
PIXELS, LENGTH_NM, LATTICE_NM = 512, 11.0, 0.246
EV_NM_TO_NN = 0.1602176634  # 1 eV/nm in nN


def synthetic_set(path: Path, n: int, seed: int = 0, block: int = 4096) -> Path:
    """Write ``n`` sawtooth-plus-sine lines with a parameter table in the sweep layout
    (kept if already there); a quarter of them on a flat substrate."""
    if path.exists():
        return path
    rng = np.random.default_rng(seed)
    x = np.arange(PIXELS) * LENGTH_NM / PIXELS
    U0, K = rng.uniform(0.3, 6.0, n), rng.uniform(1.0, 50.0, n)
    params = {"U0_eV": U0, "K_N_m": K, "eta": 52.26 * U0 / K, "F_mean_nN": np.zeros(n),
              "lattice_nm": np.full(n, LATTICE_NM), "velocity_nm_per_s": np.full(n, 60.0),
              "temperature_K": np.full(n, 296.0), "index": np.arange(n),
              "mod_amplitude": np.where(rng.random(n) < 0.25, 0.0, 0.1),
              "defect_count": np.zeros(n, np.int64)}  # fmt: skip
    part = path.with_name(path.name + ".partial")
    create_dataset_file(part, n, x, params, {"config": json.dumps({"synthetic": n})})
    for s in range(0, n, block):
        r = np.arange(s, min(s + block, n))
        fmax = np.pi * U0[r, None] * EV_NM_TO_NN / LATTICE_NM
        # a stick-slip-like sawtooth (stick slope ~ K, peak ~ F_max) plus a slow sine
        saw = np.minimum(K[r, None] * LATTICE_NM * ((x / LATTICE_NM) % 1.0), fmax)
        force = saw + 0.1 * fmax * np.sin(2 * np.pi * x / 3.0 + rng.uniform(0, 6, (r.size, 1)))
        write_rows(part, r, force.astype(np.float32), np.zeros(force.shape),
                   {"F_mean_nN": force.mean(axis=1)})  # fmt: skip
    part.rename(path)
    return path


def child(path: Path, steps: int, workers: int, model: Path) -> None:
    """One training run (in its own process): prints a JSON line with its figures."""
    import torch

    from stickslip.conditions import GRAPHITE
    from stickslip.estimators.line.streaming import StreamSettings
    from stickslip.estimators.line.training import LineTrainConfig
    from stickslip.jobs.train import read_training_data, train_line

    torch.set_num_threads(1)
    t0 = time.perf_counter()
    training = read_training_data([path], None, GRAPHITE)
    cfg = LineTrainConfig(members=1, epochs=1)
    stream = StreamSettings(num_workers=workers, steps_per_epoch=steps)
    report = train_line(training, model, cfg, progress=False, stream=stream)
    print(json.dumps({
        "n": training.data.n, "n_train": report["n_train"], "n_val": report["n_val"],
        "seconds": time.perf_counter() - t0,
        "trainer_maxrss_MB": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "workers_maxrss_MB": resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024,
    }))  # fmt: skip


def run(path: Path, steps: int, workers: int) -> dict:
    """Train on ``path`` in a fresh process; its figures and peak RSS (MB) from wait4."""
    env = {**os.environ, "NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    cmd = [sys.executable, __file__, "--child", str(path), "--steps", str(steps),
           "--workers", str(workers)]  # fmt: skip
    t0 = time.perf_counter()
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, env=env, text=True)
    out = p.stdout.read()
    _, status, usage = os.wait4(p.pid, 0)
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"training on {path} failed")
    doc = json.loads(out.strip().splitlines()[-1])
    doc.update(peak_rss_MB=usage.ru_maxrss / 1024, wall_s=time.perf_counter() - t0)
    return doc


def machine() -> str:
    import torch

    return (f"{platform.processor() or platform.machine()}, {platform.system()}, "
            f"{os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}, python "
            f"{platform.python_version()}, torch {torch.__version__}")  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs=2, default=[10_000, 100_000])
    ap.add_argument("--steps", type=int, default=20, help="training steps per run")
    ap.add_argument("--workers", type=int, default=1, help="loader workers")
    ap.add_argument("--child", type=Path, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child is not None:
        child(args.child, args.steps, args.workers, OUT / f"{args.child.stem}.pt")
        return
    OUT.mkdir(parents=True, exist_ok=True)
    results = []
    for n in args.sizes:
        t0 = time.perf_counter()
        path = synthetic_set(OUT / f"lines_{n}.h5", n)
        made = time.perf_counter() - t0
        r = run(path, args.steps, args.workers)
        results.append(r)
        print(f"{n:>7} lines ({path.stat().st_size / 1e6:.0f} MB file, set made in "
              f"{made:.0f} s): peak RSS {r['peak_rss_MB']:.0f} MB (trainer "
              f"{r['trainer_maxrss_MB']:.0f} MB, workers {r['workers_maxrss_MB']:.0f} MB), "
              f"{r['n_val']} validation lines, wall {r['wall_s']:.0f} s")  # fmt: skip
    a, b = results
    print(f"peak RSS ratio {args.sizes[1]} / {args.sizes[0]} lines: "
          f"{b['peak_rss_MB'] / a['peak_rss_MB']:.3f} (target <= 1.2); {args.steps} steps, "
          f"batch 128, {args.workers} loader worker(s)")  # fmt: skip
    print(f"machine: {machine()}")


if __name__ == "__main__":
    main()
