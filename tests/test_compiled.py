"""Chunks of lines on threads for the compiled kernels, and numba's cache check."""

from __future__ import annotations

import importlib
import os
import subprocess
import sys

import numpy as np
import pytest
from numba import njit

from stickslip.compiled import cached, chunk_bounds, compile_ahead, run_chunks
from stickslip.estimators import domain
from stickslip.estimators.classical import estimate_array
from stickslip.estimators.classical import estimator as classical_estimator
from stickslip.jobs.infer import kernels_cached
from stickslip.simulators.config import PhysicalSettings
from stickslip.simulators.simulate import simulate


@pytest.mark.parametrize(("n", "min_lines", "threads", "chunks"),
                         [(0, 16, 4, 1), (10, 16, 4, 1), (40, 16, 4, 2), (1000, 16, 4, 4),
                          (1000, 16, 1, 1), (1000, 400, 8, 2)])  # fmt: skip
def test_chunk_bounds_cover_every_line_once(n, min_lines, threads, chunks):
    b = chunk_bounds(n, min_lines, threads)
    assert b[0] == 0 and b[-1] == n and b.size == chunks + 1
    assert np.all(np.diff(b) >= 0)
    if chunks > 1:
        assert np.diff(b).min() >= min_lines


@njit(nogil=True)
def _square_rows(v: np.ndarray, out: np.ndarray) -> None:
    for i in range(v.size):
        out[i] = v[i] * v[i]


def test_run_chunks_fills_each_chunk_on_its_thread():
    v = np.arange(1000.0)
    out = np.full(1000, np.nan)
    b = chunk_bounds(v.size, 100, 4)
    run_chunks(_square_rows, [(v[i:j], out[i:j]) for i, j in zip(b[:-1], b[1:], strict=True)])
    np.testing.assert_array_equal(out, v * v)


def _lines(n: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(5)
    U0, K = rng.uniform(0.8, 3.0, n), rng.uniform(5.0, 30.0, n)
    r = simulate(U0, K, PhysicalSettings(pixels=512, length_nm=8.0), seed=5)
    return r.x_nm, r.force_nN + rng.normal(0.0, 0.05, r.force_nN.shape)


def test_classical_estimates_do_not_depend_on_the_chunks():
    x, F = _lines(48)
    one = estimate_array(x, F, threads=1)
    for threads in (2, 3):
        np.testing.assert_array_equal(estimate_array(x, F, threads=threads), one)


def test_trace_checks_do_not_depend_on_the_chunks():
    x, F = _lines(48)
    xs = [x] * len(F)
    one = domain.trace_checks(xs, list(F), threads=1)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(domain, "MIN_LINES_PER_THREAD", 8)
        three = domain.trace_checks(xs, list(F), threads=3)
    for name in ("n_drops", "n_rises", "spacing_median_nm", "spacing_q25_nm", "noise_nN"):
        np.testing.assert_array_equal(getattr(three, name), getattr(one, name))


def test_cached_after_a_call_and_never_for_a_kernel_without_a_disk_cache():
    x, F = _lines(2)
    estimate_array(x, F)
    domain.trace_checks([x, x], list(F))
    assert cached(*classical_estimator.KERNELS, *domain.KERNELS)
    assert kernels_cached()
    assert not cached(_square_rows)  # compiled, but without cache=True
    assert not cached(np.sum)  # not a numba kernel at all


def test_compile_ahead_runs_its_steps_side_by_side_in_their_own_processes(
        tmp_path, monkeypatch):  # fmt: skip
    # each step records its process and when it ran; two steps that each wait for the
    # other to start can only both finish if they run at the same time
    (tmp_path / "steps_probe.py").write_text(
        "import os, pathlib, sys, time\n"
        f"HERE = pathlib.Path({str(tmp_path)!r})\n"
        "def _step(name, other):\n"
        "    (HERE / name).write_text(str(os.getpid()))\n"
        "    t = time.time()\n"
        "    while not (HERE / other).exists():\n"
        "        if time.time() - t > 60: sys.exit(3)\n"
        "        time.sleep(0.01)\n"
        "def a(): _step('a', 'b')\n"
        "def b(): _step('b', 'a')\n"
        "def fails(): raise RuntimeError('no')\n")
    monkeypatch.setenv("PYTHONPATH", str(tmp_path))
    monkeypatch.syspath_prepend(str(tmp_path))
    probe = importlib.import_module("steps_probe")
    # a step is a function (a worker imports it by its name) or that name
    codes = compile_ahead([probe.a, "steps_probe:b", probe.fails, "no_such_module:f"],
                          processes=2)  # fmt: skip
    assert codes[:2] == [0, 0] and codes[2] != 0 and codes[3] != 0
    pids = {(tmp_path / n).read_text() for n in "ab"}
    assert len(pids) == 2 and str(os.getpid()) not in pids
    assert compile_ahead([]) == []


def test_compile_ahead_gives_up_on_a_step_past_its_time(tmp_path, monkeypatch):
    (tmp_path / "slow_probe.py").write_text("import time\ndef f(): time.sleep(30)\n")
    monkeypatch.setenv("PYTHONPATH", str(tmp_path))
    assert compile_ahead(["slow_probe:f"], timeout_s=2) == [-1]


@pytest.mark.slow
def test_a_first_run_compiles_its_kernels_in_worker_processes(tmp_path):
    # a cold `stickslip demo` (with its --check) in a cache of our own, listening to
    # numba's compile events in the command's own process: every kernel the compile
    # steps cover must come from the workers' cache (the steps' made-up lines give the
    # argument types real inputs give); only the line model's <F> interval kernels
    # (about 1 s) are left to the run itself
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    listen = (
        "import sys\n"
        "from numba.core import event\n"
        "compiled = []\n"
        "class L(event.Listener):\n"
        "    def on_start(self, ev):\n"
        "        f = ev.data['dispatcher'].py_func\n"
        "        compiled.append(f.__module__ + '.' + f.__qualname__)\n"
        "    def on_end(self, ev): pass\n"
        "event.register('numba:compile', L())\n"
        "from stickslip.cli.main import main\n"
        f"sys.argv = ['stickslip', 'demo', '--out', {str(tmp_path / 'demo')!r}]\n"
        "try:\n"
        "    main()\n"
        "except SystemExit:\n"
        "    pass\n"
        "print('\\n'.join('compiled: ' + c for c in compiled if c.startswith('stickslip')))\n"
    )  # fmt: skip
    r = subprocess.run([sys.executable, "-c", listen], env=env, capture_output=True,
                       text=True, timeout=600)  # fmt: skip
    assert "6 ok" in r.stderr and "first run after installing" in r.stderr, r.stderr
    mine = {ln.split()[1] for ln in r.stdout.splitlines() if ln.startswith("compiled: ")}
    assert mine and all(c.startswith("stickslip.estimators.offsets.") for c in mine), mine
    cached_now = "from stickslip.jobs.infer import kernels_cached; assert kernels_cached(True)"
    subprocess.run([sys.executable, "-c", cached_now], env=env, check=True, timeout=120)


def test_compile_ahead_without_an_interpreter_to_start_does_nothing(monkeypatch):
    monkeypatch.setattr(sys, "executable", "")
    assert compile_ahead(["os:getcwd", "os:getpid"]) == [-1, -1]
