"""The one lattice mapping: a trace on lattice ``a`` read as one on the reference ``a0``.

The PT model is self-similar in the lattice spacing. Substituting ``x = s x'`` with
``s = a / a0`` and keeping the force unchanged turns a trace on lattice ``a`` with
``(U0, K)`` into one on ``a0`` with ``U0' = U0 / s`` and ``K' = K s``: ``F_max = pi U0 / a``,
the stick slope ``K eta / (1 + eta)`` and ``eta = 2 pi^2 U0 / (K a^2)`` are all preserved.
So positions are divided by ``s``, the trace is resampled (pixel means) onto the
reference pixel, an estimator reads it, and ``U0 = U0' s``, ``K = K' / s`` map the answer
back. Exact in the athermal limit; the scan velocity and the temperature act only
through thermal activation, which the mapping does not carry over (docs/explanation/learned-model.md
gives the error this leaves). Every learned estimator maps through this module.
"""

from __future__ import annotations

import numpy as np

from stickslip.conditions import Reference

PIXEL_TOLERANCE = 1e-3  # relative pixel-size mismatch below which no resampling is done
MAX_PIXEL_RATIO = 4.0  # coarser pixels (under ~3 per lattice spacing) cannot be read


def resample_mean(x_nm: np.ndarray, force_nN: np.ndarray, pixel_nm: float) -> np.ndarray:
    """Resample a recorded line onto pixels of ``pixel_nm``, each the mean force over its travel.

    A recorded sample ``i`` is the mean force over its pixel's travel ``[x_i, x_{i+1}]``
    (the last one as wide as its predecessor), which fixes the integral of the force over
    every union of pixels. The new pixel ``[x_0 + j d, x_0 + (j + 1) d]`` gets the mean of
    that integral, taking the force as constant inside each recorded pixel (exact
    wherever a new pixel edge falls on a recorded one). Pixels that would run past the
    line are dropped.

    ``force_nN`` may hold many lines on the same positions, shape (..., n): each row is
    resampled alike, at the cost of one (the interpolation weights are shared).
    """
    x = np.asarray(x_nm, dtype=float)
    f = np.asarray(force_nN, dtype=float)
    edges = np.append(x, x[-1] + (x[-1] - x[-2]))
    n_new = int(np.floor((edges[-1] - edges[0]) / pixel_nm + 1e-9))
    if n_new < 1:
        return np.empty(f.shape[:-1] + (0,))
    zero = np.zeros(f.shape[:-1] + (1,))
    cum = np.concatenate([zero, np.cumsum(f * np.diff(edges), axis=-1)], axis=-1)
    new_edges = edges[0] + np.arange(n_new + 1) * pixel_nm
    # np.interp's piecewise-linear interpolation, its weights computed once for all rows
    j = np.clip(np.searchsorted(edges, new_edges, side="right") - 1, 0, edges.size - 2)
    width = edges[j + 1] - edges[j]
    w = np.divide(new_edges - edges[j], width, out=np.ones_like(width), where=width > 0)
    w = np.clip(w, 0.0, 1.0)
    at = cum[..., j] + w * (cum[..., j + 1] - cum[..., j])
    return np.diff(at, axis=-1) / pixel_nm


def resample_to_pixel(x_nm: np.ndarray, force_nN: np.ndarray, pixel_nm: float
                      ) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """A line on pixels of ``pixel_nm`` starting at ``x_nm[0]``, as an instrument sampling
    at that pixel would record it: where the new pixels are coarser, the mean force over
    each new pixel centred on its position (the recorded samples taken as constant over
    pixels centred on theirs); where they are finer, linear interpolation. Returns the
    new positions and forces."""
    x = np.asarray(x_nm, dtype=float)
    f = np.asarray(force_nN, dtype=float)
    h = x[1] - x[0]
    xn = np.arange(x[0], x[-1], pixel_nm)
    if pixel_nm <= h:
        return xn, np.interp(xn, x, f)
    edges = np.concatenate([[x[0] - h / 2], x + h / 2])
    integral = np.concatenate([[0.0], np.cumsum(f) * h])
    e = np.concatenate([xn - pixel_nm / 2, [xn[-1] + pixel_nm / 2]])
    return xn, np.diff(np.interp(e, edges, integral)) / pixel_nm


def lattice_ratio(lattice_nm: float | np.ndarray, reference: Reference) -> np.ndarray:
    """``s = a / a0``."""
    return np.asarray(lattice_nm, dtype=float) / reference.lattice_nm


def to_reference(x_nm: np.ndarray, force_nN: np.ndarray, lattice_nm: float,
                 reference: Reference) -> np.ndarray:  # fmt: skip
    """The force of a trace on the reference lattice and pixel (1-D array).

    Positions are divided by ``s = a / a0``; a line already on the reference pixel
    (every step within 0.1 % of it) is returned as it is, any other is resampled
    (:func:`resample_mean`). ``force_nN`` may hold many lines on the same positions,
    shape (..., n); they are mapped together.
    """
    s = float(lattice_nm) / reference.lattice_nm
    x = np.asarray(x_nm, float) / s
    f = np.asarray(force_nN, float)
    step = np.diff(x)
    if step.size and np.all(np.abs(step / reference.pixel_nm - 1.0) < PIXEL_TOLERANCE):
        return f
    return resample_mean(x, f, reference.pixel_nm)


def refusal(x_nm: np.ndarray, lattice_nm: float, reference: Reference,
            min_pixels: int) -> str | None:  # fmt: skip
    """Why a trace cannot be mapped and read (one line), or None when it can.

    Refused: pixels coarser than ``MAX_PIXEL_RATIO`` reference pixels (fewer than ~3 per
    lattice spacing), or fewer than ``min_pixels`` pixels once mapped.
    """
    x = np.asarray(x_nm, float)
    s = float(lattice_nm) / reference.lattice_nm
    span = float(x[-1] - x[0])
    pixel = span / max(x.size - 1, 1)
    limit = MAX_PIXEL_RATIO * reference.pixel_nm * s
    if pixel > limit:
        return (f"pixel {pixel:.3g} nm does not resolve the {lattice_nm:.3g} nm lattice "
                f"(pixels <= {limit:.3g} nm needed)")  # fmt: skip
    mapped = span / s / reference.pixel_nm
    if mapped < min_pixels:
        return (f"too short: covers {span:.3g} nm, {mapped:.0f} reference pixels; at least "
                f"{min_pixels} ({min_pixels * reference.pixel_nm * s:.3g} nm) needed")  # fmt: skip
    return None
