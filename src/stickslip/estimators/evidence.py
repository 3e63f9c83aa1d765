"""What a line shows of the effects that widen its interval, read off the line itself.

A calibration fitted on lines drawn from a broad prior of instrument effects gives every
line the width that the prior's average line needs. Some of those effects leave no mark
on the line (a stated velocity that is wrong, a gain error) and their share of the width
must stay; others show (a slow drift or a crosstalk curve, a modulated substrate, mains
pickup, a telegraph step, spikes), and a line that shows none of them should not pay for
them. The line model's calibration therefore scales each line's std by
``exp(b0 + b . e)`` (:func:`stickslip.estimators.line.training.calibrate`), where ``e``
is the evidence below and ``b >= 0``, so a line without evidence gets the least width
(``b0`` sets the level; the intervals' shape, fitted after it, rescales it); the fit is
a 95 % quantile regression, the interval score's own criterion (Gneiting and Raftery
2007), so the coefficients are those of the sharpest intervals that still cover.

The evidence, per mapped line (on the model's reference lattice and pixel):

- ``slow``: ln of the RMS of what is left once the line's lattice-periodic profile is
  taken off and the rest is averaged over one lattice period, relative to the profile's
  own std: slow, non-periodic content (drift, curvature, modulation, mains, steps).
  White noise averages out over the period; a clean stick-slip line leaves little.
- ``spikes``: ln of the largest absolute second difference over the robust scale (MAD)
  of the second differences: isolated spikes and glitches.

Both are dimensionless (no scale of their own in nN or nm) and cost one pass over the
line.
"""

from __future__ import annotations

import numpy as np

#: The evidence's names, in the order of :func:`line_evidence`'s columns.
EVIDENCE = ("slow", "spikes")
#: The result table's columns that carry a line's evidence (the line model writes them;
#: the per-map pooling reads them, :mod:`stickslip.estimators.pooling`).
EVIDENCE_COLUMNS = tuple(f"evidence_{e}" for e in EVIDENCE)

_TINY = 1e-9


def _batch(F: np.ndarray, period_px: float) -> np.ndarray:
    """:func:`line_evidence` of B lines of one length L, (B, 2), vectorised over lines."""
    B, n = F.shape
    bins = max(2, int(round(period_px)))
    phase = np.minimum(np.floor((np.arange(n) % period_px) / period_px * bins).astype(int),
                       bins - 1)  # fmt: skip
    onehot = np.zeros((n, bins))
    onehot[np.arange(n), phase] = 1.0
    profile = (F @ onehot) / np.maximum(onehot.sum(axis=0), 1.0)  # (B, bins)
    resid = F - profile[:, phase]
    # the residual averaged over one period (a moving mean of `bins` samples)
    w = min(bins, n)
    cs = np.concatenate([np.zeros((B, 1)), np.cumsum(resid, axis=1)], axis=1)
    smooth = (cs[:, w:] - cs[:, :-w]) / w
    rms = smooth.std(axis=1)
    slow = np.log(rms / (profile.std(axis=1) + _TINY) + 1e-3)
    d2 = np.diff(F, 2, axis=1)
    mad = 1.4826 * np.median(np.abs(d2 - np.median(d2, axis=1, keepdims=True)), axis=1)
    spikes = np.log(np.abs(d2).max(axis=1) / (mad + _TINY) + 1.0)
    return np.column_stack([slow, spikes])


def line_evidence(lines: list[np.ndarray] | np.ndarray, period_px: float) -> np.ndarray:
    """Evidence of visible effects (:data:`EVIDENCE`) for mapped lines of any lengths.

    Parameters
    ----------
    lines : list of ndarray, or ndarray (B, L)
        Mapped lines (force, nN) on a grid with ``period_px`` pixels per lattice period;
        lines of one length are computed together.
    period_px : float
        The lattice period in pixels of that grid.

    Returns
    -------
    ndarray (B, len(EVIDENCE))
        Zeros for a line shorter than two periods (nothing to compare).
    """
    arrays = [np.asarray(f, float) for f in lines]
    out = np.zeros((len(arrays), len(EVIDENCE)))
    sizes = np.array([f.size for f in arrays], int)
    for size in np.unique(sizes):
        if size <= 2 * period_px:
            continue
        idx = np.flatnonzero(sizes == size)
        out[idx] = _batch(np.stack([arrays[i] for i in idx]), period_px)
    return out


def line_evidence_batch(lines: np.ndarray, period_px: float) -> np.ndarray:
    """:func:`line_evidence` of B mapped lines of one length, an array (B, L).

    Returns
    -------
    ndarray (B, len(EVIDENCE))
        Zeros where the lines are shorter than two periods.
    """
    F = np.asarray(lines, float)
    if F.shape[0] == 0 or F.shape[1] <= 2 * period_px:
        return np.zeros((F.shape[0], len(EVIDENCE)))
    return _batch(F, period_px)
