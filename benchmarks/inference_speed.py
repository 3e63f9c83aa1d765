"""Inference throughput of the bundled models: traces per second, 512-pixel traces, batched.

Window model: :func:`stickslip.estimators.window.inference.predict_array` (features + one
batched forward pass + per-trace means). Line model (``--line``): the bundled CNN
ensemble with uncertainty, :func:`stickslip.estimators.line.ensemble.predict_raw_lines` (mapping,
all members, predictive mean, std and intervals), at the reference lattice and at
a = 0.316 nm. Run it on a quiet machine.

Usage: python benchmarks/inference_speed.py [--n 20000] [--repeats 5] [--threads 2] [--line]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from stickslip.estimators.window.inference import predict_array
from stickslip.estimators.window.modelfile import load_model


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=20000)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--model", default=None)
    parser.add_argument("--line", action="store_true", help="Time the line model instead.")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    rng = np.random.default_rng(0)
    x = np.arange(512) * (11.0 / 512)
    # saw-tooth-like stand-ins; throughput does not depend on the content
    force = (2.0 * ((x[None, :] / 0.246 + rng.random((args.n, 1))) % 1.0) +
             0.02 * rng.standard_normal((args.n, 512))).astype(np.float32)  # fmt: skip
    if args.line:
        line_speed(args, x, force)
        return
    model = load_model(args.model)
    predict_array(model, force[:1000])
    best = np.inf
    for _ in range(args.repeats):
        t = time.perf_counter()
        predict_array(model, force)
        best = min(best, time.perf_counter() - t)
    spec = model.features
    print(f"{args.n} traces of 512 px, recipe {spec.recipe}, window {spec.window}, "
          f"stride {spec.stride}, {args.threads} threads: best of {args.repeats} "
          f"{best:.3f} s = {args.n / best:,.0f} traces/s")


def line_speed(args, x: np.ndarray, force: np.ndarray) -> None:
    from stickslip.estimators.line.ensemble import predict_raw_lines
    from stickslip.estimators.line.modelfile import load_line_model

    ens = load_line_model(args.model)
    n = force.shape[0]
    xs, fs = [x] * n, list(force.astype(float))
    for a in (ens.spec.lattice_nm, 0.316):
        predict_raw_lines(ens, xs[:500], fs[:500], np.full(500, a), np.full(500, 60.0))
        best = np.inf
        for _ in range(args.repeats):
            t = time.perf_counter()
            predict_raw_lines(ens, xs, fs, np.full(n, a), np.full(n, 60.0))
            best = min(best, time.perf_counter() - t)
        print(f"line model ({len(ens.members)} members), {n} traces of 512 px at a = {a:g} nm, "
              f"{args.threads} threads: best of {args.repeats} {best:.3f} s = "
              f"{n / best:,.0f} traces/s")


if __name__ == "__main__":
    main()
