"""Chunks of lines on threads for the compiled kernels, and numba's cache check."""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit

from stickslip.compiled import cached, chunk_bounds, run_chunks
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
