"""Network inputs: windows of consecutive pixels and the two input recipes.

Pure numpy. A trace of P pixels gives windows of ``p`` consecutive pixels every
``stride`` pixels (a strided view, no copy). Two recipes turn a window into a vector:

- ``raw``: the ``p`` forces (nN);
- ``pi`` (physics-informed, reference paper): the ``p`` forces followed by the
  ``p - 1`` processed slopes. The slope is the finite-difference derivative
  ``s = dF/dx`` in nN/nm (= N/m) between neighbouring pixels; negative slopes are set
  to zero (only the stick branches carry K); the rectified slope ``r`` is weighted by
  the sigmoid ``f(r) = 1 / (1 + exp(-(r - mu) / sigma))`` with ``mu`` the mean of ``r``
  over the window and ``sigma = 15 nN/nm``; ``r f(r)`` is sorted ascending (the MLP
  has no positional encoding). ``2p - 1`` inputs in all.

The reference paper states ``sigma = 15`` without units; nN/nm is the natural unit of a
force-versus-distance slope and matches the range of stick slopes here (1-50 N/m).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from stickslip.conditions import GRAPHITE, Reference

RECIPES = ("raw", "pi")


class FeatureError(ValueError):
    """A trace or setting the features cannot be built from; ``str()`` is one line."""


@dataclass(frozen=True)
class FeatureSpec:
    """How a trace becomes network inputs (saved inside the model file).

    Attributes
    ----------
    recipe : {"raw", "pi"}
        Input recipe.
    window : int
        Pixels per window ``p``.
    stride : int
        Pixels between the starts of consecutive windows at inference.
    train_stride : int
        Stride used to cut training windows (denser: more windows per trajectory).
    pixel_nm : float
        Pixel size of the training traces; other traces are resampled to it.
    lattice_nm : float
        Lattice spacing of the training traces (reference of the lattice mapping).
    velocity_nm_per_s, temperature_K : float
        Scan velocity and temperature of the training traces (recorded, and compared
        with the trace's to warn about the mapping's limits).
    sigma_nN_per_nm : float
        Sigmoid smearing of the ``pi`` recipe.
    """

    recipe: str = "pi"
    window: int = 64
    stride: int = 64
    train_stride: int = 8
    pixel_nm: float = GRAPHITE.pixel_nm
    lattice_nm: float = GRAPHITE.lattice_nm
    velocity_nm_per_s: float = GRAPHITE.velocity_nm_per_s
    temperature_K: float = GRAPHITE.temperature_K
    sigma_nN_per_nm: float = 15.0

    def __post_init__(self) -> None:
        if self.recipe not in RECIPES:
            raise FeatureError(f"unknown feature recipe '{self.recipe}' (have: raw, pi)")
        if self.window < 4:
            raise FeatureError(f"window must be at least 4 pixels (got {self.window})")
        if self.stride < 1 or self.train_stride < 1:
            raise FeatureError("strides must be at least 1 pixel")
        if not (self.pixel_nm > 0 and self.lattice_nm > 0 and self.sigma_nN_per_nm > 0):
            raise FeatureError("pixel size, lattice spacing and sigma must be > 0")

    @property
    def reference(self) -> Reference:
        """The training conditions (lattice, pixel, velocity, temperature)."""
        return Reference(self.lattice_nm, self.pixel_nm, self.velocity_nm_per_s,
                         self.temperature_K)  # fmt: skip

    @property
    def n_inputs(self) -> int:
        """Length of one input vector: ``p`` (raw) or ``2p - 1`` (pi)."""
        return self.window if self.recipe == "raw" else 2 * self.window - 1

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> FeatureSpec:
        return cls(**{k: d[k] for k in cls.__dataclass_fields__ if k in d})


def n_windows(pixels: int, window: int, stride: int) -> int:
    """Number of windows a trace of ``pixels`` samples gives (0 if it is too short)."""
    return 0 if pixels < window else (pixels - window) // stride + 1


def windows(force: np.ndarray, window: int, stride: int) -> np.ndarray:
    """Windows of ``window`` consecutive samples every ``stride`` samples (a view).

    Parameters
    ----------
    force : ndarray (..., P)
        One trace or a stack of equally long traces.

    Returns
    -------
    ndarray (..., W, window)
        ``W = (P - window) // stride + 1`` windows per trace.

    Raises
    ------
    FeatureError
        If a trace is shorter than one window.
    """
    force = np.asarray(force)
    if force.shape[-1] < window:
        raise FeatureError(f"{force.shape[-1]} pixels, at least {window} needed for one window")
    view = np.lib.stride_tricks.sliding_window_view(force, window, axis=-1)
    return view[..., ::stride, :]


def processed_slopes(win: np.ndarray, pixel_nm: float, sigma: float = 15.0) -> np.ndarray:
    """The ``pi`` recipe's slope part: rectified, sigmoid-weighted, sorted ``dF/dx``.

    Parameters
    ----------
    win : ndarray (..., p)
        Force windows in nN.
    pixel_nm : float
        Pixel spacing in nm.
    sigma : float
        Sigmoid smearing in nN/nm.

    Returns
    -------
    ndarray (..., p - 1)
        ``sort(r * f(r))`` with ``r = max(dF/dx, 0)``, ``f(r) = 1/(1 + exp(-(r - mu)/sigma))``
        and ``mu`` the window mean of ``r``.
    """
    r = np.maximum(np.diff(win, axis=-1) / pixel_nm, 0.0)
    mu = r.mean(axis=-1, keepdims=True)
    # the exponent capped below the dtype's overflow: a steep slope far above the mean
    # then weighs ~0, as the sigmoid says, without an overflow warning
    cap = float(np.log(np.finfo(r.dtype).max)) - 2.0 if r.dtype.kind == "f" else 700.0
    weighted = r / (1.0 + np.exp(np.minimum(-(r - mu) / sigma, cap)))
    return np.sort(weighted, axis=-1)


def window_features(win: np.ndarray, spec: FeatureSpec) -> np.ndarray:
    """Input vectors of windows for the spec's recipe (float32, shape (..., n_inputs))."""
    win = np.asarray(win, dtype=np.float32)
    if spec.recipe == "raw":
        return np.ascontiguousarray(win)
    slopes = processed_slopes(win, spec.pixel_nm, spec.sigma_nN_per_nm).astype(np.float32)
    return np.concatenate([win, slopes], axis=-1)


