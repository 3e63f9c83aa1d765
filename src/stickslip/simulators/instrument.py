"""What a real instrument does to a clean simulated trace (pure functions on arrays).

Each effect acts on forces of shape ``(N, pixels)`` in nN and draws its randomness from
the generator it is given, so a bench or a training pipeline is reproducible from its
seed. :class:`InstrumentEffects` holds ranges for every effect; :func:`apply_instrument`
draws one value per trace from them and applies the whole chain in the order a signal
meets them: contact (precursor softening), detector bandwidth (low-pass), noise (white
and 1/f), slow offset drift, digitisation.

Listed in ../shared/PHYSICS.md ("What real traces contain that the clean model does
not"). Barrier disorder and long-wavelength modulation are substrate effects and live in
the simulator (:class:`~stickslip.simulators.config.SubstrateAugmentation`); lattice
spacing and scan velocity are simulation settings.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from scipy.signal import lfilter


def white_noise(shape: tuple[int, int], sigma_nN: np.ndarray, rng: np.random.Generator):
    """Gaussian white noise with per-trace standard deviation ``sigma_nN`` (N,)."""
    return rng.standard_normal(shape) * np.asarray(sigma_nN)[:, None]


def pink_noise(shape: tuple[int, int], sigma_nN: np.ndarray, rng: np.random.Generator):
    """1/f (pink) noise along each line, scaled to per-trace std ``sigma_nN`` (N,)."""
    n, p = shape
    spec = rng.standard_normal((n, p // 2 + 1)) + 1j * rng.standard_normal((n, p // 2 + 1))
    f = np.fft.rfftfreq(p)
    f[0] = f[1]
    spec /= np.sqrt(f)[None, :]
    spec[:, 0] = 0.0
    x = np.fft.irfft(spec, n=p, axis=1)
    x /= x.std(axis=1, keepdims=True) + 1e-30
    return x * np.asarray(sigma_nN)[:, None]


def lowpass(force_nN: np.ndarray, tau_px: np.ndarray) -> np.ndarray:
    """First-order detector response with time constant ``tau_px`` (in pixels, per trace).

    A slip that is instantaneous in the simulation is smeared over about ``tau_px``
    pixels, as by a detector or feedback of finite bandwidth. ``tau_px = 0`` is a no-op.
    """
    out = np.array(force_nN, dtype=float, copy=True)
    for i, tau in enumerate(np.asarray(tau_px, float)):
        if tau <= 0:
            continue
        alpha = 1.0 - np.exp(-1.0 / tau)
        zi = [(1.0 - alpha) * out[i, 0]]  # start in steady state at the first value
        out[i], _ = lfilter([alpha], [1.0, alpha - 1.0], out[i], zi=zi)
    return out


def offset_drift(
    shape: tuple[int, int], amplitude_nN: np.ndarray, rng: np.random.Generator
) -> np.ndarray:
    """Slow offset drift over a line, peak size ``amplitude_nN`` (N,).

    A random quadratic in the scan position plus a constant offset of up to half the
    amplitude: a single line cannot tell that offset from friction.
    """
    n, p = shape
    t = np.linspace(-1.0, 1.0, p)[None, :]
    c1 = rng.uniform(-1, 1, (n, 1))
    c2 = rng.uniform(-1, 1, (n, 1))
    d = c1 * t + c2 * (t**2 - 1.0 / 3.0)
    d /= np.max(np.abs(d), axis=1, keepdims=True) + 1e-30
    d += rng.uniform(-0.5, 0.5, (n, 1))
    return d * np.asarray(amplitude_nN)[:, None]


def digitise(force_nN: np.ndarray, bits: int, full_scale_nN: np.ndarray) -> np.ndarray:
    """Quantise to ``2**bits`` levels over ``[-full_scale, +full_scale]`` (mid-rise ADC)."""
    fs = np.asarray(full_scale_nN, float)[:, None]
    step = 2.0 * fs / 2**bits
    q = (np.floor(force_nN / step) + 0.5) * step
    return np.clip(q, -fs + 0.5 * step, fs - 0.5 * step)


def precursor_softening(force_nN: np.ndarray, strength: np.ndarray, power: float = 3.0):
    """Soften the contact before slips: the stick slope falls near the top of each stick.

    Within each stick segment (between slips), with ``r`` the fraction of the rise
    completed, the slope is scaled by ``1 - s r^power``, so the force reaches
    ``1 - s/(power + 1)`` of its original rise before the slip: the peak is rounded and
    lowered as precursor micro-slips of an extended contact do. ``s = 0`` is a no-op.
    """
    out = np.array(force_nN, dtype=float, copy=True)
    for i, s in enumerate(np.asarray(strength, float)):
        if s <= 0:
            continue
        F = out[i]
        span = np.percentile(F, 99) - np.percentile(F, 1)
        dF = np.diff(F)
        slip = np.flatnonzero(dF < -0.25 * span) + 1  # first pixel after each drop
        edges = np.r_[0, slip, F.size]
        for a, b in zip(edges[:-1], edges[1:], strict=True):
            if b - a < 3:
                continue
            seg = F[a:b]
            lo, hi = seg.min(), seg.max()
            if hi - lo <= 0:
                continue
            r = np.clip((seg - lo) / (hi - lo), 0.0, 1.0)
            out[i, a:b] = lo + (hi - lo) * (r - s * r ** (power + 1) / (power + 1))
    return out


@dataclass(frozen=True)
class InstrumentEffects:
    """Ranges ``(low, high)`` of the instrument effects; each trace draws uniformly.

    Attributes
    ----------
    white_nN : noise std of white detector noise.
    pink_nN : std of 1/f noise along the line.
    lowpass_px : detector time constant in pixels.
    drift_nN : peak size of the slow offset drift over a line.
    softening : precursor-softening strength ``s`` (0 = none, 1 = slope vanishes at top).
    bits : ADC resolution (0 = no digitisation); full scale is 1.5x the trace's |F| max,
        rounded up to a power of two in nN as a real gain setting would be.
    """

    white_nN: tuple[float, float] = (0.0, 0.0)
    pink_nN: tuple[float, float] = (0.0, 0.0)
    lowpass_px: tuple[float, float] = (0.0, 0.0)
    drift_nN: tuple[float, float] = (0.0, 0.0)
    softening: tuple[float, float] = (0.0, 0.0)
    bits: int = 0

    def replace(self, **changes) -> InstrumentEffects:
        return dataclasses.replace(self, **changes)


#: The "laboratory" effects of the test bench: what a careful AFM measurement carries.
LAB = InstrumentEffects(
    white_nN=(0.01, 0.08),
    pink_nN=(0.0, 0.05),
    lowpass_px=(0.0, 2.0),
    drift_nN=(0.0, 0.1),
    softening=(0.0, 0.4),
    bits=16,
)


EFFECT_NAMES = ("white_nN", "pink_nN", "lowpass_px", "drift_nN", "softening")


@dataclass(frozen=True)
class EffectsMixture:
    """Instruments drawn per trace: each trace takes its effect values from one of
    ``components``, chosen with probabilities ``weights``.

    A training prior that is dense where measurements usually are (a typical
    instrument) and still covers broad ranges as a tail. All components share one ADC
    resolution ``bits``.
    """

    components: tuple[InstrumentEffects, ...]
    weights: tuple[float, ...]

    def __post_init__(self) -> None:
        if len(self.components) != len(self.weights) or not self.components:
            raise ValueError("EffectsMixture needs one weight per component")
        if min(self.weights) < 0 or not np.isclose(sum(self.weights), 1.0):
            raise ValueError(f"mixture weights must be >= 0 and sum to 1, not {self.weights}")
        if len({c.bits for c in self.components}) != 1:
            raise ValueError("the mixture's components must share one ADC resolution")

    @property
    def bits(self) -> int:
        return self.components[0].bits


def draw_instrument(effects: InstrumentEffects | EffectsMixture, n: int,
                    rng: np.random.Generator) -> dict[str, np.ndarray]:  # fmt: skip
    """Per-trace effect values (dict of arrays of length ``n``) drawn from the ranges
    (for a mixture: each trace from the component it draws)."""
    if isinstance(effects, EffectsMixture):
        pick = rng.choice(len(effects.weights), size=n, p=np.asarray(effects.weights))
        draws = [draw_instrument(c, n, rng) for c in effects.components]
        return {name: np.choose(pick, [d[name] for d in draws]) for name in EFFECT_NAMES}
    return {name: rng.uniform(*getattr(effects, name), n) for name in EFFECT_NAMES}


def apply_instrument(
    force_nN: np.ndarray,
    effects: InstrumentEffects | EffectsMixture,
    rng: np.random.Generator,
    values: dict[str, np.ndarray] | None = None,
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Apply the effect chain to clean traces; returns the traces and the drawn values."""
    F = np.atleast_2d(np.asarray(force_nN, float))
    v = draw_instrument(effects, F.shape[0], rng) if values is None else values
    F = precursor_softening(F, v["softening"])
    F = lowpass(F, v["lowpass_px"])
    F = F + white_noise(F.shape, v["white_nN"], rng) + pink_noise(F.shape, v["pink_nN"], rng)
    F = F + offset_drift(F.shape, v["drift_nN"], rng)
    if effects.bits:
        fs = 2.0 ** np.ceil(np.log2(1.5 * np.max(np.abs(F), axis=1) + 1e-9))
        F = digitise(F, effects.bits, fs)
    return F, v
