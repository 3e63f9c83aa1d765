"""Inference throughput of the bundled model: traces per second, 512-pixel traces, batched.

Times :func:`stickslip.learning.inference.predict_array` (features + one batched
forward pass + per-trace means) on simulated-like traces; run it on a quiet machine.

Usage: python benchmarks/inference_speed.py [--n 20000] [--repeats 5] [--threads 2]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from stickslip.learning.inference import predict_array
from stickslip.learning.modelfile import load_model


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=20000)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--model", default=None)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    model = load_model(args.model)
    rng = np.random.default_rng(0)
    x = np.arange(512) * (11.0 / 512)
    # saw-tooth-like stand-ins; throughput does not depend on the content
    force = (2.0 * ((x[None, :] / 0.246 + rng.random((args.n, 1))) % 1.0) +
             0.02 * rng.standard_normal((args.n, 512))).astype(np.float32)  # fmt: skip
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


if __name__ == "__main__":
    main()
