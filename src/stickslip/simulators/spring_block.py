"""Macroscopic spring-block stick-slip: a rigid slider pulled through a spring.

A slider of mass ``M`` sits on a flat surface (no periodic potential). The far end of a
spring of stiffness ``k`` moves at constant velocity ``v`` (drive position ``X = v t``);
the recorded force is the spring force ``F = k (X - x)``. The slider obeys

    M x'' = k (v t - x) - c x' - sign(x') F_f(|x'|, theta)      (slipping)
    x' = 0   while |k (v t - x)| <= F_static(theta)             (stuck)

with one of three friction laws (a small frozen config each):

- :class:`Coulomb`: constant static threshold ``mu_s N`` and dynamic friction
  ``mu_d N`` (``mu_s > mu_d``). Solved exactly: during a slip the motion is a (damped)
  harmonic oscillation about a shifted equilibrium, the end of the slip (velocity back
  to zero) is located by bisection on the closed-form solution, and a stick is a
  straight line in time.
- :class:`VelocityWeakening`: ``F_f = N (mu_d + (mu_s - mu_d) / (1 + |u| / u_c))``; the
  static threshold is ``mu_s N`` (the law's value at ``u -> 0``).
- :class:`RateState`: Dieterich's aging law with the cut-offs of Baumberger & Caroli
  (Adv. Phys. 55, 279, 2006, used for paper on paper by Heslot et al., PRE 49, 4973,
  1994): ``F_f = N (mu0 + a ln(1 + |u|/V1) + b ln(1 + theta/theta1))``, ``theta' = 1 -
  |u| theta / Dc``. At rest ``theta`` grows as the time stuck, so the static threshold
  ``N (mu0 + b ln(1 + theta/theta1))`` ages logarithmically.

The two smooth laws are integrated with classical RK4 during slips only, with a step that
resolves both the spring's period and the friction law's own rate; sticks are exact for
every law (the slider does not move; the slip starts where the loading line meets the
threshold, found in closed form or by bisection), and the end of every slip is located by
bisection on the step (a slip that would only graze zero velocity inside one step is
caught by looking for a minimum of the velocity inside the step).

Optional per-cycle strength disorder (``strength_spread``): the friction of stick-slip
cycle ``i`` (its static threshold and the dynamic friction of the slip that ends it) is
multiplied by a log-normal factor ``exp(spread z_i)`` drawn from ``seed`` and
``stream``; real interfaces (paper on paper) show slips of scattered sizes.

Recording: ``n_samples`` samples at ``sample_rate_Hz``, starting ``lead_s`` after the
first slip starts. Sample ``j`` is the mean of the force at ``oversample`` instants
equally spaced inside ``[t0 + j/fs, t0 + (j+1)/fs)`` (``oversample = 1``: the force at the
interval's centre); its time stamp is the interval's centre. The truth carried along:
``k``, the fraction of the recorded time during which the slider is stuck
(``stuck_fraction``: speed at most ``stuck_tolerance v``, 1 % of the drive velocity by
default, so that the recorded slope is within 1 % of ``k``; ``rest_fraction``: speed
exactly zero), the slips that start inside the recording and their force drops (``F`` at
the start minus ``F`` at the end).

Units: SI throughout (m, s, kg, N, N/m).
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit

LAW_COULOMB, LAW_WEAKENING, LAW_RATE_STATE = 0, 1, 2
#: Standard gravity, m/s^2 (for normal forces given as a mass on the surface).
G_M_PER_S2 = 9.81
#: RK4 step times the friction law's fastest rate (``_stiff_rate``) at most: RK4 follows
#: a decay or growth at this step to 0.3 %.
RK_RATE_STEP = 1.0
#: Length of the table of per-cycle strength factors (cycle ``i`` uses entry ``i % L``).
STRENGTH_TABLE = 1 << 16


class _Thresholds:
    """The static threshold and the dynamic friction of a law with ``mu_static``,
    ``mu_dynamic`` and ``normal_force_N``."""

    mu_static: float
    mu_dynamic: float
    normal_force_N: float

    @property
    def static_N(self) -> float:
        """Static threshold ``F_s = mu_s N`` (N)."""
        return self.mu_static * self.normal_force_N

    @property
    def dynamic_N(self) -> float:
        """Dynamic (high-speed) friction ``F_d = mu_d N`` (N)."""
        return self.mu_dynamic * self.normal_force_N


@dataclass(frozen=True)
class Coulomb(_Thresholds):
    """Coulomb friction: static threshold ``mu_static N``, dynamic ``mu_dynamic N``.

    Parameters
    ----------
    mu_static, mu_dynamic : float
        Friction coefficients, ``mu_static > mu_dynamic >= 0``.
    normal_force_N : float
        Normal load on the slider, N.
    """

    mu_static: float
    mu_dynamic: float
    normal_force_N: float

    def check(self) -> None:
        if not (self.mu_static > self.mu_dynamic >= 0 and self.normal_force_N > 0):
            raise ValueError(f"need mu_static > mu_dynamic >= 0 and N > 0: {self}")

    def params(self) -> np.ndarray:
        return np.array([self.static_N, self.dynamic_N])


@dataclass(frozen=True)
class VelocityWeakening(_Thresholds):
    """Friction falling smoothly with slip speed: ``N (mu_d + (mu_s - mu_d)/(1 + |u|/u_c))``.

    Parameters
    ----------
    mu_static, mu_dynamic : float
        Friction at rest (the static threshold) and at high speed.
    velocity_scale_m_per_s : float
        Speed ``u_c`` at which half of the weakening has happened, m/s.
    normal_force_N : float
        Normal load, N.
    """

    mu_static: float
    mu_dynamic: float
    velocity_scale_m_per_s: float
    normal_force_N: float

    def check(self) -> None:
        if not (self.mu_static > self.mu_dynamic >= 0 and self.normal_force_N > 0
                and self.velocity_scale_m_per_s > 0):  # fmt: skip
            raise ValueError(f"need mu_static > mu_dynamic >= 0, N > 0, u_c > 0: {self}")

    def params(self) -> np.ndarray:
        return np.array([self.static_N, self.dynamic_N, self.velocity_scale_m_per_s])


@dataclass(frozen=True)
class RateState:
    """Rate-and-state friction, Dieterich aging law, Baumberger-Caroli cut-offs.

    ``F_f = N (mu0 + a ln(1 + |u|/V1) + b ln(1 + theta/theta1))`` and
    ``theta' = 1 - |u| theta / Dc``; static threshold ``N (mu0 + b ln(1 + theta/theta1))``.

    Parameters
    ----------
    mu0 : float
        Friction coefficient of a fresh contact at rest.
    a, b : float
        Direct (velocity-strengthening) and state (aging) coefficients; stick-slip needs
        ``b > a``.
    velocity_cutoff_m_per_s : float
        ``V1``, m/s.
    state_cutoff_s : float
        ``theta1``, s.
    length_m : float
        Memory length ``Dc``, m.
    normal_force_N : float
        Normal load, N.
    initial_state_s : float
        ``theta`` at ``t = 0`` (the age of the contact when the drive starts), s.
    """

    mu0: float
    a: float
    b: float
    velocity_cutoff_m_per_s: float
    state_cutoff_s: float
    length_m: float
    normal_force_N: float
    initial_state_s: float = 1.0

    def check(self) -> None:
        if not (self.mu0 > 0 and self.a >= 0 and self.b > 0 and self.normal_force_N > 0
                and self.velocity_cutoff_m_per_s > 0 and self.state_cutoff_s > 0
                and self.length_m > 0 and self.initial_state_s >= 0):  # fmt: skip
            raise ValueError(f"invalid rate-and-state parameters: {self}")

    def params(self) -> np.ndarray:
        return np.array([self.normal_force_N, self.mu0, self.a, self.b,
                         self.velocity_cutoff_m_per_s, self.state_cutoff_s, self.length_m,
                         self.initial_state_s])  # fmt: skip


FrictionLaw = Coulomb | VelocityWeakening | RateState
_LAW_IDS: dict[type, int] = {Coulomb: LAW_COULOMB, VelocityWeakening: LAW_WEAKENING,
                             RateState: LAW_RATE_STATE}  # fmt: skip
_LAW_NAMES: dict[str, type] = {"coulomb": Coulomb, "velocity_weakening": VelocityWeakening,
                               "rate_state": RateState}  # fmt: skip


def law_name(law: FrictionLaw) -> str:
    """The name of a friction law's class in :func:`SpringBlockConfig.to_dict`."""
    return {v: k for k, v in _LAW_NAMES.items()}[type(law)]


@dataclass(frozen=True)
class SpringBlockConfig:
    """Everything that defines one simulated spring-block recording.

    Parameters
    ----------
    k_N_per_m : float
        Spring stiffness (the truth an estimator's stick slope should give), N/m.
    mass_kg : float
        Slider mass, kg.
    velocity_m_per_s : float
        Drive velocity ``v > 0``, m/s.
    sample_rate_Hz : float
        Recording rate, Hz.
    n_samples : int
        Samples recorded.
    law : Coulomb | VelocityWeakening | RateState
        Friction law.
    damping_N_s_per_m : float
        Viscous damping of the slider's motion (``c``; below critical, ``c < 2 sqrt(k M)``).
    oversample : int
        Instants averaged per sample (1: point sampling at the interval's centre).
    lead_s : float
        Time from the start of the first slip to the start of the recording, s.
    strength_spread : float
        Standard deviation of the log of the per-cycle strength factor (0: none).
    seed, stream : int
        Seed and stream of the strength factors (random stream ``[seed, stream, 17]``).
    steps_per_period : int
        RK4 steps per period of the free spring-mass oscillation (smooth laws).
    stuck_tolerance : float
        Slider speed, as a fraction of ``v``, up to which the slider counts as stuck in
        :attr:`SpringBlockLine.stuck_fraction` (rate-and-state sliders creep before they
        slip: a stick there is a speed well below the drive's, not exactly zero).
    """

    k_N_per_m: float
    mass_kg: float
    velocity_m_per_s: float
    sample_rate_Hz: float
    n_samples: int
    law: FrictionLaw
    damping_N_s_per_m: float = 0.0
    oversample: int = 1
    lead_s: float = 0.0
    strength_spread: float = 0.0
    seed: int = 0
    stream: int = 0
    steps_per_period: int = 32
    stuck_tolerance: float = 0.01

    @property
    def omega_rad_per_s(self) -> float:
        """Natural angular frequency ``sqrt(k / M)`` of the slider on the spring."""
        return math.sqrt(self.k_N_per_m / self.mass_kg)

    def check(self) -> None:
        """Raise ValueError for settings the simulator does not support."""
        if not (self.k_N_per_m > 0 and self.mass_kg > 0 and self.velocity_m_per_s > 0
                and self.sample_rate_Hz > 0 and self.n_samples >= 1 and self.oversample >= 1
                and self.lead_s >= 0 and self.strength_spread >= 0
                and self.damping_N_s_per_m >= 0 and self.steps_per_period >= 8
                and 0 <= self.stuck_tolerance < 1):  # fmt: skip
            raise ValueError(f"invalid spring-block settings: {self}")
        if self.damping_N_s_per_m >= 2.0 * math.sqrt(self.k_N_per_m * self.mass_kg):
            raise ValueError("damping at or above critical is not supported")
        self.law.check()

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready description (:meth:`from_dict` rebuilds the config)."""
        d = dataclasses.asdict(self)
        d["law"] = {"name": law_name(self.law), **dataclasses.asdict(self.law)}
        return d

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), sort_keys=True)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> SpringBlockConfig:
        law = dict(d["law"])
        kind = _LAW_NAMES[law.pop("name")]
        return cls(**{**d, "law": kind(**law)})


@dataclass
class SpringBlockLine:
    """One simulated recording with its truth (arrays of shape ``(n_samples,)``).

    Stuck means a slider speed of at most ``stuck_tolerance`` times the drive velocity
    (the recorded slope is then within that fraction of ``k``): ``stuck`` is, per
    sample, the fraction of its instants at which the slider was stuck, and
    ``stuck_fraction`` the fraction of the recorded time (exact during sticks; during
    slips from the speed interpolated linearly over each integration step).
    ``rest_fraction`` is the fraction of time at exactly zero speed. The slip arrays
    hold the slips that start inside the recorded time window;
    ``slip_drops_N`` is NaN for a slip that has not ended when the recording ends.
    """

    config: SpringBlockConfig
    t_s: np.ndarray
    X_m: np.ndarray
    force_N: np.ndarray
    stuck: np.ndarray
    stuck_fraction: float
    rest_fraction: float
    slip_starts_s: np.ndarray
    slip_durations_s: np.ndarray
    slip_drops_N: np.ndarray
    rk_steps: int

    @property
    def k_N_per_m(self) -> float:
        return self.config.k_N_per_m

    @property
    def n_slips(self) -> int:
        """Slips that start inside the recording."""
        return int(self.slip_starts_s.size)

    @property
    def median_drop_N(self) -> float:
        """Median force drop of the recorded slips that end inside the recording."""
        d = self.slip_drops_N[np.isfinite(self.slip_drops_N)]
        return float(np.median(d)) if d.size else float("nan")

    @property
    def samples_per_slip(self) -> float:
        """Recorded samples per slip (inf without slips)."""
        return self.force_N.size / self.n_slips if self.n_slips else float("inf")


# ----------------------------------------------------------------------------- kernels


@njit(cache=True)
def _threshold(law: int, p: np.ndarray, th: float, mult: float) -> float:
    if law == LAW_RATE_STATE:
        return mult * p[0] * (p[1] + p[3] * math.log1p(th / p[5]))
    return mult * p[0]


@njit(cache=True)
def _friction(law: int, p: np.ndarray, speed: float, th: float, mult: float) -> float:
    if law == LAW_COULOMB:
        return mult * p[1]
    if law == LAW_WEAKENING:
        return mult * (p[1] + (p[0] - p[1]) / (1.0 + speed / p[2]))
    return mult * p[0] * (p[1] + p[2] * math.log1p(speed / p[4]) + p[3] * math.log1p(th / p[5]))


@njit(cache=True)
def _stiff_rate(law: int, p: np.ndarray, speed: float, th: float, mult: float, M: float,
                c: float) -> float:  # fmt: skip
    """The fastest rate (1/s) of the friction law at this state (for the RK4 step)."""
    r = c / M
    if law == LAW_WEAKENING:
        q = 1.0 + speed / p[2]
        r += mult * (p[0] - p[1]) / (p[2] * q * q) / M
    elif law == LAW_RATE_STATE:
        r += mult * p[0] * p[2] / (p[4] + speed) / M + speed / p[6]
    return r


@njit(cache=True)
def _stick_end(law: int, p: np.ndarray, k: float, v: float, x: float, t: float, th: float,
               mult: float) -> float:  # fmt: skip
    """Time at which a slider stuck at ``x`` since ``t`` starts to slip (``>= t``)."""
    F = k * (v * t - x)
    thr = _threshold(law, p, th, mult)
    if F >= thr or F < -thr:
        return t
    if law != LAW_RATE_STATE:
        return max(t, (thr / k + x) / v)
    # aging threshold: g(tau) = F + k v tau - thr(th + tau) is convex with g(0) < 0, so
    # Newton's method from a point where g >= 0 descends monotonically onto the root
    hi = max((thr - F) / (k * v), 1e-12)
    for _ in range(2000):
        if F + k * v * hi - _threshold(law, p, th + hi, mult) >= 0.0:
            break
        hi *= 2.0
    for _ in range(100):
        g = F + k * v * hi - _threshold(law, p, th + hi, mult)
        dg = k * v - mult * p[0] * p[3] / (p[5] + th + hi)
        if g <= 0.0 or dg <= 0.0:
            break
        step = g / dg
        hi -= step
        if step <= 1e-15 * (t + hi):
            break
    return t + hi


@njit(cache=True)
def _prop(z: float, zd: float, tau: float, alpha: float, wd: float, w0sq: float):
    """Damped free oscillation ``z'' + 2 alpha z' + w0^2 z = 0`` from ``(z, zd)`` by ``tau``."""
    e = math.exp(-alpha * tau)
    cs = math.cos(wd * tau)
    sn = math.sin(wd * tau)
    z1 = e * (z * cs + (zd + alpha * z) / wd * sn)
    zd1 = e * (zd * cs - (w0sq * z + alpha * zd) / wd * sn)
    return z1, zd1


@njit(cache=True)
def _deriv(law: int, p: np.ndarray, k: float, M: float, c: float, v: float, s: float,
           mult: float, t: float, x: float, u: float, th: float):  # fmt: skip
    speed = s * u if s * u > 0.0 else 0.0
    f = _friction(law, p, speed, th, mult)
    acc = (k * (v * t - x) - c * u - s * f) / M
    dth = 1.0 - speed * th / p[6] if law == LAW_RATE_STATE else 0.0
    return u, acc, dth


@njit(cache=True)
def _rk4(law: int, p: np.ndarray, k: float, M: float, c: float, v: float, s: float,
         mult: float, t: float, x: float, u: float, th: float, h: float):  # fmt: skip
    k1x, k1u, k1t = _deriv(law, p, k, M, c, v, s, mult, t, x, u, th)
    return _rk4_from(law, p, k, M, c, v, s, mult, t, x, u, th, h, k1x, k1u, k1t)


@njit(cache=True)
def _rk4_from(law: int, p: np.ndarray, k: float, M: float, c: float, v: float, s: float,
              mult: float, t: float, x: float, u: float, th: float, h: float, k1x: float,
              k1u: float, k1t: float):  # fmt: skip
    """One RK4 step given the derivatives at its start."""
    h2 = 0.5 * h
    k2x, k2u, k2t = _deriv(law, p, k, M, c, v, s, mult, t + h2, x + h2 * k1x, u + h2 * k1u,
                           th + h2 * k1t)  # fmt: skip
    k3x, k3u, k3t = _deriv(law, p, k, M, c, v, s, mult, t + h2, x + h2 * k2x, u + h2 * k2u,
                           th + h2 * k2t)  # fmt: skip
    k4x, k4u, k4t = _deriv(law, p, k, M, c, v, s, mult, t + h, x + h * k3x, u + h * k3u,
                           th + h * k3t)  # fmt: skip
    h6 = h / 6.0
    return (x + h6 * (k1x + 2.0 * k2x + 2.0 * k3x + k4x),
            u + h6 * (k1u + 2.0 * k2u + 2.0 * k3u + k4u),
            max(th + h6 * (k1t + 2.0 * k2t + 2.0 * k3t + k4t), 0.0))  # fmt: skip


@njit(cache=True)
def _slow_time(ta: float, tb: float, ua: float, ub: float, tol: float, w0: float,
               w1: float) -> float:  # fmt: skip
    """Time inside the window ``[w0, w1)`` of the step ``[ta, tb]`` during which the
    speed (linear from ``ua`` to ``ub``) is at most ``tol``."""
    if w0 < 0.0:
        return 0.0
    inside = max(0.0, min(tb, w1) - max(ta, w0))
    if inside <= 0.0:
        return 0.0
    lo, hi = min(ua, ub), max(ua, ub)
    if hi <= tol:
        frac = 1.0
    elif lo > tol:
        frac = 0.0
    else:
        frac = (tol - lo) / (hi - lo)
    return inside * frac


@njit(cache=True)
def _qtime(q: int, m: int, t_rec: float, fs: float) -> float:
    j = q // m
    i = q - j * m
    return t_rec + (j + (i + 0.5) / m) / fs


@njit(cache=True)
def _run(law: int, p: np.ndarray, k: float, M: float, c: float, v: float, fs: float, n: int,
         m: int, lead: float, strength: np.ndarray, steps_per_period: int, max_steps: int,
         tol: float):  # fmt: skip
    """Simulate and record; see the module docstring. Returns the per-sample force and
    stuck fractions, the recording's start time, the slip table (start, end, F at start,
    F at end), the time at rest and the time stuck (speed <= ``tol``) inside the
    window, and the RK4 step count."""
    nq = n * m
    F_out = np.zeros(n)
    stuck_out = np.zeros(n)
    cap = 1024
    ev = np.full((cap, 4), np.nan)
    nev = 0
    w0sq = k / M
    alpha = 0.5 * c / M
    wd = math.sqrt(w0sq - alpha * alpha)
    period = 2.0 * math.pi / wd
    t = 0.0
    x = 0.0
    u = 0.0
    th = p[7] if law == LAW_RATE_STATE else 0.0
    t_rec = -1.0
    t_w1 = math.inf
    q = 0
    stuck_time = 0.0
    rest_time = 0.0
    steps = 0
    cycle = 0
    L = strength.size
    inv_m = 1.0 / m
    while True:
        # ---- stick: the slider rests at x from t until te
        mult = strength[cycle % L]
        te = _stick_end(law, p, k, v, x, t, th, mult)
        if t_rec >= 0.0:
            while q < nq:
                tq = _qtime(q, m, t_rec, fs)
                if tq >= te:
                    break
                F_out[q // m] += k * (v * tq - x) * inv_m
                stuck_out[q // m] += inv_m
                q += 1
            rest = max(0.0, min(te, t_w1) - max(t, t_rec))
            stuck_time += rest
            rest_time += rest
        if law == LAW_RATE_STATE:
            th += te - t
        t = te
        if t_rec < 0.0:
            t_rec = t + lead
            t_w1 = t_rec + n / fs
        if q >= nq:
            break
        # ---- slip
        F0 = k * (v * t - x)
        s = 1.0 if F0 > 0.0 else -1.0
        if nev == cap:
            new = np.full((2 * cap, 4), np.nan)
            new[:cap] = ev
            ev = new
            cap *= 2
        ev[nev, 0] = t
        ev[nev, 2] = F0
        nev += 1
        stopped = False
        if law == LAW_COULOMB:
            # z = x - v t + (s Fd + c v)/k oscillates freely; F = k (shift - z), u = zd + v
            shift = (s * mult * p[1] + c * v) / k
            t0 = t
            z0 = x - v * t0 + shift
            zd0 = u - v
            hstep = period / 64.0
            tau = 0.0
            za, zda = z0, zd0
            while True:
                tn = tau + hstep
                z1, zd1 = _prop(z0, zd0, tn, alpha, wd, w0sq)
                ends = s * (zd1 + v) <= 0.0
                if not ends:
                    # a minimum of s u inside the step (s a = -s (w0^2 z + 2 alpha zd)) that
                    # dips to zero: the slip ends before it
                    a0 = -s * (w0sq * za + 2.0 * alpha * zda)
                    a1 = -s * (w0sq * z1 + 2.0 * alpha * zd1)
                    if a0 < 0.0 and a1 > 0.0 and min(s * (zda + v), s * (zd1 + v)) <= (
                            2.0 * hstep * max(-a0, a1)):  # fmt: skip
                        lo, hi = tau, tn
                        for _ in range(100):
                            mid = 0.5 * (lo + hi)
                            if mid <= lo or mid >= hi:
                                break
                            zm, zdm = _prop(z0, zd0, mid, alpha, wd, w0sq)
                            if -s * (w0sq * zm + 2.0 * alpha * zdm) < 0.0:
                                lo = mid
                            else:
                                hi = mid
                        zm, zdm = _prop(z0, zd0, lo, alpha, wd, w0sq)
                        if s * (zdm + v) <= 0.0:
                            tn = lo
                            ends = True
                if ends:
                    lo, hi = tau, tn
                    for _ in range(200):
                        mid = 0.5 * (lo + hi)
                        if mid <= lo or mid >= hi:
                            break
                        zm, zdm = _prop(z0, zd0, mid, alpha, wd, w0sq)
                        if s * (zdm + v) > 0.0:
                            lo = mid
                        else:
                            hi = mid
                    tn = hi
                t_end = t0 + tn
                if t_rec >= 0.0:
                    ub = 0.0 if ends else s * (zd1 + v)
                    stuck_time += _slow_time(t0 + tau, t_end, s * (zda + v), ub, tol, t_rec,
                                             t_w1)  # fmt: skip
                while q < nq:
                    tq = _qtime(q, m, t_rec, fs)
                    if tq > t_end or (ends and tq >= t_end):
                        break
                    zq, zdq = _prop(z0, zd0, tq - t0, alpha, wd, w0sq)
                    F_out[q // m] += k * (shift - zq) * inv_m
                    if s * (zdq + v) <= tol:
                        stuck_out[q // m] += inv_m
                    q += 1
                tau = tn
                za, zda = z1, zd1
                if ends:
                    z1, _ = _prop(z0, zd0, tn, alpha, wd, w0sq)
                    t = t_end
                    x = z1 + v * t - shift
                    u = 0.0
                    stopped = True
                    break
                if q >= nq:
                    break
        else:
            armed = False
            hmax = period / steps_per_period
            d0x, d0u, d0t = _deriv(law, p, k, M, c, v, s, mult, t, x, u, th)
            while q < nq and steps < max_steps:
                speed = s * u if s * u > 0.0 else 0.0
                lam = _stiff_rate(law, p, speed, th, mult, M, c)
                h = hmax
                if lam * h > RK_RATE_STEP:
                    h = RK_RATE_STEP / lam
                tq = _qtime(q, m, t_rec, fs)
                hit = False
                if t + h >= tq:
                    h = tq - t
                    hit = True
                x1, u1, th1 = _rk4_from(law, p, k, M, c, v, s, mult, t, x, u, th, h, d0x, d0u,
                                        d0t)  # fmt: skip
                d1x, d1u, d1t = _deriv(law, p, k, M, c, v, s, mult, t + h, x1, u1, th1)
                steps += 1
                ends = False
                hend = h
                if armed:
                    if s * u1 <= 0.0:
                        ends = True
                    else:
                        a0, a1 = d0u, d1u
                        # a minimum of s u in the step that may dip to zero (the speed
                        # changes by at most about h max|a| within the step)
                        if (s * a0 < 0.0 and s * a1 > 0.0 and min(s * u, s * u1)
                                <= 2.0 * h * max(-s * a0, s * a1)):  # fmt: skip
                            lo, hi = 0.0, h
                            for _ in range(30):
                                mid = 0.5 * (lo + hi)
                                xm, um, tm = _rk4(law, p, k, M, c, v, s, mult, t, x, u, th, mid)
                                _, am, _ = _deriv(law, p, k, M, c, v, s, mult, t + mid, xm, um,
                                                  tm)  # fmt: skip
                                if s * am < 0.0:
                                    lo = mid
                                else:
                                    hi = mid
                            xm, um, tm = _rk4(law, p, k, M, c, v, s, mult, t, x, u, th, lo)
                            if s * um <= 0.0:
                                ends = True
                                hend = lo
                if ends:
                    # the zero of s u in (0, hend]: regula falsi (Illinois), bracketed
                    lo, hi = 0.0, hend
                    flo = s * u
                    _, um, _ = _rk4(law, p, k, M, c, v, s, mult, t, x, u, th, hi)
                    fhi = s * um
                    side = 0
                    for _ in range(60):
                        if hi - lo <= 1e-12 * hend:
                            break
                        mid = (lo * fhi - hi * flo) / (fhi - flo) if fhi < flo else 0.5 * (lo + hi)
                        if not (lo < mid < hi):
                            mid = 0.5 * (lo + hi)
                        _, um, _ = _rk4(law, p, k, M, c, v, s, mult, t, x, u, th, mid)
                        fm = s * um
                        if fm > 0.0:
                            lo, flo = mid, fm
                            if side == 1:
                                fhi *= 0.5
                            side = 1
                        else:
                            hi, fhi = mid, fm
                            if side == -1:
                                flo *= 0.5
                            side = -1
                            if fm == 0.0:
                                break
                    x, _, th = _rk4(law, p, k, M, c, v, s, mult, t, x, u, th, hi)
                    stuck_time += _slow_time(t, t + hi, s * u, 0.0, tol, t_rec, t_w1)
                    u = 0.0
                    t = t + hi
                    stopped = True
                    break
                if not armed:
                    if s * u1 > 0.0:
                        armed = True
                    else:
                        u1 = 0.0
                        d1x, d1u, d1t = _deriv(law, p, k, M, c, v, s, mult, t + h, x1, u1, th1)
                d0x, d0u, d0t = d1x, d1u, d1t
                tn = tq if hit else t + h
                stuck_time += _slow_time(t, tn, s * u, s * u1, tol, t_rec, t_w1)
                x, u, th = x1, u1, th1
                t = tn
                if hit:
                    F_out[q // m] += k * (v * t - x) * inv_m
                    if s * u <= tol:
                        stuck_out[q // m] += inv_m
                    q += 1
        if not stopped:
            break
        ev[nev - 1, 1] = t
        ev[nev - 1, 3] = k * (v * t - x)
        cycle += 1
    return F_out, stuck_out, t_rec, ev[:nev], rest_time, stuck_time, steps


def strength_factors(spread: float, seed: int, stream: int = 0) -> np.ndarray:
    """Per-cycle strength factors ``exp(spread z)`` (:data:`STRENGTH_TABLE` of them;
    ``[1.0]`` without spread), from the random stream ``[seed, stream, 17]``."""
    if spread <= 0:
        return np.ones(1)
    z = np.random.default_rng([seed, stream, 17]).standard_normal(STRENGTH_TABLE)
    return np.exp(spread * z)


def simulate_spring_block(config: SpringBlockConfig, max_steps: int = 500_000_000
                          ) -> SpringBlockLine:  # fmt: skip
    """Simulate one recording (see the module docstring).

    Parameters
    ----------
    config : SpringBlockConfig
        The settings.
    max_steps : int
        Cap on RK4 steps (smooth laws); a run that reaches it raises RuntimeError.

    Returns
    -------
    SpringBlockLine
        Recorded time, drive position, force, per-sample stuck fractions and the truth.
    """
    config.check()
    law = _LAW_IDS[type(config.law)]
    p = np.zeros(8)
    pl = config.law.params()
    p[: pl.size] = pl
    n, m, fs = int(config.n_samples), int(config.oversample), float(config.sample_rate_Hz)
    F, stuck, t_rec, ev, rest_time, stuck_time, steps = _run(
        law, p, float(config.k_N_per_m), float(config.mass_kg), float(config.damping_N_s_per_m),
        float(config.velocity_m_per_s), fs, n, m, float(config.lead_s),
        strength_factors(config.strength_spread, config.seed, config.stream),
        int(config.steps_per_period), int(max_steps),
        float(config.stuck_tolerance * config.velocity_m_per_s),
    )  # fmt: skip
    if steps >= max_steps:
        raise RuntimeError(f"spring-block simulation hit max_steps={max_steps}: {config}")
    t = t_rec + (np.arange(n) + 0.5) / fs
    t_w1 = t_rec + n / fs
    inside = (ev[:, 0] >= t_rec) & (ev[:, 0] < t_w1)
    ev = ev[inside]
    return SpringBlockLine(
        config=config, t_s=t, X_m=config.velocity_m_per_s * t, force_N=F, stuck=stuck,
        stuck_fraction=float(stuck_time / (n / fs)),
        rest_fraction=float(rest_time / (n / fs)), slip_starts_s=ev[:, 0].copy(),
        slip_durations_s=ev[:, 1] - ev[:, 0], slip_drops_N=ev[:, 2] - ev[:, 3],
        rk_steps=int(steps),
    )  # fmt: skip


def coulomb_slip_time_s(config: SpringBlockConfig) -> float:
    """Duration of an undamped Coulomb slip from rest at the static threshold (exact):
    ``(2 pi - 2 atan(w (F_s - F_d) / (k v))) / w`` with ``w = sqrt(k/M)``; ``pi / w`` as
    ``v -> 0``."""
    law = config.law
    w = config.omega_rad_per_s
    v_star = w * (law.static_N - law.dynamic_N) / config.k_N_per_m
    return (2 * math.pi - 2 * math.atan(v_star / config.velocity_m_per_s)) / w
