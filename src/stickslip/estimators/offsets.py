"""The offset one line cannot tell from friction, carried in its <F> interval.

An additive offset of the lateral signal that does not reverse with the scan
(topography crosstalk, a detector offset) shifts a line's mean force, and one line
cannot tell it from friction (PHYSICS.md: "an honest interval carries that
ambiguity"). A model can learn where friction sits on a line, but not an offset that
leaves no other trace on it; a calibration that never met such offsets cannot size it
either. So the single-line <F> interval is made of two parts:

- the model's own error ``e`` (its calibrated interval, fitted against the friction
  *plus* the line's offset: what the line shows);
- the offset ``o`` from a documented prior (:class:`OffsetPrior`, by default the
  crosstalk family's documented range, :class:`stickslip.simulators.effects.Crosstalk`):
  none with probability ``1 - p``, else ``|o|`` uniform in ``mean_nN`` with either sign.

:func:`offset_half_width` turns the model's half-width at a level into that of ``e +
o``, exactly (``e`` Gaussian with the same half-width). The prior is not fitted on
data, so it holds as well for offsets the calibration never saw; a trace/retrace pair
cancels the offset (:mod:`stickslip.estimators.pairs`), and its interval is the
model's alone.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import ndtr

from stickslip.estimators.calibration import gaussian_z


@dataclass(frozen=True)
class OffsetPrior:
    """Offsets a line may carry: none with probability ``1 - p``; else ``|o|`` uniform in
    ``mean_nN`` (nN), either sign equally likely."""

    p: float = 0.5
    mean_nN: tuple[float, float] = (0.02, 0.5)

    @classmethod
    def from_family(cls, family) -> OffsetPrior:
        """From a crosstalk family's settings (anything with ``enabled``, ``p`` and
        ``mean_nN``, e.g. :class:`stickslip.simulators.effects.Crosstalk`)."""
        p = float(family.p) if family.enabled else 0.0
        return cls(p=p, mean_nN=(float(family.mean_nN[0]), float(family.mean_nN[1])))

    def to_dict(self) -> dict:
        return {"p": self.p, "mean_nN": list(self.mean_nN)}

    @classmethod
    def from_dict(cls, d: dict) -> OffsetPrior:
        return cls(p=float(d["p"]), mean_nN=(float(d["mean_nN"][0]), float(d["mean_nN"][1])))


def _psi(x: np.ndarray) -> np.ndarray:
    """An antiderivative of the standard normal CDF: ``x Phi(x) + phi(x)``."""
    return x * ndtr(x) + np.exp(-0.5 * x * x) / np.sqrt(2.0 * np.pi)


def coverage(t: np.ndarray, sigma: np.ndarray, prior: OffsetPrior) -> np.ndarray:
    """``P(|e + o| <= t)`` for ``e ~ N(0, sigma^2)`` and ``o`` from ``prior``."""
    t, s = np.asarray(t, float), np.maximum(np.asarray(sigma, float), 1e-12)
    none = ndtr(t / s) - ndtr(-t / s)
    a, b = prior.mean_nN
    if prior.p <= 0.0 or b <= a:
        return none

    def mean_cdf(c):  # E_o Phi((c - o) / s), o uniform on [a, b]
        return s / (b - a) * (_psi((c - a) / s) - _psi((c - b) / s))

    # by symmetry -o gives the same as +o
    some = mean_cdf(t) - mean_cdf(-t)
    return (1.0 - prior.p) * none + prior.p * some


def offset_half_width(half_width: np.ndarray, level: float, prior: OffsetPrior | None,
                      iterations: int = 48) -> np.ndarray:  # fmt: skip
    """The half-width of the central ``level`` interval of ``e + o``, where ``e`` is
    Gaussian with central half-width ``half_width`` at ``level`` and ``o`` is drawn from
    ``prior`` (None or ``p = 0``: ``half_width`` unchanged).

    Parameters
    ----------
    half_width : array of the model's half-widths at ``level`` (nN).
    level : the interval's level, in (0, 1).
    prior : the offsets' prior.
    iterations : bisection steps (48 reach double precision on the bracket).
    """
    h = np.asarray(half_width, float)
    if prior is None or prior.p <= 0.0:
        return h
    sigma = h / gaussian_z(level)
    # adding a symmetric offset never narrows a symmetric unimodal error's interval
    # (Anderson), and it moves it by at most the largest offset
    lo, hi = h.copy(), h + prior.mean_nN[1]
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        low = coverage(mid, sigma, prior) < level
        lo, hi = np.where(low, mid, lo), np.where(low, hi, mid)
    return 0.5 * (lo + hi)

