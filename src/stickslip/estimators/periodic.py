"""Means over exactly one lattice period.

Over one period of the lattice a stick-slip line's own pattern averages to its mean
force, whatever its shape, so a mean over exactly one period sees only what the
lattice does not set: an offset, a drift, a crosstalk curve, a defect's local push. A
period is rarely a whole number of samples; the samples at the window's ends count with
the fraction of them inside. Samples are cells of unit width (sample ``j`` spans ``[j,
j + 1)``), as a pixel is the mean over its travel. What is left of the sawtooth comes
from the pixel that holds a slip, whose mean says nothing of where in it the slip fell:
on pixel means of a sawtooth of 11.4 samples per period it is 0.4 % of the range rms
(2 % at worst), against 1.0 % rms for a window of a whole number of samples
(``tests/estimators/test_periodic.py``).
"""

from __future__ import annotations

import numpy as np


def period_means(F: np.ndarray, period_px: float, starts: np.ndarray) -> np.ndarray:
    """Means of series over windows ``[s, s + period_px)`` (in samples) at ``starts``.

    Parameters
    ----------
    F : ndarray (L,) or (B, L)
        Series sampled on one grid.
    period_px : float
        The lattice period in samples (> 0).
    starts : ndarray (m,)
        Window starts, real, with ``0 <= s`` and ``s + period_px <= L``.

    Returns
    -------
    ndarray (m,) or (B, m)
        The exact mean of the piecewise-constant series over each window.
    """
    F = np.asarray(F, float)
    flat = F.ndim == 1
    F2 = np.atleast_2d(F)
    B, n = F2.shape
    C = np.concatenate([np.zeros((B, 1)), np.cumsum(F2, axis=1)], axis=1)
    # the integral up to real position p: whole cells, then the part of cell floor(p)
    padded = np.concatenate([F2, F2[:, -1:]], axis=1)

    def integral(p: np.ndarray) -> np.ndarray:
        j = np.clip(np.floor(p).astype(int), 0, n)
        return C[:, j] + (p - j)[None, :] * padded[:, j]

    s = np.asarray(starts, float)
    out = (integral(s + float(period_px)) - integral(s)) / float(period_px)
    return out[0] if flat else out


def sliding_period_mean(F: np.ndarray, period_px: float) -> np.ndarray:
    """The mean of B series (B, L) over a window of one period sliding by one sample
    from the start, (B, L - ceil(period_px) + 1): every window that fits."""
    F = np.atleast_2d(np.asarray(F, float))
    m = F.shape[1] - int(np.ceil(period_px)) + 1
    return period_means(F, period_px, np.arange(max(m, 0), dtype=float))
