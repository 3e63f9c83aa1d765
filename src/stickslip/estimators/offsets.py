"""The offset and the compression one line cannot tell from friction, carried in its <F>
interval.

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

A compression of large signals (photodetector or amplifier saturation) is the same
kind of ambiguity: it bends the top of each stick as the contact's own precursor
softening does, so one line cannot tell a compressed signal from a softer contact, and
only the first lowers the recorded mean below the friction. A calibration that never
met it does not widen for it (``benchmarks/families.py``, saturation left out). Its
term (:class:`CompressionPrior`, by default the saturation family's documented range,
:class:`stickslip.simulators.effects.Saturation`) puts the truth above what the line
shows by ``d = c m3``: none with probability ``1 - p``, else ``c`` uniform in
``compression``, where ``m3 = mean(F^3) / max(F^2)`` is read off the line
(:func:`compression_moment`; exact for a cubic compression ``F - c M (F / M)^3``, the
leading order of ``S tanh(F / S)``). The interval is then the equal-tailed one of ``e +
o + d`` (:func:`friction_bounds`), no longer symmetric about the estimate. The term is
a statement, not a fit, like the offsets': where the calibration met saturation it
comes on top of the error seen there (conservative).

The model's error ``e`` enters these sums as a Gaussian, but its tails are heavier, and
a Gaussian with its 95 % half-width has too wide a core: added to an offset as wide as
the error or wider, the sum's interval came out too wide. The calibration therefore
fits a factor on the model's half-width per level (:func:`fit_friction_factor`), so
that the sum's interval covers the level on the calibration lines, each line's own
error meeting the priors' offsets and compressions (:func:`friction_coverage`): the
priors stay statements, and the fit is the same whether or not the calibration lines
carry those effects.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit, prange

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

    def draw(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """``n`` offsets (nN) drawn from the prior: 0 with probability ``1 - p``."""
        size = rng.uniform(*self.mean_nN, n)
        return size * rng.choice([-1.0, 1.0], n) * (rng.random(n) < self.p)

    def to_dict(self) -> dict:
        return {"p": self.p, "mean_nN": list(self.mean_nN)}

    @classmethod
    def from_dict(cls, d: dict) -> OffsetPrior:
        return cls(p=float(d["p"]), mean_nN=(float(d["mean_nN"][0]), float(d["mean_nN"][1])))


@dataclass(frozen=True)
class CompressionPrior:
    """Compressions of large signals a line may carry: none with probability ``1 - p``,
    else ``c = 1 - F_out / F`` at the line's largest force uniform in ``compression``."""

    p: float = 0.3
    compression: tuple[float, float] = (0.0, 0.15)

    @classmethod
    def from_family(cls, family) -> CompressionPrior:
        """From a saturation family's settings (anything with ``enabled``, ``p`` and
        ``compression``, e.g. :class:`stickslip.simulators.effects.Saturation`)."""
        p = float(family.p) if family.enabled else 0.0
        return cls(p=p, compression=(float(family.compression[0]),
                                     float(family.compression[1])))  # fmt: skip

    def to_dict(self) -> dict:
        return {"p": self.p, "compression": list(self.compression)}

    @classmethod
    def from_dict(cls, d: dict) -> CompressionPrior:
        c = d["compression"]
        return cls(p=float(d["p"]), compression=(float(c[0]), float(c[1])))


def compression_moment(force_nN: np.ndarray) -> float | np.ndarray:
    """``mean(F^3) / max(F^2)`` of one line (nN): a compression ``c`` at the line's
    largest force lowers its mean by ``c`` times this (:class:`CompressionPrior`).

    ``force_nN`` of shape (..., n) gives one value per line, shape (...); a 1-D line
    gives a float.
    """
    f = np.asarray(force_nN, float)
    if f.shape[-1] == 0:
        return 0.0 if f.ndim == 1 else np.zeros(f.shape[:-1])
    sq = f * f
    top = np.max(sq, axis=-1)
    cube = np.mean(sq * f, axis=-1)
    m3 = np.divide(cube, top, out=np.zeros_like(cube), where=top > 0.0)
    return float(m3) if f.ndim == 1 else m3


# ------------------------------------------------------------------ the numerics
# One scalar CDF of e + o + d, compiled, behind every public function here: the
# intervals are solved per line, and at inference speed (thousands of lines a second)
# array-at-a-time numpy spent as long on them as the networks did.
_SQRT_2PI = math.sqrt(2.0 * math.pi)
_SQRT_2 = math.sqrt(2.0)


@njit(cache=True)
def _ndtr(x: float) -> float:
    return 0.5 * math.erfc(-x / _SQRT_2)


@njit(cache=True)
def _psi(x: float) -> float:
    """An antiderivative of the standard normal CDF: ``x Phi(x) + phi(x)``."""
    return x * _ndtr(x) + math.exp(-0.5 * x * x) / _SQRT_2PI


@njit(cache=True)
def _psi2(x: float) -> float:
    """An antiderivative of :func:`_psi`: ``((x^2 + 1) Phi(x) + x phi(x)) / 2``."""
    return 0.5 * ((x * x + 1.0) * _ndtr(x) + x * math.exp(-0.5 * x * x) / _SQRT_2PI)


@njit(cache=True)
def _uniform(x: float, s: float, lo: float, hi: float) -> float:
    """``E Phi((x - u) / s)`` for ``u`` uniform on ``[lo, hi]`` (``hi > lo``)."""
    return s / (hi - lo) * (_psi((x - lo) / s) - _psi((x - hi) / s))


@njit(cache=True)
def _two_uniform(x: float, s: float, lo1: float, hi1: float, lo2: float, hi2: float) -> float:
    """``E Phi((x - u - w) / s)`` for independent ``u`` uniform on ``[lo1, hi1]`` and
    ``w`` uniform on ``[lo2, hi2]`` (both ranges of positive width)."""
    w = s * s / ((hi1 - lo1) * (hi2 - lo2))
    return w * (_psi2((x - lo1 - lo2) / s) - _psi2((x - hi1 - lo2) / s)
                - _psi2((x - lo1 - hi2) / s) + _psi2((x - hi1 - hi2) / s))  # fmt: skip


@njit(cache=True)
def _offset_cdf(x: float, s: float, po: float, a: float, b: float) -> float:
    """``P(e + o <= x)``: ``e ~ N(0, s^2)``, ``o`` none with probability ``1 - po``, else
    ``|o|`` uniform on ``[a, b]`` with either sign."""
    none = _ndtr(x / s)
    if po <= 0.0 or b <= a:
        return none
    return (1.0 - po) * none + po * 0.5 * (_uniform(x, s, a, b) + _uniform(x, s, -b, -a))


@njit(cache=True)
def _cdf(x: float, s: float, po: float, a: float, b: float, pc: float, c0: float,
         c1: float, m3: float) -> float:  # fmt: skip
    """``P(e + o + d <= x)``, ``d = c m3`` none with probability ``1 - pc``, else ``c``
    uniform on ``[c0, c1]``."""
    base = _offset_cdf(x, s, po, a, b)
    if pc <= 0.0:
        return base
    d0, d1 = min(c0 * m3, c1 * m3), max(c0 * m3, c1 * m3)
    if d1 - d0 < 1e-3 * s:  # a range much narrower than the model's error: a point
        shifted = _offset_cdf(x - 0.5 * (d0 + d1), s, po, a, b)
    else:
        shifted = _uniform(x, s, d0, d1)
        if po > 0.0 and b > a:
            both = 0.5 * (_two_uniform(x, s, a, b, d0, d1) + _two_uniform(x, s, -b, -a, d0, d1))
            shifted = (1.0 - po) * shifted + po * both
    return (1.0 - pc) * base + pc * shifted


@njit(cache=True, parallel=True)
def _cdf_rows(x, s, m3, po, a, b, pc, c0, c1):  # pragma: no cover - compiled
    out = np.empty(x.size)
    for i in prange(x.size):
        out[i] = _cdf(x[i], max(s[i], 1e-12), po, a, b, pc, c0, c1, m3[i])
    return out


@njit(cache=True, parallel=True)
def _quantile_rows(q, s, m3, po, a, b, pc, c0, c1, iterations):  # pragma: no cover
    """Per row, the ``q`` quantile of ``e + o + d``: regula falsi (Illinois variant:
    superlinear, and it keeps the bracket), from a bracket that holds it."""
    out = np.empty(s.size)
    for i in prange(s.size):
        si = max(s[i], 1e-12)
        # within the model's own 8 sigma, the largest offset and the largest shift
        reach = 8.0 * si + max(b, 0.0) + max(abs(c0), abs(c1)) * abs(m3[i])
        lo, hi = -reach, reach
        flo = _cdf(lo, si, po, a, b, pc, c0, c1, m3[i]) - q
        fhi = _cdf(hi, si, po, a, b, pc, c0, c1, m3[i]) - q
        side = 0
        for _ in range(iterations):
            if fhi - flo <= 0.0:
                break
            c = (lo * fhi - hi * flo) / (fhi - flo)
            fc = _cdf(c, si, po, a, b, pc, c0, c1, m3[i]) - q
            if abs(fc) < 1e-11:  # converged (in probability)
                lo, hi, flo, fhi = c, c, 0.0, 0.0
                break
            if fc < 0.0:  # the quantile is in (c, hi)
                lo, flo = c, fc
                if side == 1:  # an end kept twice in a row has its value halved
                    fhi *= 0.5
                side = 1
            else:
                hi, fhi = c, fc
                if side == -1:
                    flo *= 0.5
                side = -1
        out[i] = lo if abs(flo) < abs(fhi) else hi
    return out


def _terms(offset: OffsetPrior | None, compression: CompressionPrior | None):
    po, (a, b) = (0.0, (0.0, 0.0)) if offset is None else (offset.p, offset.mean_nN)
    pc, (c0, c1) = (0.0, (0.0, 0.0)) if compression is None else (compression.p,
                                                                   compression.compression)
    return float(po), float(a), float(b), float(pc), float(c0), float(c1)


def _rows(*arrays) -> list[np.ndarray]:
    shape = np.broadcast_shapes(*(np.shape(v) for v in arrays))
    return [np.ascontiguousarray(np.broadcast_to(np.asarray(v, float), shape)).ravel()
            for v in arrays] + [shape]  # fmt: skip


def friction_cdf(x: np.ndarray, sigma: np.ndarray, offset: OffsetPrior | None,
                 compression: CompressionPrior | None = None,
                 m3_nN: np.ndarray | float = 0.0) -> np.ndarray:  # fmt: skip
    """``P(e + o + d <= x)``: ``e ~ N(0, sigma^2)``, ``o`` from ``offset``, ``d = c m3``
    with ``c`` from ``compression`` (None: no such term)."""
    x, s, m3, shape = _rows(x, sigma, m3_nN)
    return _cdf_rows(x, s, m3, *_terms(offset, compression)).reshape(shape)


def offset_cdf(x: np.ndarray, sigma: np.ndarray, prior: OffsetPrior | None) -> np.ndarray:
    """``P(e + o <= x)`` for ``e ~ N(0, sigma^2)`` and ``o`` from ``prior`` (None: no o)."""
    return friction_cdf(x, sigma, prior)


def coverage(t: np.ndarray, sigma: np.ndarray, prior: OffsetPrior) -> np.ndarray:
    """``P(|e + o| <= t)`` for ``e ~ N(0, sigma^2)`` and ``o`` from ``prior``."""
    return offset_cdf(t, sigma, prior) - offset_cdf(-np.asarray(t, float), sigma, prior)


def friction_bounds(half_width: np.ndarray, level: float, offset: OffsetPrior | None,
                    compression: CompressionPrior | None = None,
                    m3_nN: np.ndarray | float = 0.0,
                    iterations: int = 40) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """The equal-tailed ``level`` interval of ``e + o + d`` about 0, as ``(lo, hi)``
    (add the estimate to both), where ``e`` is Gaussian with central half-width
    ``half_width`` at ``level``, ``o`` is drawn from ``offset`` and ``d = c m3`` from
    ``compression`` (:class:`CompressionPrior`; ``m3_nN`` per row,
    :func:`compression_moment`). Without a compression term this is ``(-t, t)``, ``t =
    offset_half_width(half_width, level, offset)``; without either term, ``(-h, h)``.

    ``iterations`` bounds the root finder's steps; it stops earlier once converged.
    """
    h, m3, shape = _rows(half_width, m3_nN)
    terms = _terms(offset, compression)
    p_offset, p_compression = terms[0], terms[3]
    if p_offset <= 0.0 and p_compression <= 0.0:
        return -h.reshape(shape), h.reshape(shape)
    s = h / gaussian_z(level)
    lo = _quantile_rows(0.5 - level / 2, s, m3, *terms, iterations)
    if p_compression <= 0.0:  # symmetric: the upper bound mirrors the lower
        return lo.reshape(shape), -lo.reshape(shape)
    hi = _quantile_rows(0.5 + level / 2, s, m3, *terms, iterations)
    return lo.reshape(shape), hi.reshape(shape)


def offset_half_width(half_width: np.ndarray, level: float,
                      prior: OffsetPrior | None) -> np.ndarray:  # fmt: skip
    """The half-width of the central ``level`` interval of ``e + o``, where ``e`` is
    Gaussian with central half-width ``half_width`` at ``level`` and ``o`` is drawn from
    ``prior`` (None or ``p = 0``: ``half_width`` unchanged). Adding a symmetric offset
    never narrows a symmetric unimodal error's interval (Anderson), and it moves it by
    at most the largest offset.

    Parameters
    ----------
    half_width : array of the model's half-widths at ``level`` (nN).
    level : the interval's level, in (0, 1).
    prior : the offsets' prior.
    """
    return friction_bounds(half_width, level, prior)[1]


#: Levels at which :func:`fit_friction_factor` fits the <F> model part's factor (the
#: single-line interval is made at 0.68 and 0.95; the others shape it in between).
FRICTION_LEVELS = (0.5, 0.68, 0.8, 0.9, 0.95, 0.99)


def friction_coverage(error_nN: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                      offset: OffsetPrior | None, compression: CompressionPrior | None = None,
                      m3_nN: np.ndarray | float = 0.0) -> np.ndarray:  # fmt: skip
    """Per row, the probability that ``r + o + d`` lies in ``[lo, hi]``, where ``r`` is
    the model's own signed error (``error_nN``: what the line shows minus the estimate)
    and ``o``, ``d`` are drawn from ``offset`` and ``compression``: the coverage an
    interval ``estimate + [lo, hi]`` has for a line with that error, the offset and the
    compression being the priors' statements rather than the line's own."""
    r, lo, hi, m3, shape = _rows(error_nN, lo, hi, m3_nN)
    terms = _terms(offset, compression)
    tiny = np.full(r.size, 1e-6)  # nN: o + d alone (a point mass when neither term is on)
    up = _cdf_rows(hi - r, tiny, m3, *terms)
    down = _cdf_rows(lo - r, tiny, m3, *terms)
    return (up - down).reshape(shape)


def fit_friction_factor(error_nN: np.ndarray, model_half_width, offset: OffsetPrior | None,
                        compression: CompressionPrior | None = None,
                        m3_nN: np.ndarray | float = 0.0, weights: np.ndarray | None = None,
                        levels: tuple[float, ...] = FRICTION_LEVELS,
                        steps: int = 16) -> np.ndarray:  # fmt: skip
    """Factors on the model's own <F> half-width that make the single-line interval
    (:func:`friction_bounds`) cover ``level`` of calibration lines, one per level.

    :func:`friction_bounds` takes the model's error ``e`` as Gaussian. It is not: its
    tails are heavier (the 95 % half-width is about three times the 68 % one, not two),
    so a Gaussian with the right 95 % half-width has too wide a core, and added to an
    offset as wide as the model's error or wider, the sum's interval comes out too wide
    (measured on the bundled model's family calibration: 0.958 expected coverage for a
    95 % interval). The factor ``f`` is fitted so that the weighted mean of
    :func:`friction_coverage` over the calibration lines, with half-width ``f h``, is
    the level: the lines' own errors meet the priors' offsets and compressions, so the
    fit holds whether or not the calibration lines carry those effects.

    Parameters
    ----------
    error_nN : (N,) each calibration line's signed error, target minus estimate (nN).
    model_half_width : callable ``level -> (N,)`` half-widths of the model's own
        interval at that level (nN).
    offset, compression, m3_nN : the terms of :func:`friction_bounds`.
    weights : (N,) row weights (default equal).
    levels : the levels to fit.
    steps : bisection steps in ``ln f`` over ``[ln 0.2, ln 5]``.

    Returns
    -------
    ndarray (len(levels),)
    """
    r = np.asarray(error_nN, float)
    w = np.ones(r.size) if weights is None else np.asarray(weights, float)
    w = w / w.sum()
    out = np.empty(len(levels))
    for j, q in enumerate(levels):
        h = np.asarray(model_half_width(q), float)

        def covered(log_f: float, h=h, q=q) -> float:
            lo, hi = friction_bounds(np.exp(log_f) * h, q, offset, compression, m3_nN)
            return float(np.sum(w * friction_coverage(r, lo, hi, offset, compression, m3_nN)))

        a, b = np.log(0.2), np.log(5.0)
        for _ in range(steps):
            mid = 0.5 * (a + b)
            a, b = (mid, b) if covered(mid) < q else (a, mid)
        out[j] = np.exp(0.5 * (a + b))
    return out
