"""Inference throughput of an estimator: traces per second, 512-pixel traces.

Times ``estimator.predict(traces)`` (:mod:`stickslip.estimators.base`: conditions,
mapping, the model, one result row per trace), the call ``infer`` and the Python API
make, and for learned models the numerical kernel alone on an (N, 512) array
(window: :func:`stickslip.estimators.window.inference.predict_array`, features + one
batched forward pass + per-trace means; line: :func:`stickslip.estimators.line.ensemble.
predict_raw_lines`, mapping, all members, mean, std and intervals), for any estimator
``load_estimator`` gives: ``window`` (the default: the bundled
paper MLP, windows through one batched forward pass), ``default`` (the bundled line
model: the CNN ensemble with calibrated intervals; ``--line`` is a shorthand), ``classical``
or a model file. Learned models are timed at the reference lattice and, where they map
it, at a = 0.316 nm. ``predict()`` is timed with the in/out-of-domain verdict (the
default) and without it (``no verdict``), and the ratio of the two throughputs printed
(issue target: at least 0.70). Run it on a quiet machine.

Usage: python benchmarks/inference_speed.py [--n 20000] [--repeats 5] [--threads 2]
       [--model window | --line | FILE [--embedding-reference NPZ]]
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np
import torch

from stickslip.estimators.domain import EmbeddingReference
from stickslip.estimators.line.ensemble import predict_raw_lines
from stickslip.estimators.line.estimator import fingerprint
from stickslip.estimators.load import load_estimator
from stickslip.estimators.window.inference import predict_array
from stickslip.traces.trace import Trace


def best_of_each(repeats: int, calls: dict) -> dict[str, float]:
    """The shortest wall time of each call over ``repeats`` rounds, the calls taken in
    turn within each round (after one warm-up round)."""
    best = dict.fromkeys(calls, np.inf)
    for r in range(repeats + 1):
        for what, call in calls.items():
            t = time.perf_counter()
            call()
            if r:
                best[what] = min(best[what], time.perf_counter() - t)
    return best


def best_of(repeats: int, call) -> float:
    """The shortest wall time of ``repeats`` calls (after one warm-up call)."""
    return best_of_each(repeats, {"call": call})["call"]


def kernel(estimator, force: np.ndarray, x: np.ndarray, a: float):
    """The numerical kernel of a learned estimator on an (N, P) array, or None."""
    n = force.shape[0]
    if estimator.kind == "window":
        f32 = force.astype(np.float32)
        if a != estimator.reference.lattice_nm:
            return None  # predict_array reads traces already on the training lattice
        return lambda: predict_array(estimator.model, f32)
    if estimator.kind == "line":
        xs, fs = [x] * n, list(force)
        v, T = np.full(n, 60.0), np.full(n, 296.0)
        return lambda: predict_raw_lines(estimator.ensemble, xs, fs, np.full(n, a), v,
                                         temperature_K=T)  # fmt: skip
    return None


def without_verdict(estimator, traces: list[Trace], a: float):
    """``estimator.predict`` with the in/out-of-domain verdict switched off."""
    estimator.domain_verdict = False
    try:
        return estimator.predict(traces, lattice_nm=a)
    finally:
        estimator.domain_verdict = True


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=20000)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--model", default="window",
                        help="window (bundled paper MLP), default (bundled line model), "
                        "classical, or a model file")  # fmt: skip
    parser.add_argument("--line", action="store_true", help="Time the bundled line model.")
    parser.add_argument("--embedding-reference", default=None,
                        help="a line model file's own domain reference (.npz), where "
                        "it is not the bundled one (an earlier model's full verdict)")  # fmt: skip
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    load = f", load average {os.getloadavg()[0]:.1f}" if hasattr(os, "getloadavg") else ""
    print(f"machine: {platform.processor() or platform.machine()}, {platform.system()}, "
          f"{os.cpu_count()} cores{load}, python {platform.python_version()}, "
          f"torch {torch.__version__}")  # fmt: skip
    estimator = load_estimator(None if args.line else args.model)
    if args.embedding_reference:
        ref = EmbeddingReference.load(args.embedding_reference)
        if ref.fingerprint != fingerprint(estimator.ensemble):
            parser.error(f"{args.embedding_reference} is not this model's reference")
        estimator.embedding_reference = ref
    print(f"estimator: {estimator.describe()}")
    rng = np.random.default_rng(0)
    x = np.arange(512) * (11.0 / 512)
    # saw-tooth-like stand-ins; throughput does not depend on the content
    force = (2.0 * ((x[None, :] / 0.246 + rng.random((args.n, 1))) % 1.0) +
             0.02 * rng.standard_normal((args.n, 512)))  # fmt: skip
    traces = [Trace(x, f, f"t{i}") for i, f in enumerate(force)]
    lattices = [estimator.reference.lattice_nm]
    if estimator.kind != "classical":
        lattices.append(0.316)
    for a in lattices:
        first = traces[:200]
        answered = len(estimator.predict(first, lattice_nm=a).ok())
        runs = {"predict()": lambda a=a: estimator.predict(traces, lattice_nm=a),
                "no verdict": lambda a=a: without_verdict(estimator, traces, a),
                "kernel": kernel(estimator, force, x, a)}  # fmt: skip
        # with and without the verdict in turn, so that a change in the machine's speed
        # (a shared VM) hits both alike
        times = best_of_each(args.repeats, {k: runs[k] for k in ("predict()", "no verdict")})
        if runs["kernel"] is not None:
            times["kernel"] = best_of(args.repeats, runs["kernel"])
        for what, best in times.items():
            print(f"{estimator.name} {what:<10}: {args.n} traces of 512 px at a = {a:g} nm, "
                  f"{args.threads} threads: best of {args.repeats} {best:.3f} s = "
                  f"{args.n / best:,.0f} traces/s")  # fmt: skip
        print(f"  throughput of predict() with / without the domain verdict: "
              f"{times['no verdict'] / times['predict()']:.3f}")
        print(f"  ({answered} of the first {len(first)} traces answered)")


if __name__ == "__main__":
    main()
