"""What a line shows of the effects that widen its interval, read off the line itself.

A calibration fitted on lines drawn from a broad prior of instrument effects gives every
line the width that the prior's average line needs. Some of those effects leave no mark
on the line (a stated velocity that is wrong, a gain error) and their share of the width
must stay; others show (a slow drift or a crosstalk curve, a modulated substrate, mains
pickup, a telegraph step, spikes), and a line that shows none of them should not pay for
them. The line model's calibration therefore scales each line's std by
``exp(b0 + b . e)`` (:func:`stickslip.estimators.line.training.calibrate`), where ``e``
is the evidence below, ``b >= 0``, and ``b0`` (negative) is what a line without
evidence saves; the fit is a 95 % quantile regression, the interval score's own
criterion (Gneiting and Raftery 2007), so the coefficients are those of the sharpest
intervals that still cover.

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

_TINY = 1e-9


def _slow(F: np.ndarray, period_px: float) -> float:
    n = F.size
    bins = max(2, int(round(period_px)))
    phase = np.floor((np.arange(n) % period_px) / period_px * bins).astype(int)
    phase = np.minimum(phase, bins - 1)
    counts = np.bincount(phase, minlength=bins)
    profile = np.bincount(phase, weights=F, minlength=bins) / np.maximum(counts, 1)
    resid = F - profile[phase]
    w = min(bins, n)
    smooth = np.convolve(resid, np.full(w, 1.0 / w), mode="valid")
    rms = float(np.sqrt(np.mean((smooth - smooth.mean()) ** 2))) if smooth.size else 0.0
    return float(np.log(rms / (float(np.std(profile)) + _TINY) + 1e-3))


def _spikes(F: np.ndarray) -> float:
    d2 = np.diff(F, 2)
    if d2.size < 3:
        return 0.0
    mad = 1.4826 * float(np.median(np.abs(d2 - np.median(d2))))
    return float(np.log(float(np.max(np.abs(d2))) / (mad + _TINY) + 1.0))


def line_evidence(lines: list[np.ndarray], period_px: float) -> np.ndarray:
    """Evidence of visible effects (:data:`EVIDENCE`) for mapped lines of any lengths.

    Parameters
    ----------
    lines : list of ndarray
        Mapped lines (force, nN) on a grid with ``period_px`` pixels per lattice period.
    period_px : float
        The lattice period in pixels of that grid.

    Returns
    -------
    ndarray (B, len(EVIDENCE))
    """
    out = np.empty((len(lines), len(EVIDENCE)))
    for i, f in enumerate(lines):
        F = np.asarray(f, float)
        out[i] = (_slow(F, period_px), _spikes(F)) if F.size > 2 * period_px else (0.0, 0.0)
    return out
