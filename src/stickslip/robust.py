"""Exact order statistics, compiled, for the per-line kernels (slip checks, noise).

``numba``'s ``np.median`` selects with a branchy partition: on a fresh line of a few
hundred samples about half its comparisons are mispredicted, and it costs ~7 us at 512
samples, several times its cost on data the branch predictor has seen. The selection
here partitions without branches (Lomuto's scheme written as an unconditional swap and a
conditional increment, which compiles to a conditional move) and gives the same values:
order statistics are exact, and the median of an even count is the mean of the two
middle ones, as numpy's. Inputs with NaN give NaN, as numpy's median does.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["mad_sigma", "median", "select"]


@njit(cache=True, error_model="numpy")
def _select_inplace(a: np.ndarray, k: int) -> float:
    """The ``k``-th smallest value of ``a`` (0-based), ``a`` reordered in place so that
    ``a[:k] <= a[k] <= a[k + 1:]``."""
    lo, hi = 0, a.size - 1
    rounds = 0
    while hi > lo:
        rounds += 1
        if rounds > 64:
            # many equal values make Lomuto's scheme slow: numpy's selection finishes
            part = np.partition(a[lo : hi + 1], k - lo)
            a[lo : hi + 1] = part
            return a[k]
        # median of three as the pivot, moved to the end
        mid = (lo + hi) // 2
        x, y, z = a[lo], a[mid], a[hi]
        if (x <= y) == (y <= z):
            p = mid
        elif (y <= x) == (x <= z):
            p = lo
        else:
            p = hi
        pivot = a[p]
        a[p] = a[hi]
        a[hi] = pivot
        j = lo
        for i in range(lo, hi):
            v = a[i]
            a[i] = a[j]
            a[j] = v
            j += v < pivot
        a[hi] = a[j]
        a[j] = pivot
        if j == k:
            return pivot
        if j < k:
            lo = j + 1
        else:
            hi = j - 1
    return a[k]


@njit(cache=True, error_model="numpy")
def select(v: np.ndarray, k: int) -> float:
    """The ``k``-th smallest value of ``v`` (0-based; ``v`` is not changed), as
    ``np.partition(v, k)[k]``."""
    return _select_inplace(v.copy(), k)


@njit(cache=True, error_model="numpy")
def median(v: np.ndarray) -> float:
    """``np.median(v)`` of a 1-D array (NaN for an empty array or one holding NaN)."""
    n = v.size
    if n == 0:
        return np.nan
    for x in v:  # not np.sum: +inf and -inf together sum to NaN
        if np.isnan(x):
            return np.nan
    a = v.copy()
    k = (n - 1) // 2
    m = _select_inplace(a, k)
    if n % 2:
        return m
    # the next order statistic is the least value above position k
    return 0.5 * (m + np.min(a[k + 1 :]))


@njit(cache=True, error_model="numpy")
def mad_sigma(v: np.ndarray) -> float:
    """Robust standard deviation of ``v``: 1.4826 times its median absolute deviation, or,
    where more than half the values are equal (digitised signals, MAD 0), 1.2533 times
    the mean absolute deviation from the median. 0 for an empty array."""
    if v.size == 0:
        return 0.0
    med = median(v)
    s = 1.4826 * median(np.abs(v - med))
    if s == 0.0:
        s = 1.2533 * np.mean(np.abs(v - med))
    return s
