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

A third measure, read by the per-map pooling only and not by the calibration's factor:

- ``local`` (:func:`local_evidence`): a local anomaly, a few stick-slip cycles whose level
  differs from their neighbours' (a point defect's force), told from a smooth drift or
  crosstalk curve by a filter a few lattice periods wide that is blind to an offset, a
  slope and a curvature. Also dimensionless.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from stickslip.estimators.periodic import sliding_period_mean

#: The evidence's names, in the order of :func:`line_evidence`'s columns.
EVIDENCE = ("slow", "spikes")
#: The result table's columns that carry a line's evidence (the line model writes them;
#: the per-map pooling reads them, :mod:`stickslip.estimators.pooling`).
EVIDENCE_COLUMNS = tuple(f"evidence_{e}" for e in EVIDENCE)

_TINY = 1e-9


def _profile(F: np.ndarray, period_px: float) -> tuple[np.ndarray, np.ndarray]:
    """The lattice-periodic profile of B lines (B, L): its mean per phase bin (B, bins;
    about one bin per pixel of a period) and each sample's bin (L,)."""
    n = F.shape[1]
    bins = max(2, int(round(period_px)))
    phase = np.minimum(np.floor((np.arange(n) % period_px) / period_px * bins).astype(int),
                       bins - 1)  # fmt: skip
    onehot = np.zeros((n, bins))
    onehot[np.arange(n), phase] = 1.0
    return (F @ onehot) / np.maximum(onehot.sum(axis=0), 1.0), phase


def _slow_residual(F: np.ndarray, period_px: float) -> tuple[np.ndarray, np.ndarray]:
    """What B lines (B, L) leave once their lattice-periodic profile is taken off, averaged
    over one lattice period (a moving mean; (B, L - bins + 1)), and the std of each
    line's profile (B,)."""
    B, n = F.shape
    bins = max(2, int(round(period_px)))
    profile, phase = _profile(F, period_px)
    resid = F - profile[:, phase]
    # the residual averaged over one period (a moving mean of `bins` samples)
    w = min(bins, n)
    cs = np.concatenate([np.zeros((B, 1)), np.cumsum(resid, axis=1)], axis=1)
    return (cs[:, w:] - cs[:, :-w]) / w, profile.std(axis=1)


def _batch(F: np.ndarray, period_px: float) -> np.ndarray:
    """:func:`line_evidence` of B lines of one length L, (B, 2), vectorised over lines."""
    smooth, profile_std = _slow_residual(F, period_px)
    rms = smooth.std(axis=1)
    slow = np.log(rms / (profile_std + _TINY) + 1e-3)
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
    return _by_length(lines, period_px, _batch, (len(EVIDENCE),))


def _by_length(lines: list[np.ndarray] | np.ndarray, period_px: float, batch,
               shape: tuple[int, ...]) -> np.ndarray:  # fmt: skip
    """``batch`` (of B lines of one length, and ``period_px``) over lines of any lengths,
    each length at once; zeros (of ``shape`` per line) for lines of two periods or less."""
    arrays = [np.asarray(f, float) for f in lines]
    out = np.zeros((len(arrays), *shape))
    sizes = np.array([f.size for f in arrays], int)
    for size in np.unique(sizes):
        if size <= 2 * period_px:
            continue
        idx = np.flatnonzero(sizes == size)
        out[idx] = batch(np.stack([arrays[i] for i in idx]), period_px)
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


# ---------------------------------------------------------------------------- local anomaly

#: What :func:`local_evidence` is called in the result table and the per-map pooling.
LOCAL = "local"
#: The result table's column that carries :func:`local_evidence` (written by the line
#: model beside :data:`EVIDENCE_COLUMNS`; not an input of its calibration).
LOCAL_COLUMN = f"evidence_{LOCAL}"
#: Width (the Gaussian's sigma) of the local-anomaly filter, in lattice periods: a few
#: stick-slip cycles, the reach of a point defect's force along a line.
LOCAL_SCALE = 3.0
#: Half-length of the filter, in sigmas.
LOCAL_REACH = 3.0
#: Closest the filter's centre comes to a line's end, in sigmas (nearer the ends than
#: :data:`LOCAL_REACH` it is cut to the line and kept blind to an offset, a slope and a
#: curvature).
LOCAL_EDGE = 1.0


def local_kernel(sigma_px: float) -> np.ndarray:
    """The local-anomaly filter: the third derivative of a Gaussian of std ``sigma_px``
    (pixels), cut at :data:`LOCAL_REACH` sigmas, orthogonal to an offset, a slope and a
    curvature, of unit norm.

    Correlated with a series, it answers to a localised dipole (an odd bump: what a
    point defect's force ``-dV/dx`` adds to a line) and not to an offset, a slope or a
    curvature (a drift or a smooth crosstalk curve); on a random walk it is the Mexican
    hat applied to the walk's white steps.
    """
    h = max(1, int(np.ceil(LOCAL_REACH * sigma_px)))
    return _edge_kernels(sigma_px, 2 * h + 1, LOCAL_REACH)[:, -1].copy()


@lru_cache(maxsize=32)
def _edge_kernels(sigma_px: float, length: int, edge: float) -> np.ndarray:
    """The filter (:func:`local_kernel`) centred at each position ``c`` of a series of
    ``length`` samples from ``edge`` sigmas after its start up to where the whole filter
    fits (last column; ``c`` at least ``edge`` sigmas before the series' end too), each
    cut to the series, made orthogonal to an offset, a slope and a curvature over what is
    left, and of unit norm; rows: the series' first samples. A series too short for any
    such ``c`` gets the filter at its middle. Read-only (cached)."""
    h = max(1, int(np.ceil(LOCAL_REACH * sigma_px)))
    first = min(max(1, int(np.ceil(edge * sigma_px))), h)
    rows = min(2 * h + 1, length)
    centres = list(range(first, min(h, length - 1 - first) + 1)) or [length // 2]
    out = np.zeros((rows, len(centres)))
    for col, c in enumerate(centres):
        idx = np.arange(max(0, c - h), min(c + h + 1, rows))
        t = (idx - c) / sigma_px
        k = (3.0 * t - t ** 3) * np.exp(-0.5 * t * t)
        basis, _ = np.linalg.qr(np.column_stack([np.ones_like(t), t, t * t]))
        k = k - basis @ (basis.T @ k)
        out[idx, col] = k / max(float(np.sqrt(np.sum(k * k))), _TINY)
    out.setflags(write=False)
    return out


def _local_batch(F: np.ndarray, period_px: float) -> np.ndarray:
    """:func:`local_evidence` of B lines of one length, (B,)."""
    from scipy.signal import fftconvolve

    level = sliding_period_mean(F, period_px)
    profile_std = _profile(F, period_px)[0].std(axis=1)
    sigma = LOCAL_SCALE * period_px
    n = level.shape[1]
    edges = _edge_kernels(sigma, n, LOCAL_EDGE)
    k = local_kernel(sigma)
    # near the ends: the filter cut to the line (from both ends; the filter is odd)
    m = edges.shape[0]
    best = np.maximum(np.abs(level[:, :m] @ edges).max(axis=1),
                      np.abs(level[:, ::-1][:, :m] @ edges).max(axis=1))  # fmt: skip
    if n >= k.size:  # where the whole filter lies within the line
        inner = fftconvolve(level, k[None, ::-1], mode="valid", axes=1)
        best = np.maximum(best, np.abs(inner).max(axis=1))
    return np.log(best / (profile_std + _TINY) + 1e-3)


def local_evidence(lines: list[np.ndarray] | np.ndarray, period_px: float) -> np.ndarray:
    """What a line shows of a local anomaly: a few stick-slip cycles whose level differs
    from their neighbours', as a point defect or an adsorbate makes them.

    A defect's potential bump adds its force ``-dV/dx`` to the stick phases it spans:
    the cycles on its near side sit higher, those on its far side lower, over a few
    lattice periods, while a drift or a crosstalk curve moves the level smoothly. The
    line's level (its mean over a sliding window of exactly one lattice period, which
    any lattice-periodic pattern leaves constant) is correlated with
    :func:`local_kernel` of std :data:`LOCAL_SCALE` lattice periods at every position
    at least :data:`LOCAL_EDGE` sigmas from the line's ends (cut to the line near them);
    the evidence is ``ln`` of the largest absolute response over the std of the line's
    lattice-periodic profile. Dimensionless (a ratio of forces, a width in lattice
    periods); an FFT convolution per line. What a normal line shows depends on its
    noise and on its own stick-slip irregularity; the per-map pooling judges it against
    the other lines of the map (:mod:`stickslip.estimators.pooling`).

    Parameters
    ----------
    lines : list of ndarray, or ndarray (B, L)
        Mapped lines (force, nN) on a grid with ``period_px`` pixels per lattice period;
        lines of one length are computed together.
    period_px : float
        The lattice period in pixels of that grid.

    Returns
    -------
    ndarray (B,)
        Zeros for a line shorter than two periods (nothing to compare).
    """
    return _by_length(lines, period_px, _local_batch, ())
