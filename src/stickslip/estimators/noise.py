"""The one white-noise estimate of a force line, from its second differences.

Second differences of white noise of standard deviation ``sigma`` have standard
deviation ``sqrt(6) sigma``, and the median of their absolute value is ``0.6745`` of
that. Slips make a quarter or more of them large, so :func:`noise_nN` can iterate:
values beyond 3.5 standard deviations are dropped and the median recomputed.
(The compiled kernels, the slip detector and the verdict's trace checks, use the
plain estimate's numba twin, :func:`stickslip.robust.white_sigma`.)
"""

from __future__ import annotations

import numpy as np

MEDIAN_ABS_Z = 0.6745  # median of |Z| for a standard normal Z
SQRT6 = float(np.sqrt(6.0))


def abs_second_differences(force_nN: np.ndarray) -> np.ndarray:
    """``|F[i+1] - 2 F[i] + F[i-1]|`` along the last axis."""
    return np.abs(np.diff(np.asarray(force_nN, float), n=2, axis=-1))


def noise_nN(force_nN: np.ndarray, iterations: int = 3) -> np.ndarray:
    """Robust white-noise standard deviation (nN) of each row of ``force_nN``.

    Parameters
    ----------
    force_nN : ndarray (..., P)
        Lines of force samples.
    iterations : int
        Rounds of rejecting second differences beyond 3.5 standard deviations
        (0: the plain median estimate).

    Returns
    -------
    ndarray (...,)
    """
    d2 = abs_second_differences(force_nN)
    sd = np.median(d2, axis=-1, keepdims=True) / MEDIAN_ABS_Z
    keep = np.ones_like(d2, dtype=bool)
    for _ in range(iterations):
        keep = d2 <= 3.5 * sd + 1e-15
        sd = np.nan_to_num(np.nanmedian(np.where(keep, d2, np.nan), axis=-1, keepdims=True)
                           / MEDIAN_ABS_Z, nan=0.0)  # fmt: skip
    return sd[..., 0] / SQRT6


def log_noise_level(force_nN: np.ndarray) -> np.ndarray:
    """``ln(median |second difference| + 1e-4 nN)`` of each row: the line model's noise
    coordinate (its spread classes are defined on it)."""
    return np.log(np.median(abs_second_differences(force_nN), axis=-1) + 1e-4)


#: Floor of :func:`log_noise_ratio`'s ratio: a noiseless simulated line reads about this.
NOISE_RATIO_FLOOR = 1e-4


def log_noise_ratio(force_nN: np.ndarray) -> np.ndarray:
    """``ln(noise / std + 1e-4)`` of each row: the white noise (:func:`noise_nN`) over
    the line's own standard deviation, a dimensionless measure of how noisy a line is
    (the line model's location calibration reads it).

    Parameters
    ----------
    force_nN : ndarray (..., P)

    Returns
    -------
    ndarray (...,)
    """
    F = np.asarray(force_nN, float)
    std = F.std(axis=-1)
    ratio = np.divide(noise_nN(F), std, out=np.zeros_like(std), where=std > 0)
    return np.log(ratio + NOISE_RATIO_FLOOR)
