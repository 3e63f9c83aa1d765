"""A broad nuisance prior for simulated friction lines, organised in effect families.

Every effect a real AFM line carries beyond the clean Prandtl-Tomlinson force
(../shared/PHYSICS.md, "What real traces contain..." and "Other effects of real
instruments") belongs to one *family* of :data:`FAMILIES`. A :class:`NuisancePrior` holds,
per family, whether it is enabled, the probability ``p`` that a line gets it and the
ranges of its parameters. :func:`draw` draws per-line parameters (a :class:`Draw`, which
records which families each line got); :func:`apply` applies them to a batch of lines
``(N, pixels)`` and returns the corrupted force and the conditions an estimator is told
(:class:`Stated`).

Two implementations. Every family has a ``"train"`` implementation (used to corrupt
training batches on the fly, fast) and an independent ``"eval"`` one with a different
functional form over the same documented ranges (for honest evaluation sets). With the
same seed both draw the same documented sizes (amplitudes, counts, strengths); only the
shapes differ (``stated_conditions`` is the exception: its eval errors have another
distribution over the same range).

Independent streams. Each family draws from a random stream of its own (derived from
the generator given), so disabling one family (:meth:`NuisancePrior.without`) leaves
every other family's draws and realisations unchanged.

Signal path (the order of :func:`apply`):

1. contact: ``precursor`` (the contact force; its mean is the <F> truth, see
   :func:`contact_force`);
2. support: ``piezo`` (the support positions behind the nominal x axis);
3. lever: ``cantilever`` (torsional ringing), ``crosstalk`` (topography, additive);
4. photodetector: ``saturation``, ``gain``;
5. electronics: ``detector`` low-pass, then additive ``detector`` noise and drift,
   ``telegraph``, ``mains``, ``spikes``;
6. ADC: ``detector`` digitisation.

Truth conventions (PHYSICS.md): no family changes U0 or K (the cantilever family's
series split only sets the lever's in-contact resonance: the quasi-static force through
springs in series is the same everywhere, so the recorded force is still K (X - x) with K
the series stiffness); <F> is the mean of :func:`contact_force` (precursor softening
lowers the contact force itself; every other family is an instrument artefact).

Time. The controller samples uniformly in time: pixel ``i`` spans ``[i T, (i + 1) T]``
with ``T = pixel_nm / v`` (the true velocity). Families defined in time (``cantilever``,
``mains``) use this time base; ``piezo`` warps the support positions, not the time.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numba as nb
import numpy as np

from stickslip.conditions import ROOM_TEMPERATURE_K
from stickslip.simulators.instrument import (
    InstrumentEffects,
)

#: Effect families, in the order of the signal path is NOT implied (see module docs).
FAMILIES: tuple[str, ...] = (
    "precursor",
    "piezo",
    "cantilever",
    "crosstalk",
    "saturation",
    "gain",
    "detector",
    "telegraph",
    "mains",
    "spikes",
    "stated_conditions",
)

#: The two independent implementations of every family.
IMPLEMENTATIONS: tuple[str, ...] = ("train", "eval")

#: Families whose effect is an additive term (recorded by :func:`apply` under ``record``).
ADDITIVE: tuple[str, ...] = ("crosstalk", "detector", "telegraph", "mains", "spikes")

Range = tuple[float, float]
PRIOR_FORMAT = 1


# --------------------------------------------------------------------------------------
# family settings
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Precursor:
    """Precursor softening of the contact before each slip (contact force changes).

    ``drop``: fraction of each stick's rise lost at its top (uniform); today's
    :func:`~stickslip.simulators.instrument.precursor_softening` reaches 0.125.
    """

    enabled: bool = True
    p: float = 0.5
    drop: Range = (0.0, 0.5)


@dataclass(frozen=True)
class Piezo:
    """Non-uniform support motion (creep, hysteresis, nonlinearity) behind a uniform x axis.

    ``warp``: largest ``|X_true - x_nominal|`` over the line, as a fraction of the line
    length (uniform, either sign); the ends are fixed (the mean velocity is
    ``stated_conditions``' business).
    """

    enabled: bool = True
    p: float = 0.5
    warp: Range = (0.0, 0.05)


@dataclass(frozen=True)
class Cantilever:
    """Torsional dynamics of the lever: ringing after slips.

    ``free_resonance_kHz`` (log-uniform): the lever's free torsional resonance;
    ``lever_share`` (uniform): ``K / k_lever``, the lever's part of the series compliance,
    which pins the in-contact resonance at ``f_free / sqrt(1 - lever_share)``;
    ``quality`` (log-uniform): Q of the in-contact mode.
    """

    enabled: bool = True
    p: float = 0.5
    free_resonance_kHz: Range = (1.0, 50.0)
    lever_share: Range = (0.2, 0.9)
    quality: Range = (3.0, 100.0)


@dataclass(frozen=True)
class Crosstalk:
    """Topography crosstalk into the lateral channel (additive, does not reverse).

    ``mean_nN``: ``|mean|`` of the term over the line (uniform, either sign);
    ``rms_nN``: std of its variation along the line (log-uniform).
    """

    enabled: bool = True
    p: float = 0.5
    mean_nN: Range = (0.02, 0.5)
    rms_nN: Range = (0.005, 0.2)


@dataclass(frozen=True)
class Saturation:
    """Photodetector / amplifier compression of large signals.

    ``compression``: ``1 - F_out / F`` at the line's largest positive force (uniform).
    """

    enabled: bool = True
    p: float = 0.3
    compression: Range = (0.0, 0.15)


@dataclass(frozen=True)
class Gain:
    """Lateral sensitivity drifting along a line (multiplicative, mean 1).

    ``variation``: largest ``|g - 1|`` over the line (uniform).
    """

    enabled: bool = True
    p: float = 0.3
    variation: Range = (0.0, 0.08)


@dataclass(frozen=True)
class Detector:
    """Today's detector effects (:mod:`~stickslip.simulators.instrument`), all uniform.

    ``white_nN`` and ``pink_nN``: noise std; ``lowpass_px``: detector time constant in
    pixels; ``drift_nN``: peak size of the slow offset drift (with a constant offset of up
    to half of it); ``bits``: ADC resolution (0 = none).
    """

    enabled: bool = True
    p: float = 0.8
    white_nN: Range = (0.0, 0.12)
    pink_nN: Range = (0.0, 0.08)
    lowpass_px: Range = (0.0, 3.0)
    drift_nN: Range = (0.0, 0.15)
    bits: int = 16

    @classmethod
    def from_effects(cls, effects: InstrumentEffects, p: float = 0.8) -> Detector:
        """The detector family with the ranges of an :class:`InstrumentEffects` (its
        ``softening`` belongs to :class:`Precursor` and is not carried over)."""
        return cls(p=p, white_nN=effects.white_nN, pink_nN=effects.pink_nN,
                   lowpass_px=effects.lowpass_px, drift_nN=effects.drift_nN,
                   bits=effects.bits)  # fmt: skip


@dataclass(frozen=True)
class Telegraph:
    """Burst (random-telegraph) noise: the offset jumps between two levels.

    ``amplitude_nN`` (log-uniform): the jump; ``switches`` (uniform integer): jumps per line.
    """

    enabled: bool = True
    p: float = 0.2
    amplitude_nN: Range = (0.02, 0.3)
    switches: tuple[int, int] = (1, 8)


@dataclass(frozen=True)
class Mains:
    """Electrical pickup at the mains frequency and its harmonics, in time.

    ``amplitude_nN`` (log-uniform): rms of the pickup; ``frequency_Hz``: the grid's
    fundamental, one of these per line.
    """

    enabled: bool = True
    p: float = 0.5
    amplitude_nN: Range = (0.005, 0.15)
    frequency_Hz: tuple[float, ...] = (50.0, 60.0)


@dataclass(frozen=True)
class Spikes:
    """Isolated glitches of one to a few pixels.

    ``count`` (uniform integer) per line; ``height_nN`` (log-uniform): std of the spike
    heights on the line; ``width_px`` (uniform integer): pixels per spike.
    """

    enabled: bool = True
    p: float = 0.3
    count: tuple[int, int] = (1, 6)
    height_nN: Range = (0.1, 2.0)
    width_px: tuple[int, int] = (1, 3)


@dataclass(frozen=True)
class StatedConditions:
    """The velocity and temperature an estimator is told differ from the true ones.

    ``velocity_error``, ``temperature_error``: ``stated / true - 1``.
    """

    enabled: bool = True
    p: float = 0.5
    velocity_error: Range = (-0.15, 0.15)
    temperature_error: Range = (-0.15, 0.15)


_FAMILY_CLASSES: dict[str, type] = {
    "precursor": Precursor,
    "piezo": Piezo,
    "cantilever": Cantilever,
    "crosstalk": Crosstalk,
    "saturation": Saturation,
    "gain": Gain,
    "detector": Detector,
    "telegraph": Telegraph,
    "mains": Mains,
    "spikes": Spikes,
    "stated_conditions": StatedConditions,
}


def _check_family(family: str) -> None:
    if family not in FAMILIES:
        raise ValueError(f"unknown effect family {family!r}; families: {', '.join(FAMILIES)}")


@dataclass(frozen=True)
class NuisancePrior:
    """Per-family settings (enabled flag, probability per line, ranges) of the prior.

    The defaults are the broad training prior. Save with :meth:`to_dict` next to a model
    or data set; :meth:`from_dict` reads it back (a family missing from the dict was not
    known when it was written, so it comes back disabled).
    """

    precursor: Precursor = field(default_factory=Precursor)
    piezo: Piezo = field(default_factory=Piezo)
    cantilever: Cantilever = field(default_factory=Cantilever)
    crosstalk: Crosstalk = field(default_factory=Crosstalk)
    saturation: Saturation = field(default_factory=Saturation)
    gain: Gain = field(default_factory=Gain)
    detector: Detector = field(default_factory=Detector)
    telegraph: Telegraph = field(default_factory=Telegraph)
    mains: Mains = field(default_factory=Mains)
    spikes: Spikes = field(default_factory=Spikes)
    stated_conditions: StatedConditions = field(default_factory=StatedConditions)

    def family(self, family: str) -> Any:
        """The settings of one family."""
        _check_family(family)
        return getattr(self, family)

    def replace(self, family: str, **changes: Any) -> NuisancePrior:
        """A copy with one family's settings changed (e.g. ``replace("mains", p=1.0)``)."""
        _check_family(family)
        return dataclasses.replace(
            self, **{family: dataclasses.replace(getattr(self, family), **changes)}
        )

    def without(self, *families: str) -> NuisancePrior:
        """A copy in which ``families`` are disabled (never applied)."""
        out = self
        for f in families:
            out = out.replace(f, enabled=False)
        return out

    def only(self, *families: str, p: float | None = None) -> NuisancePrior:
        """A copy in which only ``families`` are enabled (with probability ``p`` if given)."""
        for f in families:
            _check_family(f)
        out = self.without(*(f for f in FAMILIES if f not in families))
        for f in families:
            out = out.replace(f, enabled=True, **({} if p is None else {"p": p}))
        return out

    def enabled(self) -> tuple[str, ...]:
        """The enabled families (with ``p > 0``)."""
        return tuple(f for f in FAMILIES if getattr(self, f).enabled and getattr(self, f).p > 0)

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-able dict (``format`` and one entry per family)."""
        return {"format": PRIOR_FORMAT,
                **{f: dataclasses.asdict(getattr(self, f)) for f in FAMILIES}}  # fmt: skip

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> NuisancePrior:
        """Inverse of :meth:`to_dict`; unknown families raise, missing ones are disabled."""
        if d.get("format", PRIOR_FORMAT) != PRIOR_FORMAT:
            raise ValueError(f"nuisance prior format {d.get('format')} is not {PRIOR_FORMAT}")
        unknown = set(d) - set(FAMILIES) - {"format"}
        if unknown:
            raise ValueError(f"unknown effect families in the prior: {sorted(unknown)}")
        kw = {}
        for f in FAMILIES:
            klass = _FAMILY_CLASSES[f]
            if f not in d:
                kw[f] = klass(enabled=False)
                continue
            kw[f] = klass(**{k: tuple(v) if isinstance(v, list) else v for k, v in d[f].items()})
        return cls(**kw)


# --------------------------------------------------------------------------------------
# draws
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Draw:
    """Per-line effect parameters (``n`` lines) and which families each line got.

    Attributes
    ----------
    implementation : "train" or "eval".
    applied : ndarray (n, len(FAMILIES)) of bool
        ``applied[i, j]``: line ``i`` gets family ``FAMILIES[j]``.
    params : dict family -> dict name -> ndarray (n,)
        Drawn for every line; only the lines marked in ``applied`` use them.
    """

    implementation: str
    applied: np.ndarray
    params: dict[str, dict[str, np.ndarray]]

    @property
    def n(self) -> int:
        return self.applied.shape[0]

    def mask(self, family: str) -> np.ndarray:
        """(n,) bool: the lines that get ``family``."""
        _check_family(family)
        return self.applied[:, FAMILIES.index(family)]

    def families_of(self, line: int) -> tuple[str, ...]:
        """The families applied to one line."""
        return tuple(f for f, a in zip(FAMILIES, self.applied[line], strict=True) if a)

    def coverage(self) -> dict[str, float]:
        """Fraction of lines that got each family."""
        return {f: float(self.applied[:, j].mean()) for j, f in enumerate(FAMILIES)}

    def take(self, rows: np.ndarray) -> Draw:
        """The draw of a subset of lines."""
        rows = np.asarray(rows)
        params = {f: {k: v[rows] for k, v in p.items()} for f, p in self.params.items()}
        return Draw(self.implementation, self.applied[rows], params)

    def table(self) -> dict[str, np.ndarray]:
        """Flat columns: ``applied.<family>`` and ``<family>.<param>`` (for saving)."""
        out = {f"applied.{f}": self.applied[:, j] for j, f in enumerate(FAMILIES)}
        for f, p in self.params.items():
            out.update({f"{f}.{k}": v for k, v in p.items()})
        return out


def _streams(rng: np.random.Generator) -> dict[str, np.random.Generator]:
    """One independent generator per family (fixed order, whatever is enabled)."""
    seeds = rng.integers(0, 2**63 - 1, size=len(FAMILIES))
    return {f: np.random.default_rng(int(s)) for f, s in zip(FAMILIES, seeds, strict=True)}


def _loguniform(rng: np.random.Generator, r: Range, n: int) -> np.ndarray:
    return np.exp(rng.uniform(np.log(r[0]), np.log(r[1]), n))


def _signed(rng: np.random.Generator, r: Range, n: int) -> np.ndarray:
    """Uniform magnitude in ``r`` with a random sign."""
    return rng.uniform(r[0], r[1], n) * rng.choice([-1.0, 1.0], n)


def _precursor_lost(kappa: np.ndarray) -> np.ndarray:
    """Fraction of the rise lost at full strength by the eval (exponential) softening."""
    return (np.expm1(kappa) - kappa) / (kappa * np.expm1(kappa))


_KAPPA_GRID = np.geomspace(1e-3, 8.0, 400)
_KAPPA_LOST = _precursor_lost(_KAPPA_GRID)  # decreasing from 0.5


def _draw_family(f: str, cfg: Any, n: int, rng: np.random.Generator, impl: str):
    """The parameters of one family for ``n`` lines (common sizes first, then shapes)."""
    u = rng.uniform
    if f == "precursor":
        drop = u(*cfg.drop, n)
        if impl == "train":  # slope scaled by 1 - s r^power: lost = s / (power + 1)
            top = np.floor(np.clip(1.0 / np.maximum(drop, 1e-12) - 1.0, 1.0, 3.0))
            power = 1.0 + np.floor(u(0, 1, n) * top)  # an integer in 1..top
            return {"drop": drop, "power": power}
        kmax = np.interp(np.minimum(drop, 0.5), _KAPPA_LOST[::-1], _KAPPA_GRID[::-1])
        kmin = np.minimum(0.05, kmax)
        return {"drop": drop, "kappa": kmin + u(0, 1, n) * (kmax - kmin)}
    if f == "piezo":
        d = {"warp": _signed(rng, cfg.warp, n)}
        if impl == "train":
            d["exponent"] = u(1.5, 4.0, n)
        else:
            d["creep_time"] = u(0.02, 0.3, n)  # fraction of the line
            d["creep_share"] = u(0.0, 1.0, n)
        return d
    if f == "cantilever":
        d = {"free_resonance_kHz": _loguniform(rng, cfg.free_resonance_kHz, n),
             "lever_share": u(*cfg.lever_share, n),
             "quality": _loguniform(rng, cfg.quality, n)}  # fmt: skip
        d["resonance_kHz"] = d["free_resonance_kHz"] / np.sqrt(1.0 - d["lever_share"])
        if impl == "eval":  # a weaker second mode (torsion-bending coupling)
            d["second_ratio"] = u(2.0, 3.5, n)
            d["second_weight"] = u(0.0, 0.3, n)
        return d
    if f == "crosstalk":
        return {"mean_nN": _signed(rng, cfg.mean_nN, n), "rms_nN": _loguniform(rng, cfg.rms_nN, n)}
    if f == "saturation":
        d = {"compression": u(*cfg.compression, n)}
        if impl == "eval":
            d["asymmetry"] = u(0.0, 1.0, n)  # negative side compressed by compression * this
        return d
    if f == "gain":
        return {"variation": u(*cfg.variation, n)}
    if f == "detector":
        return {"white_nN": u(*cfg.white_nN, n), "pink_nN": u(*cfg.pink_nN, n),
                "lowpass_px": u(*cfg.lowpass_px, n), "drift_nN": u(*cfg.drift_nN, n),
                "bits": np.full(n, int(cfg.bits))}  # fmt: skip
    if f == "telegraph":
        return {"amplitude_nN": _loguniform(rng, cfg.amplitude_nN, n),
                "switches": rng.integers(cfg.switches[0], cfg.switches[1] + 1, n)}  # fmt: skip
    if f == "mains":
        d = {"amplitude_nN": _loguniform(rng, cfg.amplitude_nN, n),
             "frequency_Hz": rng.choice(np.asarray(cfg.frequency_Hz, float), n)}  # fmt: skip
        if impl == "train":  # harmonics 1, 2, 3
            d["harmonic_2"], d["harmonic_3"] = u(0, 0.5, n), u(0, 0.3, n)
        else:  # odd harmonics 1, 3, 5 and the grid's frequency deviation
            d["harmonic_3"], d["harmonic_5"] = u(0, 0.6, n), u(0, 0.3, n)
            d["frequency_deviation"] = u(-0.004, 0.004, n)
        return d
    if f == "spikes":
        return {"count": rng.integers(cfg.count[0], cfg.count[1] + 1, n),
                "height_nN": _loguniform(rng, cfg.height_nN, n),
                "width_min_px": np.full(n, int(cfg.width_px[0])),
                "width_max_px": np.full(n, int(cfg.width_px[1]))}  # fmt: skip
    if f == "stated_conditions":
        ve, te = cfg.velocity_error, cfg.temperature_error
        if impl == "train":
            return {"velocity_error": u(*ve, n), "temperature_error": u(*te, n)}
        # eval: scan-size calibration error (truncated normal) and a tip warmer than the
        # room (stated temperature below the true one)
        v = np.clip(rng.normal(0.5 * (ve[0] + ve[1]), 0.25 * (ve[1] - ve[0]), n), *ve)
        return {"velocity_error": v, "temperature_error": u(min(te[0], 0.0), min(te[1], 0.0), n)}
    raise AssertionError(f)


def draw(prior: NuisancePrior, n: int, rng: np.random.Generator,
         implementation: str = "train") -> Draw:  # fmt: skip
    """Per-line parameters of every family for ``n`` lines.

    Parameters
    ----------
    prior : the families' settings.
    n : number of lines.
    rng : source of randomness (each family gets a stream of its own from it).
    implementation : "train" or "eval".

    Returns
    -------
    Draw
        Parameters for every family and line; ``applied`` marks the lines that get each
        family (never a disabled one).
    """
    if implementation not in IMPLEMENTATIONS:
        raise ValueError(f"implementation must be one of {IMPLEMENTATIONS}, not {implementation!r}")
    streams = _streams(rng)
    applied = np.zeros((n, len(FAMILIES)), bool)
    params = {}
    for j, f in enumerate(FAMILIES):
        cfg, r = getattr(prior, f), streams[f]
        on = r.random(n) < cfg.p
        applied[:, j] = on & bool(cfg.enabled)
        params[f] = _draw_family(f, cfg, n, r, implementation)
    return Draw(implementation, applied, params)


# --------------------------------------------------------------------------------------
# numba kernels (each loops over the selected rows of a C-contiguous (N, P) float array)
# --------------------------------------------------------------------------------------


@nb.njit(cache=True)
def _one_pole(F, rows, alpha):  # pragma: no cover - compiled
    """In place: y[k] = alpha u[k] + (1 - alpha) y[k-1], starting in steady state."""
    P = F.shape[1]
    for j in range(rows.size):
        i, a = rows[j], alpha[j]
        y = F[i, 0]
        for k in range(P):
            y = a * F[i, k] + (1.0 - a) * y
            F[i, k] = y


@nb.njit(cache=True)
def _ring_iir(F, rows, z, alpha):  # pragma: no cover - compiled
    """In place: exact pixel-mean response of a 2nd-order low-pass (unit DC gain) to a
    piecewise-constant input: y[k] = u[k] + Re(alpha w[k]), w[k] = z w[k-1] + (u[k] - u[k-1])."""
    P = F.shape[1]
    for j in range(rows.size):
        i = rows[j]
        w = 0.0 + 0.0j
        prev = F[i, 0]
        for k in range(P):
            u = F[i, k]
            w = z[j] * w + (u - prev)
            prev = u
            F[i, k] = u + (alpha[j] * w).real


@nb.njit(cache=True)
def _ring_kernels(f0T, quality, ratio, weight, L):  # pragma: no cover - compiled
    """Pixel-domain kernels g (n, L) of h(t) = sum_modes e^{-w t / 2Q} sin(w t) (unit
    integral per mode, weights 1 and ``weight``): g[j] = int h(tau) (1 - |tau - j|)+ dtau
    (tau in pixels), by the midpoint rule with 40 nodes per oscillation or more, each mode
    normalised by its own quadrature sum (so the DC gain is 1 to rounding)."""
    n = f0T.size
    g = np.zeros((n, L))
    part = np.zeros(L)
    for j in range(n):
        for m in range(2):
            wgt = 1.0 if m == 0 else weight[j]
            if wgt <= 0.0:
                continue
            fT = f0T[j] * (1.0 if m == 0 else ratio[j])
            om = 2.0 * np.pi * fT
            sig = om / (2.0 * quality[j])
            M = min(max(int(40.0 * fT) + 16, 16), 8192)
            nodes = int((14.0 / sig + 2.0) * M)  # to e^-14 of the envelope
            step = np.exp(complex(-sig, om) / M)
            e = np.exp(complex(-sig, om) * (0.5 / M))
            part[:] = 0.0
            total = 0.0
            for q in range(nodes):
                tau = (q + 0.5) / M
                h = e.imag
                e = e * step
                total += h
                j0 = int(tau)
                if j0 + 1 > L:
                    continue
                fr = tau - j0
                part[j0] += h * (1.0 - fr)
                if j0 + 1 < L:
                    part[j0 + 1] += h * fr
            g[j] += part * (wgt / total)  # unit integral of the quadrature itself
        g[j] /= 1.0 + (weight[j] if weight[j] > 0.0 else 0.0)
    return g


@nb.njit(cache=True)
def _add_sines(F, rows, omega, phase, amp):  # pragma: no cover - compiled
    """In place: F[i, k] += sum_m amp sin(omega k + phase) (Chebyshev recurrence)."""
    P = F.shape[1]
    for j in range(rows.size):
        i = rows[j]
        for m in range(omega.shape[1]):
            a = amp[j, m]
            if a == 0.0:
                continue
            c2 = 2.0 * np.cos(omega[j, m])
            s0 = a * np.sin(phase[j, m] - omega[j, m])
            s1 = a * np.sin(phase[j, m])
            for k in range(P):
                F[i, k] += s1
                s0, s1 = s1, c2 * s1 - s0


@nb.njit(cache=True)
def _standardise(v, mean, rms):  # pragma: no cover - compiled
    """In place: each row of v to exactly the given mean and std."""
    n, P = v.shape
    for i in range(n):
        m = v[i].mean()
        sd = np.sqrt(np.mean((v[i] - m) ** 2)) + 1e-30
        for k in range(P):
            v[i, k] = mean[i] + rms[i] * (v[i, k] - m) / sd


@nb.njit(cache=True)
def _resample_rows(F, rows, pos):  # pragma: no cover - compiled
    """In place: row rows[j] of F linearly interpolated at fractional pixels pos[j]."""
    P = F.shape[1]
    buf = np.empty(P)
    for j in range(rows.size):
        i = rows[j]
        buf[:] = F[i]
        for k in range(P):
            x = pos[j, k]
            i0 = min(max(int(np.floor(x)), 0), P - 2)
            fr = x - i0
            F[i, k] = buf[i0] + (buf[i0 + 1] - buf[i0]) * fr


@nb.njit(cache=True)
def _power_warp(d, g, P):  # pragma: no cover - compiled
    """Support positions (pixels) u - d (u - u^g) / m(g), u = k / (P - 1), clipped to [0, 1]."""
    n = d.size
    pos = np.empty((n, P))
    logu = np.log(np.arange(1, P) / (P - 1))
    for j in range(n):
        us = g[j] ** (-1.0 / (g[j] - 1.0))
        scale = d[j] / (us - us ** g[j])
        pos[j, 0] = 0.0
        for k in range(1, P):
            u = k / (P - 1)
            ug = np.exp(g[j] * logu[k - 1])
            pos[j, k] = (P - 1) * min(max(u - scale * (u - ug), 0.0), 1.0)
    return pos


@nb.njit(cache=True)
def _saturate_tanh(F, rows, c):  # pragma: no cover - compiled
    """In place: F -> S tanh(F / S) with S tanh(M / S) = (1 - c) M, M = max |F| of the row."""
    P = F.shape[1]
    for j in range(rows.size):
        i = rows[j]
        if c[j] <= 0.0:
            continue
        M = np.abs(F[i]).max()
        if M <= 0.0:
            continue
        u = np.sqrt(3.0 * c[j])
        for _ in range(60):  # Newton on tanh(u) - (1 - c) u = 0
            t = np.tanh(u)
            du = (t - (1.0 - c[j]) * u) / (c[j] - t * t)
            u -= du
            if abs(du) < 1e-14 * u:
                break
        S = M / u
        for k in range(P):
            F[i, k] = S * (1.0 - 2.0 / (np.exp(2.0 * F[i, k] / S) + 1.0))  # S tanh(F / S)


@nb.njit(cache=True)
def _add_drift(F, rows, c1, c2, off, amp):  # pragma: no cover - compiled
    """In place: F += amp (shape / max|shape| + off), shape = c1 t + c2 (t^2 - 1/3) on
    t in [-1, 1]: :func:`~stickslip.simulators.instrument.offset_drift`'s form."""
    P = F.shape[1]
    d = np.empty(P)
    for j in range(rows.size):
        i = rows[j]
        top = 0.0
        for k in range(P):
            t = -1.0 + 2.0 * k / (P - 1)
            d[k] = c1[j] * t + c2[j] * (t * t - 1.0 / 3.0)
            top = max(top, abs(d[k]))
        for k in range(P):
            F[i, k] += amp[j] * (d[k] / (top + 1e-30) + off[j])


@nb.njit(cache=True)
def _digitise_rows(F, rows, bits, fs):  # pragma: no cover - compiled
    """In place: :func:`~stickslip.simulators.instrument.digitise` of each row."""
    P = F.shape[1]
    for j in range(rows.size):
        i = rows[j]
        if bits[j] <= 0:
            continue
        step = 2.0 * fs[j] / 2.0 ** bits[j]
        lo, hi = -fs[j] + 0.5 * step, fs[j] - 0.5 * step
        for k in range(P):
            q = (np.floor(F[i, k] / step) + 0.5) * step
            F[i, k] = min(max(q, lo), hi)


@nb.njit(cache=True)
def _telegraph_levels(counts, pos, start, P):  # pragma: no cover - compiled
    """Two-level signal (k, P) of 0/1: row j starts at start[j] and flips at its
    ``counts[j]`` positions (consecutive in ``pos``; a position met twice cancels)."""
    k = counts.size
    out = np.empty((k, P))
    flip = np.zeros(P, np.int64)
    q = 0
    for j in range(k):
        flip[:] = 0
        for _ in range(counts[j]):
            flip[pos[q]] += 1
            q += 1
        level = start[j]
        for i in range(P):
            level = (level + flip[i]) % 2
            out[j, i] = level
    return out


@nb.njit(cache=True)
def _add_scaled(F, rows, x, sigma, standardise):  # pragma: no cover - compiled
    """In place: F[rows[j]] += sigma[j] * x[j], x[j] first made zero-mean and unit-std if
    ``standardise``."""
    P = F.shape[1]
    for j in range(rows.size):
        i = rows[j]
        m, sd = 0.0, 1.0
        if standardise:
            m = x[j].mean()
            sd = np.sqrt(np.mean((x[j] - m) ** 2)) + 1e-30
        a = sigma[j] / sd
        for k in range(P):
            F[i, k] += a * (x[j, k] - m)


@nb.njit(cache=True)
def _row_absmax(F, rows):  # pragma: no cover - compiled
    """max |F| of each selected row."""
    out = np.empty(rows.size)
    for j in range(rows.size):
        out[j] = np.abs(F[rows[j]]).max()
    return out


@nb.njit(cache=True)
def _soften(F, rows, strength, shape, mode):  # pragma: no cover - compiled
    """In place precursor softening of each stick segment (between slips, found on the
    original force as drops below -1/4 of the line's range). With r the fraction of the
    segment's rise, the force becomes lo + (hi - lo) S(r):
    mode 0: S = r - s r^(b+1)/(b+1), b integer  (slope 1 - s r^b);
    mode 1: S = r - s ((e^(b r) - 1)/b - r)/(e^b - 1)   (slope 1 - s (e^(b r) - 1)/(e^b - 1))."""
    P = F.shape[1]
    edges = np.empty(P + 1, np.int64)
    for j in range(rows.size):
        i, s, b = rows[j], strength[j], shape[j]
        if s <= 0.0:
            continue
        f = F[i]
        thr = -0.25 * (f.max() - f.min())
        ne = 1
        edges[0] = 0
        for k in range(1, P):
            if f[k] - f[k - 1] < thr:
                edges[ne] = k
                ne += 1
        edges[ne] = P
        ne += 1
        for e in range(ne - 1):
            a0, a1 = edges[e], edges[e + 1]
            if a1 - a0 < 3:
                continue
            lo, hi = f[a0:a1].min(), f[a0:a1].max()
            if hi <= lo:
                continue
            for k in range(a0, a1):
                r = min(max((f[k] - lo) / (hi - lo), 0.0), 1.0)
                if mode == 0:
                    rp = r
                    for _ in range(int(b)):
                        rp *= r
                    S = r - s * rp / (b + 1.0)
                else:
                    S = r - s * (np.expm1(b * r) / b - r) / np.expm1(b)
                f[k] = lo + (hi - lo) * S


# --------------------------------------------------------------------------------------
# family implementations (act on the rows ``sel`` of F in place or return (len(sel), P))
# --------------------------------------------------------------------------------------


def _lowpass_rows(F: np.ndarray, rows: np.ndarray, tau_px: np.ndarray) -> None:
    """First-order low-pass (as :func:`~stickslip.simulators.instrument.lowpass`) in place."""
    keep = tau_px > 0
    rows, tau_px = rows[keep], tau_px[keep]
    if rows.size:
        _one_pole(F, rows.astype(np.int64), 1.0 - np.exp(-1.0 / tau_px))


def lowpass_px(force_nN: np.ndarray, tau_px: np.ndarray) -> np.ndarray:
    """Vectorised first-order detector low-pass, identical to
    :func:`stickslip.simulators.instrument.lowpass` (time constant per line in pixels)."""
    out = np.array(force_nN, dtype=float, order="C", copy=True)
    _lowpass_rows(out, np.arange(out.shape[0]), np.asarray(tau_px, float))
    return out


def _precursor(F, sel, prm, impl):
    d = prm["drop"][sel]
    if impl == "train":
        b = prm["power"][sel]
        s = d * (b + 1.0)
        _soften(F, sel, s, b, 0)
    else:
        b = prm["kappa"][sel]
        s = np.minimum(d / _precursor_lost(b), 1.0)
        _soften(F, sel, s, b, 1)


def piezo_positions(params: dict[str, np.ndarray], pixels: int, implementation: str) -> np.ndarray:
    """True support positions behind the nominal pixels, in pixel units (n, pixels).

    ``train``: power law ``u - d (u - u^gamma) / m(gamma)`` (creep lag or lead);
    ``eval``: a Rayleigh hysteresis branch ``4 u (1 - u)`` blended with logarithmic creep
    ``ln(1 + u / tau) / ln(1 + 1 / tau) - u``, normalised to peak 1, times ``-d``.
    With u = x / length; both fixed at the ends, peak displacement ``|d|`` of the line.
    """
    u = np.linspace(0.0, 1.0, pixels)[None, :]
    d = params["warp"][:, None]
    if implementation == "train":
        g = params["exponent"][:, None]
        ustar = g ** (-1.0 / (g - 1.0))
        shape = (u - u**g) / (ustar - ustar**g)
    else:
        tau = params["creep_time"][:, None]
        creep = np.log1p(u / tau) / np.log1p(1.0 / tau) - u
        creep /= creep.max(axis=1, keepdims=True)
        w = params["creep_share"][:, None]
        shape = (1.0 - w) * 4.0 * u * (1.0 - u) + w * creep
        shape /= shape.max(axis=1, keepdims=True)
    return (pixels - 1) * np.clip(u - d * shape, 0.0, 1.0)


def _piezo(F, sel, prm, impl):
    if impl == "train":
        pos = _power_warp(prm["warp"][sel], prm["exponent"][sel], F.shape[1])
    else:
        pos = piezo_positions({k: v[sel] for k, v in prm.items()}, F.shape[1], impl)
    _resample_rows(F, sel, pos)


def _cantilever(F, sel, prm, impl, pixel_s):
    f0T = prm["resonance_kHz"][sel] * 1e3 * pixel_s[sel]  # cycles per pixel
    Q = prm["quality"][sel]
    if impl == "train":
        zeta = 0.5 / Q
        wd = np.sqrt(1.0 - zeta**2)
        lam = 2.0 * np.pi * f0T * (-zeta + 1j * wd)  # pole times T
        z = np.exp(lam)
        c = -1.0 + 1j * zeta / wd  # step response 1 + Re(c e^{lambda t})
        _ring_iir(F, sel, z, c * (z - 1.0) / lam)
        return
    ratio, weight = prm["second_ratio"][sel], prm["second_weight"][sel]
    P = F.shape[1]
    L = int(min(P, max(2, np.ceil(np.max(14.0 * Q / (np.pi * f0T))) + 2)))
    g = _ring_kernels(f0T, Q, ratio, weight, L)
    u = F[sel] - F[sel, :1]
    nfft = 1 << int(np.ceil(np.log2(P + L)))
    y = np.fft.irfft(np.fft.rfft(u, nfft, axis=1) * np.fft.rfft(g, nfft, axis=1), nfft, axis=1)
    F[sel] = F[sel, :1] + y[:, :P]


def _crosstalk_rows(draw: Draw, sel: np.ndarray, x: np.ndarray, rng: np.random.Generator):
    """The crosstalk term of the lines ``sel`` (len(sel), P)."""
    k, P = sel.size, x.size
    prm = draw.params["crosstalk"]
    if draw.implementation == "train":
        lam = np.exp(rng.uniform(np.log(0.5), np.log(30.0), (k, 3)))
        omega = 2.0 * np.pi * (x[1] - x[0]) / lam
        amp = rng.uniform(0.2, 1.0, (k, 3))
        phase = rng.uniform(0.0, 2.0 * np.pi, (k, 3))
        v = np.zeros((k, P))
        _add_sines(v, np.arange(k), omega, phase + 0.5 * np.pi, amp)  # slope: cosines
    else:
        v = np.cumsum(rng.standard_normal((k, P)), axis=1)
    _standardise(v, prm["mean_nN"][sel], prm["rms_nN"][sel])
    return v


def crosstalk_term(draw: Draw, x_nm: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """The additive topography-crosstalk term of every line (n, P), zero where the line
    does not get the family, indexed by the nominal x of a forward scan.

    It does not reverse with the scan direction: pass the same term to :func:`apply` for
    a trace and its retrace (``crosstalk_nN=``) and ``(trace + retrace) / 2`` is this term
    while ``(trace - retrace) / 2`` is the friction. Each line's term has exactly the mean
    ``mean_nN`` and the std ``rms_nN`` drawn.

    ``train``: the slope of a topography made of three sinusoids (wavelengths 0.5-30 nm,
    random weights and phases); ``eval``: proportional to the height of a random-walk
    topography (optical crosstalk of the height signal).
    """
    x = np.asarray(x_nm, float)
    out = np.zeros((draw.n, x.size))
    sel = np.flatnonzero(draw.mask("crosstalk"))
    if sel.size:
        out[sel] = _crosstalk_rows(draw, sel, x, rng)
    return out


def _saturation(F, sel, prm, impl):
    c = prm["compression"][sel]
    if impl == "train":  # F -> S tanh(F / S), S tanh(M / S) = (1 - c) M
        _saturate_tanh(F, sel, c)
        return
    # eval: cubic, stronger on one side: F - c M (F / M)^3, c * asymmetry below zero
    f = F[sel]
    M = np.abs(f).max(axis=1, keepdims=True) + 1e-30
    cc = np.where(f >= 0, c[:, None], (c * prm["asymmetry"][sel])[:, None])
    F[sel] = f - cc * M * (f / M) ** 3


def _gain(F, sel, prm, impl, rng):
    P = F.shape[1]
    k = sel.size
    if impl == "train":  # slow polynomial along the line
        t = np.linspace(-1.0, 1.0, P)[None, :]
        s = rng.uniform(-1, 1, (k, 1)) * t + rng.uniform(-1, 1, (k, 1)) * (t**2 - 1.0 / 3.0)
    else:  # random walk
        s = np.cumsum(rng.standard_normal((k, P)), axis=1)
        s -= s.mean(axis=1, keepdims=True)
    s /= np.abs(s).max(axis=1, keepdims=True) + 1e-30
    g = 1.0 + prm["variation"][sel, None] * s
    F[sel] *= g
    return g


def _voss_pink(shape: tuple[int, int], sigma_nN: np.ndarray, rng: np.random.Generator):
    """1/f noise by the Voss-McCartney algorithm (row k redrawn every 2^k samples),
    zero mean and std ``sigma_nN`` per line."""
    n, P = shape
    x = np.zeros((n, P))
    idx = np.arange(P)
    for k in range(int(np.ceil(np.log2(P))) + 1):
        step = 1 << k
        off = rng.integers(0, step, (n, 1))
        vals = rng.standard_normal((n, P // step + 2))
        x += np.take_along_axis(vals, (idx[None, :] + off) // step, axis=1)
    x -= x.mean(axis=1, keepdims=True)
    x /= x.std(axis=1, keepdims=True) + 1e-30
    return x * np.asarray(sigma_nN)[:, None]


def _detector_filter(F, sel, prm, impl):
    tau = prm["lowpass_px"][sel]
    if impl == "train":
        _lowpass_rows(F, sel, tau)
    else:  # two cascaded poles of tau / 2 each (same mean delay)
        _lowpass_rows(F, sel, 0.5 * tau)
        _lowpass_rows(F, sel, 0.5 * tau)


def pink_spectrum_noise(shape: tuple[int, int], rng: np.random.Generator) -> np.ndarray:
    """1/f noise as :func:`~stickslip.simulators.instrument.pink_noise` makes it (complex
    Gaussian spectrum times f^-1/2, no DC), unnormalised, from one draw of normals."""
    n, P = shape
    m = P // 2 + 1
    spec = rng.standard_normal((n, 2 * m)).view(np.complex128)
    f = np.fft.rfftfreq(P)
    f[0] = f[1]
    w = 1.0 / np.sqrt(f)
    w[0] = 0.0
    spec *= w
    return np.fft.irfft(spec, n=P, axis=1)


def _detector_noise(F, sel, prm, impl, rng, record):
    """Add the detector's noise and drift to the rows ``sel`` of F (and to ``record``)."""
    k, P = sel.size, F.shape[1]
    w, p, d = prm["white_nN"][sel], prm["pink_nN"][sel], prm["drift_nN"][sel]
    rows = np.arange(k)
    term = np.zeros((k, P)) if record is not None else None
    if impl == "train":  # instrument.py's forms: Gaussian white, FFT 1/f, quadratic drift
        white = rng.standard_normal((k, P))
        pink = pink_spectrum_noise((k, P), rng)
        c1, c2 = rng.uniform(-1, 1, (2, k))
        off = rng.uniform(-0.5, 0.5, k)
        for target, r in ((F, sel), (term, rows)):
            if target is None:
                continue
            _add_scaled(target, r, white, w, False)
            _add_scaled(target, r, pink, p, True)
            _add_drift(target, r, c1, c2, off, d)
        return term
    white = rng.laplace(0.0, 1.0 / np.sqrt(2.0), (k, P)) * w[:, None]
    drift = np.cumsum(np.cumsum(rng.standard_normal((k, P)), axis=1), axis=1)
    drift -= drift.mean(axis=1, keepdims=True)
    drift /= np.abs(drift).max(axis=1, keepdims=True) + 1e-30
    drift += rng.uniform(-0.5, 0.5, (k, 1))
    t = white + _voss_pink((k, P), p, rng) + drift * d[:, None]
    F[sel] += t
    return t


def _detector_adc(F, sel, prm, impl, rng):
    bits = prm["bits"][sel]
    m = _row_absmax(F, sel)
    if impl == "train":  # 1.5x the largest |F|, rounded up to a power of two (instrument.py)
        fs = 2.0 ** np.ceil(np.log2(1.5 * m + 1e-9))
    else:  # a gain set by hand: 1.2-2x the largest |F|
        fs = rng.uniform(1.2, 2.0, sel.size) * m + 1e-9
    _digitise_rows(F, sel, bits.astype(np.int64), fs)


def _telegraph(shape, prm, sel, impl, rng):
    k, P = shape
    A, c = prm["amplitude_nN"][sel], prm["switches"][sel].astype(np.int64)
    if impl == "train":  # Markov two-level: switch times uniform on the line, levels +-A/2
        pos = rng.integers(1, P, int(c.sum()))
    else:  # renewal with gamma(3) dwell times (more regular), levels 0 and A, 1-px settling
        cmax = int(c.max()) if k else 0
        dwell = rng.gamma(3.0, 1.0, (k, cmax + 1))
        dwell[np.arange(cmax + 1)[None, :] > c[:, None]] = 0.0
        cum = np.cumsum(dwell, axis=1) / dwell.sum(axis=1, keepdims=True)
        cols = np.arange(cmax + 1)[None, :] < c[:, None]
        pos = np.clip(np.round(cum[cols] * P).astype(np.int64), 1, P - 1)
    level = _telegraph_levels(c, pos.astype(np.int64), rng.integers(0, 2, k), P)
    if impl == "train":
        return (level - 0.5) * A[:, None]
    term = level * A[:, None]
    _lowpass_rows(term, np.arange(k), np.ones(k))
    return term


def _mains(shape, prm, sel, impl, rng, pixel_s):
    k, P = shape
    A, f = prm["amplitude_nN"][sel], prm["frequency_Hz"][sel]
    one = np.ones(k)
    if impl == "train":
        harm = np.array([1.0, 2.0, 3.0])
        rel = np.column_stack([one, prm["harmonic_2"][sel], prm["harmonic_3"][sel]])
    else:
        harm = np.array([1.0, 3.0, 5.0])
        rel = np.column_stack([one, prm["harmonic_3"][sel], prm["harmonic_5"][sel]])
        f = f * (1.0 + prm["frequency_deviation"][sel])
    amp = rel * (A / np.sqrt(0.5 * np.sum(rel**2, axis=1)))[:, None]  # rms A
    omega = 2.0 * np.pi * f[:, None] * harm[None, :] * pixel_s[sel, None]  # rad per pixel
    phase = rng.uniform(0.0, 2.0 * np.pi, (k, harm.size)) + 0.5 * omega  # at pixel centres
    if impl == "eval":  # each pixel the mean over its time window
        amp = amp * np.sinc(omega / (2.0 * np.pi))
    term = np.zeros((k, P))
    _add_sines(term, np.arange(k), omega, phase, amp)
    return term


def _spikes(shape, prm, sel, impl, rng):
    k, P = shape
    term = np.zeros((k, P))
    c = prm["count"][sel].astype(np.int64)
    row = np.repeat(np.arange(k), c)
    sd = prm["height_nN"][sel][row]
    pos = rng.integers(0, P, row.size)
    wmax = prm["width_max_px"][sel][row]
    width = rng.integers(prm["width_min_px"][sel][row], wmax + 1)
    if impl == "train":  # Gaussian heights, rectangular
        h = rng.standard_normal(row.size) * sd
        decay = 1.0
    else:  # Laplacian heights (same std), decaying glitch 1, 1/2, 1/4...
        h = rng.laplace(0.0, 1.0 / np.sqrt(2.0), row.size) * sd
        decay = 0.5
    for j in range(int(wmax.max(initial=0))):
        ok = (j < width) & (pos + j < P)
        np.add.at(term, (row[ok], pos[ok] + j), h[ok] * decay**j)
    return term


# --------------------------------------------------------------------------------------
# public application
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Stated:
    """The conditions an estimator is told for each line (the true ones go into the
    simulation; they differ on lines that get ``stated_conditions``)."""

    velocity_nm_per_s: np.ndarray
    temperature_K: np.ndarray


def stated(draw: Draw, velocity_nm_per_s, temperature_K=ROOM_TEMPERATURE_K) -> Stated:
    """Stated conditions from the true ones: ``true * (1 + error)`` where drawn."""
    v = np.broadcast_to(np.asarray(velocity_nm_per_s, float), (draw.n,)).copy()
    T = np.broadcast_to(np.asarray(temperature_K, float), (draw.n,)).copy()
    on = draw.mask("stated_conditions")
    prm = draw.params["stated_conditions"]
    v[on] *= 1.0 + prm["velocity_error"][on]
    T[on] *= 1.0 + prm["temperature_error"][on]
    return Stated(v, T)


def contact_force(draw: Draw, force_nN: np.ndarray) -> np.ndarray:
    """The lateral force at the contact (n, P): the clean force after the contact-level
    family (``precursor``). Its mean over the line is the <F> truth; :func:`apply` starts
    from it."""
    F = np.array(force_nN, dtype=float, order="C", copy=True)
    if F.ndim != 2 or F.shape[0] != draw.n:
        raise ValueError(f"force must be (n={draw.n}, pixels), got {F.shape}")
    sel = np.flatnonzero(draw.mask("precursor"))
    if sel.size:
        _precursor(F, sel, draw.params["precursor"], draw.implementation)
    return F


def apply(
    draw: Draw,
    x_nm: np.ndarray,
    force_nN: np.ndarray,
    velocity_nm_per_s: float | np.ndarray,
    rng: np.random.Generator,
    temperature_K: float | np.ndarray = ROOM_TEMPERATURE_K,
    crosstalk_nN: np.ndarray | None = None,
    record: dict[str, np.ndarray] | None = None,
) -> tuple[np.ndarray, Stated]:
    """Apply a draw's effects to a batch of clean lines.

    Parameters
    ----------
    draw : per-line parameters (:func:`draw`); its implementation is used.
    x_nm : (P,) nominal, uniform positions of the pixels (pixel size and crosstalk scale).
    force_nN : (n, P) clean force.
    velocity_nm_per_s : true scan velocity, scalar or (n,) (sets the time base).
    rng : randomness of the realisations (noise, spikes, ...), one stream per family.
    temperature_K : true temperature, scalar or (n,) (only for the stated conditions).
    crosstalk_nN : (n, P) crosstalk term to use (e.g. the same for a trace and its
        retrace, from :func:`crosstalk_term`); drawn from ``rng`` when None.
    record : if a dict, receives each additive family's term (keys of :data:`ADDITIVE`,
        ``"detector"`` being its noise and drift), the ``"gain"`` factor and what the
        ``"saturation"`` changed (output minus input), (n, P) each.

    Returns
    -------
    force_nN : (n, P) the recorded force.
    stated : :class:`Stated` conditions to tell the estimator.
    """
    impl = draw.implementation
    x = np.asarray(x_nm, float)
    F = contact_force(draw, force_nN)
    n, P = F.shape
    if x.shape != (P,):
        raise ValueError(f"x_nm must be ({P},), got {x.shape}")
    v = np.broadcast_to(np.asarray(velocity_nm_per_s, float), (n,))
    pixel_s = (x[1] - x[0]) / v
    streams = _streams(rng)
    prm = draw.params
    if record is not None:
        record.update({name: np.zeros((n, P)) for name in ADDITIVE}, gain=np.ones((n, P)),
                      saturation=np.zeros((n, P)))  # fmt: skip

    def rows(f: str) -> np.ndarray:
        return np.flatnonzero(draw.mask(f))

    if (sel := rows("piezo")).size:
        _piezo(F, sel, prm["piezo"], impl)
    if (sel := rows("cantilever")).size:
        _cantilever(F, sel, prm["cantilever"], impl, pixel_s)
    if (sel := rows("crosstalk")).size:
        if crosstalk_nN is None:
            term = _crosstalk_rows(draw, sel, x, streams["crosstalk"])
        else:
            term = np.asarray(crosstalk_nN, float)[sel]
        F[sel] += term
        if record is not None:
            record["crosstalk"][sel] = term
    if (sel := rows("saturation")).size:
        before = F[sel].copy() if record is not None else None
        _saturation(F, sel, prm["saturation"], impl)
        if record is not None:
            record["saturation"][sel] = F[sel] - before
    if (sel := rows("gain")).size:
        g = _gain(F, sel, prm["gain"], impl, streams["gain"])
        if record is not None:
            record["gain"][sel] = g
    det = rows("detector")
    if det.size:
        _detector_filter(F, det, prm["detector"], impl)
        term = _detector_noise(F, det, prm["detector"], impl, streams["detector"], record)
        if record is not None:
            record["detector"][det] = term
    for f in ("telegraph", "mains", "spikes"):
        sel = rows(f)
        if not sel.size:
            continue
        if f == "telegraph":
            term = _telegraph((sel.size, P), prm[f], sel, impl, streams[f])
        elif f == "mains":
            term = _mains((sel.size, P), prm[f], sel, impl, streams[f], pixel_s)
        else:
            term = _spikes((sel.size, P), prm[f], sel, impl, streams[f])
        F[sel] += term
        if record is not None:
            record[f][sel] = term
    if det.size:
        _detector_adc(F, det, prm["detector"], impl, streams["detector"])
    return F, stated(draw, v, temperature_K)
