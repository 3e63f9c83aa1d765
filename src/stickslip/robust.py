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

__all__ = ["mad_sigma", "median", "percentile", "select", "select_tails", "white_sigma"]


@njit(cache=True, error_model="numpy")
def _select_three_way(a: np.ndarray, k: int, lo: int, hi: int) -> float:
    """:func:`_select_inplace` within ``a[lo : hi + 1]`` by three-way partitions (less
    than, equal to, greater than the pivot): one round sets aside every value equal to
    the pivot, however many there are."""
    while hi > lo:
        pivot = a[(lo + hi) // 2]
        lt, i, gt = lo, lo, hi
        while i <= gt:
            v = a[i]
            if v < pivot:
                a[i] = a[lt]
                a[lt] = v
                lt += 1
                i += 1
            elif v > pivot:
                a[i] = a[gt]
                a[gt] = v
                gt -= 1
            else:
                i += 1
        if k < lt:
            hi = lt - 1
        elif k > gt:
            lo = gt + 1
        else:
            return pivot
    return a[k]


@njit(cache=True, error_model="numpy")
def _select_inplace(a: np.ndarray, k: int) -> float:
    """The ``k``-th smallest value of ``a`` (0-based), ``a`` reordered in place so that
    ``a[:k] <= a[k] <= a[k + 1:]``."""
    lo, hi = 0, a.size - 1
    rounds = 0
    while hi > lo:
        rounds += 1
        if rounds > 64:
            # many equal values make Lomuto's scheme slow (a round may set aside one
            # value); three-way partitions finish. (Not np.partition: its compiled
            # machinery took 4 s of the first run's compilation.)
            return _select_three_way(a, k, lo, hi)
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


#: :func:`select_tails` keeps a sorted buffer of each tail up to this many values
#: (insertions cost up to the buffer's length each); beyond it, it selects.
MAX_TAIL = 32


@njit(cache=True, error_model="numpy")
def select_tails(v: np.ndarray, lo: int, hi: int) -> tuple[float, float]:
    """The ``lo``-th and ``hi``-th smallest values of ``v`` (0-based, ``lo <= hi``), as
    two :func:`select` calls give them, ``v`` unchanged.

    For order statistics near both ends (a 2-98 % range): one pass that keeps the
    ``lo + 1`` smallest and ``v.size - hi`` largest values in two short sorted buffers,
    about a third of the comparisons of two selections on a few hundred samples. Tails
    longer than :data:`MAX_TAIL` fall back to :func:`select`.
    """
    n = v.size
    nlo, nhi = lo + 1, n - hi
    if nlo > MAX_TAIL or nhi > MAX_TAIL:
        return select(v, lo), select(v, hi)
    small = np.empty(nlo)  # ascending: small[-1] is the lo-th smallest so far
    large = np.empty(nhi)  # descending: large[-1] is the hi-th smallest so far
    small[:] = np.inf
    large[:] = -np.inf
    for x in v:
        if x < small[nlo - 1]:
            j = nlo - 1
            while j > 0 and small[j - 1] > x:
                small[j] = small[j - 1]
                j -= 1
            small[j] = x
        if x > large[nhi - 1]:
            j = nhi - 1
            while j > 0 and large[j - 1] < x:
                large[j] = large[j - 1]
                j -= 1
            large[j] = x
    return small[nlo - 1], large[nhi - 1]


@njit(cache=True, error_model="numpy")
def _median_inplace(a: np.ndarray) -> float:
    """The median of ``a`` (no NaN), ``a`` reordered in place."""
    n = a.size
    k = (n - 1) // 2
    m = _select_inplace(a, k)
    if n % 2:
        return m
    # the next order statistic is the least value above position k
    return 0.5 * (m + np.min(a[k + 1 :]))


@njit(cache=True, error_model="numpy")
def _has_nan(v: np.ndarray) -> bool:
    for x in v:  # not np.sum: +inf and -inf together sum to NaN
        if np.isnan(x):
            return True
    return False


@njit(cache=True, error_model="numpy")
def median(v: np.ndarray) -> float:
    """``np.median(v)`` of a 1-D array (NaN for an empty array or one holding NaN)."""
    if v.size == 0 or _has_nan(v):
        return np.nan
    return _median_inplace(v.copy())


@njit(cache=True, error_model="numpy")
def mad_sigma(v: np.ndarray) -> float:
    """Robust standard deviation of ``v``: 1.4826 times its median absolute deviation, or,
    where more than half the values are equal (digitised signals, MAD 0), 1.2533 times
    the mean absolute deviation from the median. 0 for an empty array."""
    n = v.size
    if n == 0:
        return 0.0
    if _has_nan(v):
        return np.nan
    # one work array for both medians (this runs on every line, several times)
    buf = v.copy()
    med = _median_inplace(buf)
    for i in range(n):
        buf[i] = abs(v[i] - med)
    s = 1.4826 * _median_inplace(buf)
    if s == 0.0:
        total = 0.0
        for i in range(n):  # in v's order, as np.mean sums
            total += abs(v[i] - med)
        s = 1.2533 * (total / n)
    return s


@njit(cache=True, error_model="numpy")
def percentile(v: np.ndarray, q: float) -> float:
    """``np.percentile(v, q)`` of a 1-D array as numba computes it (linear interpolation
    between the two order statistics about rank ``(n - 1) q / 100``), from one branchless
    selection (NaN for an empty array or one holding NaN)."""
    n = v.size
    if n == 0 or _has_nan(v):
        return np.nan
    if n == 1:
        return v[0]
    if q >= 100.0:
        return np.max(v)
    if q <= 0.0:
        return np.min(v)
    rank = 1.0 + (n - 1) * (q / 100.0)
    f = np.floor(rank)
    m = rank - f
    k = int(f) - 1
    a = v.copy()
    lower = _select_inplace(a, k)
    upper = np.min(a[k + 1 :])  # the next order statistic
    return lower * (1 - m) + upper * m


@njit(cache=True, error_model="numpy")
def white_sigma(F: np.ndarray) -> float:
    """Robust standard deviation of white noise on a line from all its second
    differences (whose std is ``sqrt(6)`` times the noise's): ``mad_sigma(d2) /
    sqrt(6)``, 0 below 3 samples. Slips and the sticks' bends count in: this is the
    plain estimate (the compiled twin of :func:`stickslip.estimators.noise.noise_nN` at
    ``iterations=0``, with the MAD in place of the median absolute value)."""
    n = F.size
    if n < 3:
        return 0.0
    d2 = np.empty(n - 2)
    for i in range(n - 2):
        d2[i] = F[i + 2] - 2.0 * F[i + 1] + F[i]
    return mad_sigma(d2) / np.sqrt(6.0)
