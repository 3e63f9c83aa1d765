"""Contacts that are not one point: multi-asperity tips, tips that change, and their truth.

Two kinds of line that single-point Prandtl-Tomlinson (PT) does not describe exactly
(issue 40), a Langevin simulator and a quasi-static T = 0 solver for both, and the
convention that defines their U0 and K: the *effective PT parameters*.

Units: public arguments carry their unit in the name (eV, N/m, nm, kg, rad); inside the
kernels everything is in nm, ns, nN (:mod:`stickslip.units`).

## The multi-asperity contact

N asperities (1-6) hang on one tip body; the cantilever (stiffness ``k_c``) joins the
support ``X = v t`` to the body (position ``y``), and a contact spring ``k_i`` joins the
body to asperity ``i`` (position ``x_i``), which feels its own substrate potential:

    E = (k_c/2) (X - y)^2 + sum_i [ (k_i/2) (y - x_i)^2 + U_i(x_i) ]
    U_i(x) = -(U0_i/2) cos(2 pi x / a + phi_i)         (U0_i peak-to-peak, eV)
    F = k_c (X - y)                                     (recorded force, nN)

``phi_i`` is asperity i's registry with the lattice (coherent contact: all equal; random:
uniform on [0, 2 pi)). Without a cantilever (``cantilever_N_m=None``) the body is rigid
and fixed to the support: ``E = sum_i [(k_i/2)(X - x_i)^2 + U_i(x_i)]`` and
``F = sum_i k_i (X - x_i)``; one asperity without a cantilever is single-point PT with
``K = k_1``. Shifting the support by ``a`` and every coordinate by ``a`` leaves ``E``
unchanged: the contact is periodic in the support position with the lattice period.

Dynamics (:func:`simulate_contacts`): every coordinate (body and asperities) obeys the
Langevin equation of PHYSICS.md with its own mass, the common damping rate Gamma and
temperature T, integrated by BAOAB with one force evaluation per step (the project's
scheme, random streams from ``(seed, line index)`` as in :mod:`.lanes`). Default masses
split the preset mass: half to the body, half shared equally by the asperities (all of it
shared by the asperities when there is no body). The step is the settings' ``dt_s``,
shortened where needed so that ``omega_max dt <= 0.5`` with ``omega_max^2`` the
Gershgorin bound of ``M^-1 Hessian`` (stiff contact springs on light asperities are
faster than the paper's PT), then adjusted so that a pixel holds an even number of steps
(:func:`stickslip.simulators.lanes.step_layout`). Recording as the project's simulator:
a warm-up of ``max(1 nm, F_max/K + 4a)`` (``F_max`` of the summed barrier, ``K`` the
series stiffness) or ``settings.warmup_nm`` is discarded, then each pixel is the mean of
``F`` over its steps.

## Tip change

A :class:`ContactLine` may carry a second contact (``after``) that takes over at support
position ``change_nm`` (measured on the recorded axis ``x_nm``, 0 at the first pixel):
the barrier and stiffnesses jump there, the masses stay. :func:`tip_change` builds the
single-point case: U0 and/or K multiplied by a factor (1.3-2x, up or down).

## Quasi-static T = 0 waveform

:func:`quasistatic_contacts` follows the stable equilibrium of ``E`` as the support
advances (predictor-corrector continuation, 16 sub-steps per pixel, trapezoid rule for
the pixel mean). Where the equilibrium branch ends (a fold: the Hessian loses positive
definiteness), the fold is located by bisection in ``X`` (to 1e-12 nm) and the contact
relaxes there by overdamped, mass-weighted gradient flow ``m_j Gamma q_j' = -dE/dq_j``
(the overdamped limit of the Langevin equations) to the next local minimum; at a tip
change it relaxes from its state under the new parameters. The waveform does not depend
on v, Gamma or the overall mass scale. It is the *noiseless T = 0 waveform* of the truth
convention below, and for single-point PT it is exactly the quasi-static PT of
PHYSICS.md (slip at ``F_slip``, into the next well).

## Truth convention: the effective PT parameters

- A line's effective PT parameters are the (U0, K) of the 1D PT model that best
  reproduces its noiseless T = 0 quasi-static waveform (above): least squares over the
  line's pixels of the pixel-averaged quasi-static single-point PT force at the same
  support positions, minimised over (U0, K, lattice phase). The phase is a free offset
  of the support position (the model is periodic in it), so the fit does not depend on
  the line's registry. eta = 2 pi^2 U0 / (K a^2) follows.
- The model is evaluated exactly (:func:`pt_quasistatic_force`): on one period of the
  stick branch the support position is ``X(x) = x + (pi U0 / (K a)) sin(2 pi x / a)``
  and the integral ``int F dX = -(U0/2) cos(2 pi x/a) + F(x)^2 / (2K)``, so a pixel
  mean needs two root solves, no sub-sampling. At T = 0 quasi-statically every slip of
  single-point PT lands in the next well (gradient flow), so the model waveform has
  period a for every eta.
- Fit quality: ``misfit_fraction`` = RMS(model - waveform) / (max - min of the
  waveform). A line is *described by one PT* when ``misfit_fraction <= 0.05``
  (:data:`MISFIT_LIMIT`); otherwise (several unequal slips per period, two regimes in one
  line) it has no U0 and K (PHYSICS.md). Tip-change lines are two regimes by
  construction and are never described, whatever their misfit.
- Validation (tests/simulators/test_contacts.py): one asperity on a stiff contact spring
  gives back its U0 and the series stiffness ``K = (1/k_c + 1/k_1)^-1`` (-> ``k_c``);
  identical asperities in the same registry give ``U0 = sum U0_i`` and
  ``K = (1/k_c + 1/sum k_i)^-1``; compliant asperities in random registry fit worse.
- Finite-temperature lines (:func:`simulate_contacts` at 296 K) keep the truth of their
  T = 0 waveform, as for every PT line (PHYSICS.md: U0 and K are the model's, not the
  measured peak's). The quasi-static waveform leaves out the dynamics on purpose: for
  single-point PT it gives back the simulator's own (U0, K) whatever the mass and damping.
  Measured with the paper preset (30 multi-asperity lines of :func:`contact_set`, 3 nm):
  Langevin at T = 0 differs from the quasi-static waveform mainly in the pixels of the
  slips (slips take time near the fold), RMS 0.6 % of the force range in the median,
  1.5 % at the 90th percentile, and fitting the T = 0 Langevin lines instead moves U0 and
  K of the described lines by at most 0.4 %. Where the dynamics make multiple slips
  (light, weakly damped asperities; more often than single-point PT at the same eta) the
  two differ and the truth stays the quasi-static one.
- Speed (one core): quasi-static waveform ~60 multi-asperity lines/s, effective fit ~13
  lines/s (512 pixels, 3 least-squares starts); Langevin ~1.2 single-point and ~0.4
  multi-asperity lines/s at the paper preset (2e7 steps per line).
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numba as nb
import numpy as np
from scipy.optimize import least_squares

from stickslip.simulators.config import PhysicalSettings, SettingsError, warmup_nm_for
from stickslip.simulators.kernel import box_muller, sin_2pi, xoroshiro_pair
from stickslip.simulators.lanes import rng_states, step_layout
from stickslip.traces.dataset import Dataset
from stickslip.units import (
    EV_TO_NN_NM,
    KB_NN_NM_PER_K,
    KG_TO_INTERNAL_MASS,
    PER_S_TO_PER_NS,
    S_TO_NS,
    eta_from,
)

#: Most asperities per contact.
MAX_ASPERITIES = 6
_MAXQ = MAX_ASPERITIES + 1
#: A line is described by one PT when its effective fit misses by at most this fraction
#: of the waveform's force range (RMS).
MISFIT_LIMIT = 0.05
#: ``omega_max dt`` at most (Gershgorin bound) in :func:`simulate_contacts`.
OMEGA_DT_MAX = 0.5
#: Sub-steps per pixel of the quasi-static solver.
QS_SUBSTEPS = 16


# --------------------------------------------------------------------------------------
# contacts
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Contact:
    """A tip of one or more asperities (see the module docs).

    Parameters
    ----------
    U0_eV : tuple of float
        Barrier (peak-to-peak) felt by each asperity, eV.
    k_N_m : tuple of float
        Contact spring between the tip body and each asperity, N/m (without a cantilever:
        between the support and each asperity).
    phase_rad : tuple of float, optional
        Registry ``phi_i`` of each asperity with the lattice, rad (default all 0).
    cantilever_N_m : float or None
        Cantilever spring ``k_c`` between the support and the tip body, N/m; ``None``:
        no tip body (asperities attached straight to the support).
    mass_body_kg : float or None
        Mass of the tip body (default half the settings' mass).
    mass_asperity_kg : tuple of float or None
        Mass of each asperity (default the rest of the settings' mass, shared equally).
    """

    U0_eV: tuple[float, ...]
    k_N_m: tuple[float, ...]
    phase_rad: tuple[float, ...] | None = None
    cantilever_N_m: float | None = None
    mass_body_kg: float | None = None
    mass_asperity_kg: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        n = len(self.U0_eV)
        if not 1 <= n <= MAX_ASPERITIES:
            raise SettingsError(f"a contact has 1-{MAX_ASPERITIES} asperities (got {n})")
        if len(self.k_N_m) != n or (self.phase_rad is not None and len(self.phase_rad) != n):
            raise SettingsError("U0_eV, k_N_m and phase_rad need one value per asperity")
        if self.mass_asperity_kg is not None and len(self.mass_asperity_kg) != n:
            raise SettingsError("mass_asperity_kg needs one value per asperity")
        if any(not (u >= 0 and math.isfinite(u)) for u in self.U0_eV):
            raise SettingsError(f"barriers must be >= 0 eV (got {self.U0_eV})")
        if any(not (k > 0 and math.isfinite(k)) for k in self.k_N_m):
            raise SettingsError(f"contact springs must be > 0 N/m (got {self.k_N_m})")
        if self.cantilever_N_m is not None and not self.cantilever_N_m > 0:
            raise SettingsError(f"cantilever spring must be > 0 N/m ({self.cantilever_N_m})")

    @property
    def n_asperities(self) -> int:
        return len(self.U0_eV)

    @property
    def has_body(self) -> bool:
        return self.cantilever_N_m is not None

    @property
    def phases(self) -> tuple[float, ...]:
        return self.phase_rad if self.phase_rad is not None else (0.0,) * self.n_asperities

    @property
    def barrier_sum_eV(self) -> float:
        """Sum of the asperities' barriers, eV (the effective U0 of a coherent contact)."""
        return float(sum(self.U0_eV))

    @property
    def series_N_m(self) -> float:
        """``(1/k_c + 1/sum k_i)^-1`` (``sum k_i`` without a cantilever), N/m."""
        k = float(sum(self.k_N_m))
        if self.cantilever_N_m is None:
            return k
        return 1.0 / (1.0 / self.cantilever_N_m + 1.0 / k)

    def masses_kg(self, total_kg: float) -> np.ndarray:
        """Masses of the coordinates (body first, if any), kg."""
        n = self.n_asperities
        share = 0.5 * total_kg if self.has_body else total_kg
        asp = (
            np.full(n, share / n) if self.mass_asperity_kg is None
            else np.asarray(self.mass_asperity_kg, float)
        )  # fmt: skip
        if not self.has_body:
            return asp
        body = 0.5 * total_kg if self.mass_body_kg is None else float(self.mass_body_kg)
        return np.concatenate([[body], asp])


def point_contact(U0_eV: float, K_N_m: float, phase_rad: float = 0.0) -> Contact:
    """Single-point PT as a :class:`Contact`: one asperity on the support, ``K = k_1``."""
    return Contact(U0_eV=(float(U0_eV),), k_N_m=(float(K_N_m),), phase_rad=(float(phase_rad),))


@dataclass(frozen=True)
class ContactLine:
    """One scan line: a contact, optionally replaced by ``after`` from ``change_nm`` on.

    ``change_nm`` is on the recorded axis (0 at the first pixel). ``after`` must have as
    many asperities as ``contact`` and a body exactly when it has one; masses are taken
    from ``contact``.
    """

    contact: Contact
    after: Contact | None = None
    change_nm: float | None = None

    def __post_init__(self) -> None:
        if (self.after is None) != (self.change_nm is None):
            raise SettingsError("a tip change needs both 'after' and 'change_nm'")
        if self.after is not None and (
            self.after.n_asperities != self.contact.n_asperities
            or self.after.has_body != self.contact.has_body
        ):
            raise SettingsError("a tip change keeps the number of asperities and the body")


def tip_change(
    U0_eV: float,
    K_N_m: float,
    change_nm: float,
    U0_factor: float = 1.0,
    K_factor: float = 1.0,
) -> ContactLine:
    """Single-point PT line whose U0 and K are multiplied by the factors at ``change_nm``."""
    before = point_contact(U0_eV, K_N_m)
    after = point_contact(U0_eV * U0_factor, K_N_m * K_factor)
    return ContactLine(before, after, float(change_nm))


def _as_lines(lines) -> list[ContactLine]:
    if isinstance(lines, (Contact, ContactLine)):
        lines = [lines]
    return [ln if isinstance(ln, ContactLine) else ContactLine(ln) for ln in lines]


# --------------------------------------------------------------------------------------
# packing into internal units
# --------------------------------------------------------------------------------------


@dataclass
class _Packed:
    body: np.ndarray  # (L,) int64 0/1
    n_asp: np.ndarray  # (L,) int64
    prm: np.ndarray  # (L, 2, 3, 6): [before/after][f0 nN, k nN/nm, phase rad]
    kc: np.ndarray  # (L, 2) nN/nm (0 without a body)
    mass: np.ndarray  # (L, 7) internal mass units
    a: float
    X_change: np.ndarray  # (L,) absolute support position, nm (inf: none)
    dt: np.ndarray  # (L,) ns
    n_pp: np.ndarray  # (L,) steps per pixel
    n_warm: np.ndarray  # (L,) warm-up steps
    dX: np.ndarray  # (L,) nm per step
    X0: np.ndarray  # (L,) support position of the first recorded step's start, nm


def _pack(lines: list[ContactLine], s: PhysicalSettings) -> _Packed:
    L = len(lines)
    a = float(s.lattice_nm)
    body = np.zeros(L, np.int64)
    n_asp = np.zeros(L, np.int64)
    prm = np.zeros((L, 2, 3, MAX_ASPERITIES))
    kc = np.zeros((L, 2))
    mass = np.ones((L, _MAXQ))
    X_change_rel = np.full(L, np.inf)
    omega2 = np.zeros(L)
    U0_sum, K_ser = np.zeros(L), np.zeros(L)
    for l_, ln in enumerate(lines):
        c = ln.contact
        n = c.n_asperities
        body[l_], n_asp[l_] = int(c.has_body), n
        m = c.masses_kg(s.mass_kg) * KG_TO_INTERNAL_MASS
        mass[l_, : m.size] = m
        for j, ct in enumerate((c, ln.after if ln.after is not None else c)):
            f0 = np.pi * np.asarray(ct.U0_eV) * EV_TO_NN_NM / a
            k = np.asarray(ct.k_N_m, float)
            prm[l_, j, 0, :n], prm[l_, j, 1, :n], prm[l_, j, 2, :n] = f0, k, ct.phases
            kc[l_, j] = ct.cantilever_N_m or 0.0
            # Gershgorin bound of M^-1 H
            rows = (2.0 * k + f0 * 2.0 * np.pi / a) / m[int(ct.has_body) :]
            w2 = rows.max()
            if ct.has_body:
                w2 = max(w2, (kc[l_, j] + 2.0 * k.sum()) / m[0])
            omega2[l_] = max(omega2[l_], w2)
        U0_sum[l_], K_ser[l_] = c.barrier_sum_eV, c.series_N_m
        if ln.change_nm is not None:
            X_change_rel[l_] = ln.change_nm
    v = np.full(L, float(s.velocity_nm_per_s))
    dt_s = np.minimum(s.dt_s, OMEGA_DT_MAX / np.sqrt(omega2) / S_TO_NS)  # omega in 1/ns
    n_pp = np.empty(L, np.int64)
    dt_eff = np.empty(L)
    for l_ in range(L):  # step_layout takes a scalar dt
        n_pp[l_ : l_ + 1], dt_eff[l_ : l_ + 1] = step_layout(
            s.pixel_nm, v[l_ : l_ + 1], dt_s[l_], 1
        )
    dt = dt_eff * S_TO_NS
    dX = v * PER_S_TO_PER_NS * dt
    warm = warmup_nm_for(U0_sum, K_ser, np.full(L, a), s.warmup_nm)
    n_warm = 2 * np.ceil(warm / dX / 2.0).astype(np.int64)
    X0 = n_warm * dX
    return _Packed(body, n_asp, prm, kc, mass, a, X0 + X_change_rel, dt, n_pp, n_warm, dX, X0)


# --------------------------------------------------------------------------------------
# Langevin (BAOAB) kernel
# --------------------------------------------------------------------------------------


@nb.njit(cache=True, fastmath=True, inline="always")
def _lv_forces(q, X, body, n, f0, kk, turns, kc, inv_a, f):
    """Forces ``-dE/dq`` into ``f``; returns the recorded force (polynomial sine)."""
    if body:
        y = q[0]
        fy = kc * (X - y)
        for i in range(n):
            d = q[1 + i] - y
            fy += kk[i] * d
            f[1 + i] = -kk[i] * d - f0[i] * sin_2pi(q[1 + i] * inv_a + turns[i])
        f[0] = fy
        return kc * (X - y)
    F = 0.0
    for i in range(n):
        d = X - q[i]
        F += kk[i] * d
        f[i] = kk[i] * d - f0[i] * sin_2pi(q[i] * inv_a + turns[i])
    return F


@nb.njit(cache=True, fastmath=True, parallel=True)
def _langevin_kernel(
    body, n_asp, prm, kc, mass, inv_a, X_change, dt, n_pp, n_warm, dX, gamma, kT,
    rng0, rng1, n_pix, out,
):  # fmt: skip
    """BAOAB for every line (one parallel task per line); pixel means into ``out``."""
    two_pi = 2.0 * math.pi
    for l in nb.prange(n_asp.size):
        bd = body[l] != 0
        n = n_asp[l]
        nq = n + body[l]
        h = 0.5 * dt[l]
        c = math.exp(-gamma * dt[l])
        hdtm = np.empty(_MAXQ)
        sig = np.empty(_MAXQ)
        for j in range(nq):
            hdtm[j] = h / mass[l, j]
            sig[j] = math.sqrt((1.0 - c * c) * kT / mass[l, j])
        noisy = kT > 0.0
        q = np.zeros(_MAXQ)
        u = np.zeros(_MAXQ)
        f = np.zeros(_MAXQ)
        tt = prm[l, :, 2] / two_pi  # registry in turns, before / after
        Xc = X_change[l]
        cur = 1 if Xc <= 0.0 else 0
        f0, kk, turns, kcl = prm[l, cur, 0], prm[l, cur, 1], tt[cur], kc[l, cur]
        X = 0.0
        _lv_forces(q, X, bd, n, f0, kk, turns, kcl, inv_a, f)
        s0, s1 = rng0[l], rng1[l]
        npp = n_pp[l]
        nw = n_warm[l]
        dXl = dX[l]
        acc = 0.0
        p = 0
        k_in = 0
        for step in range(nw + n_pix * npp):
            for j in range(nq):
                u[j] += hdtm[j] * f[j]
                q[j] += h * u[j]
            if noisy:
                for j in range(0, nq, 2):
                    ra, rb, s0, s1 = xoroshiro_pair(s0, s1)
                    g1, g2 = box_muller(ra, rb)
                    u[j] = c * u[j] + sig[j] * g1
                    if j + 1 < nq:
                        u[j + 1] = c * u[j + 1] + sig[j + 1] * g2
            else:
                for j in range(nq):
                    u[j] *= c
            for j in range(nq):
                q[j] += h * u[j]
            X += dXl
            if cur == 0 and X >= Xc:
                cur = 1
                f0, kk, turns, kcl = prm[l, 1, 0], prm[l, 1, 1], tt[1], kc[l, 1]
            fk = _lv_forces(q, X, bd, n, f0, kk, turns, kcl, inv_a, f)
            for j in range(nq):
                u[j] += hdtm[j] * f[j]
            if step >= nw:
                acc += fk
                k_in += 1
                if k_in == npp:
                    out[l, p] = acc / npp
                    p += 1
                    acc = 0.0
                    k_in = 0


# --------------------------------------------------------------------------------------
# quasi-static T = 0 solver
# --------------------------------------------------------------------------------------


@nb.njit(cache=True)
def _qs_grad(q, X, body, n, f0, kk, ph, kc, ka, g):
    """``g = dE/dq`` (nN); returns the recorded force (nN)."""
    if body:
        y = q[0]
        gy = kc * (y - X)
        for i in range(n):
            d = q[1 + i] - y
            gy -= kk[i] * d
            g[1 + i] = kk[i] * d + f0[i] * math.sin(ka * q[1 + i] + ph[i])
        g[0] = gy
        return kc * (X - y)
    F = 0.0
    for i in range(n):
        d = q[i] - X
        g[i] = kk[i] * d + f0[i] * math.sin(ka * q[i] + ph[i])
        F -= kk[i] * d
    return F


@nb.njit(cache=True)
def _qs_hess(q, body, n, f0, kk, ph, kc, ka, H):
    nq = n + body
    for i in range(nq):
        for j in range(nq):
            H[i, j] = 0.0
    if body:
        s = kc
        for i in range(n):
            s += kk[i]
            H[0, 1 + i] = -kk[i]
            H[1 + i, 0] = -kk[i]
            H[1 + i, 1 + i] = kk[i] + f0[i] * ka * math.cos(ka * q[1 + i] + ph[i])
        H[0, 0] = s
    else:
        for i in range(n):
            H[i, i] = kk[i] + f0[i] * ka * math.cos(ka * q[i] + ph[i])


@nb.njit(cache=True)
def _chol(A, nq, Lc):
    """Cholesky factor of ``A[:nq, :nq]`` into ``Lc``; False if not positive definite."""
    for j in range(nq):
        s = A[j, j]
        for k in range(j):
            s -= Lc[j, k] * Lc[j, k]
        if not s > 0.0:
            return False
        d = math.sqrt(s)
        Lc[j, j] = d
        for i in range(j + 1, nq):
            t = A[i, j]
            for k in range(j):
                t -= Lc[i, k] * Lc[j, k]
            Lc[i, j] = t / d
    return True


@nb.njit(cache=True)
def _chol_solve(Lc, nq, b, x):
    for i in range(nq):
        t = b[i]
        for k in range(i):
            t -= Lc[i, k] * x[k]
        x[i] = t / Lc[i, i]
    for i in range(nq - 1, -1, -1):
        t = x[i]
        for k in range(i + 1, nq):
            t -= Lc[k, i] * x[k]
        x[i] = t / Lc[i, i]


@nb.njit(cache=True)
def _tangent(q, body, n, f0, kk, ph, kc, ka, H, Lc, b, t):
    """``dq/dX`` on the equilibrium branch into ``t``; False if the Hessian is not PD."""
    nq = n + body
    _qs_hess(q, body, n, f0, kk, ph, kc, ka, H)
    if not _chol(H, nq, Lc):
        return False
    if body:
        b[0] = kc
        for i in range(n):
            b[1 + i] = 0.0
    else:
        for i in range(n):
            b[i] = kk[i]
    _chol_solve(Lc, nq, b, t)
    return True


@nb.njit(cache=True)
def _qs_step(q, X, X_new, body, n, f0, kk, ph, kc, ka, a, q_new, W, H, Lc):
    """Continue the stable branch from ``(q, X)`` to ``X_new`` into ``q_new``."""
    nq = n + body
    g, b, t = W[0], W[1], W[2]
    if not _tangent(q, body, n, f0, kk, ph, kc, ka, H, Lc, b, t):
        return False
    for j in range(nq):
        q_new[j] = q[j] + (X_new - X) * t[j]
    for _ in range(60):
        _qs_grad(q_new, X_new, body, n, f0, kk, ph, kc, ka, g)
        _qs_hess(q_new, body, n, f0, kk, ph, kc, ka, H)
        if not _chol(H, nq, Lc):
            return False
        for j in range(nq):
            b[j] = -g[j]
        _chol_solve(Lc, nq, b, t)
        step = 0.0
        far = 0.0
        for j in range(nq):
            q_new[j] += t[j]
            step = max(step, abs(t[j]))
            far = max(far, abs(q_new[j] - q[j]))
        if step > a / 16.0 or far > a / 4.0:
            return False
        if step < 1e-11:
            _qs_hess(q_new, body, n, f0, kk, ph, kc, ka, H)
            return _chol(H, nq, Lc)
    return False


@nb.njit(cache=True)
def _qs_relax(q, X, body, n, f0, kk, ph, kc, ka, a, mass, W, H, Lc, A):
    """Overdamped mass-weighted gradient flow to a local minimum (linearly implicit Euler,
    steps at most a/32, adaptive time step)."""
    nq = n + body
    g, b, t = W[0], W[1], W[2]
    _qs_hess(q, body, n, f0, kk, ph, kc, ka, H)
    lam = 0.0
    for i in range(nq):
        r = 0.0
        for j in range(nq):
            r += abs(H[i, j])
        lam = max(lam, r / mass[i])
    tau = 0.1 / lam
    for _ in range(20000):
        _qs_grad(q, X, body, n, f0, kk, ph, kc, ka, g)
        _qs_hess(q, body, n, f0, kk, ph, kc, ka, H)
        for i in range(nq):
            for j in range(nq):
                A[i, j] = H[i, j]
            A[i, i] += mass[i] / tau
        if not _chol(A, nq, Lc):
            tau *= 0.25
            continue
        for j in range(nq):
            b[j] = -g[j]
        _chol_solve(Lc, nq, b, t)
        step = 0.0
        for j in range(nq):
            step = max(step, abs(t[j]))
        if step > a / 32.0:
            tau *= 0.5
            continue
        for j in range(nq):
            q[j] += t[j]
        if step < 1e-11 and _chol(H, nq, Lc):
            return True
        tau = min(tau * 2.0, 1e300)
    return False


@nb.njit(cache=True)
def _qs_advance(q, X, X_b, body, n, f0, kk, ph, kc, ka, a, mass, W, H, Lc, A, q_new, q_lo):
    """Move the support from ``X`` to ``X_b`` (state ``q`` updated in place); returns
    the integral of the recorded force over the travel, nN nm."""
    nq = n + body
    g = W[3]
    F_a = _qs_grad(q, X, body, n, f0, kk, ph, kc, ka, g)
    total = 0.0
    for _ in range(1000):
        if X >= X_b:
            break
        if _qs_step(q, X, X_b, body, n, f0, kk, ph, kc, ka, a, q_new, W, H, Lc):
            F_b = _qs_grad(q_new, X_b, body, n, f0, kk, ph, kc, ka, g)
            total += 0.5 * (F_a + F_b) * (X_b - X)
            for j in range(nq):
                q[j] = q_new[j]
            X = X_b
            break
        # the branch ends (fold) between X and X_b: locate it by bisection
        lo, hi = X, X_b
        for j in range(nq):
            q_lo[j] = q[j]
        for _ in range(80):
            if hi - lo <= 1e-12:
                break
            mid = 0.5 * (lo + hi)
            if _qs_step(q_lo, lo, mid, body, n, f0, kk, ph, kc, ka, a, q_new, W, H, Lc):
                lo = mid
                for j in range(nq):
                    q_lo[j] = q_new[j]
            else:
                hi = mid
        F_lo = _qs_grad(q_lo, lo, body, n, f0, kk, ph, kc, ka, g)
        total += 0.5 * (F_a + F_lo) * (lo - X)
        # kick along the branch's tangent (the unstable direction at the fold), relax
        t = W[4]
        if _tangent(q_lo, body, n, f0, kk, ph, kc, ka, H, Lc, W[1], t):
            tm = 0.0
            for j in range(nq):
                tm = max(tm, abs(t[j]))
            for j in range(nq):
                q[j] = q_lo[j] + 1e-4 * a * t[j] / tm
        else:
            for j in range(nq):
                q[j] = q_lo[j]
        _qs_relax(q, hi, body, n, f0, kk, ph, kc, ka, a, mass, W, H, Lc, A)
        F_hi = _qs_grad(q, hi, body, n, f0, kk, ph, kc, ka, g)
        total += 0.5 * (F_lo + F_hi) * (hi - lo)
        X = hi
        F_a = F_hi
    return total


@nb.njit(cache=True)
def _quasistatic_kernel(body, n_asp, prm, kc, mass, a, X_change, X0, pix, n_pix, n_sub, out):
    """Quasi-static T = 0 waveform of every line; pixel means into ``out``."""
    ka = 2.0 * math.pi / a
    h = pix / n_sub
    for l in range(n_asp.size):
        bd = body[l]
        n = n_asp[l]
        W = np.zeros((5, _MAXQ))
        H = np.zeros((_MAXQ, _MAXQ))
        Lc = np.zeros((_MAXQ, _MAXQ))
        A = np.zeros((_MAXQ, _MAXQ))
        q = np.zeros(_MAXQ)
        q_new = np.zeros(_MAXQ)
        q_lo = np.zeros(_MAXQ)
        m = mass[l]
        Xc = X_change[l]
        j_prm = 1 if Xc <= 0.0 else 0
        f0, kk, ph, kcl = prm[l, j_prm, 0], prm[l, j_prm, 1], prm[l, j_prm, 2], kc[l, j_prm]
        X = 0.0
        _qs_relax(q, X, bd, n, f0, kk, ph, kcl, ka, a, m, W, H, Lc, A)
        n_w = int(math.ceil(X0[l] / h - 1e-9))
        acc = 0.0
        for step in range(n_w + n_pix * n_sub):
            rec = step >= n_w
            if rec:
                i_rec = step - n_w + 1
                X_b = X0[l] + (i_rec // n_sub) * pix + (i_rec % n_sub) * h
            else:
                X_b = min(X0[l], (step + 1) * h)
            if j_prm == 0 and X < Xc <= X_b:
                # the tip changes: to the change with the old contact, relax in the new one
                acc += _qs_advance(q, X, Xc, bd, n, f0, kk, ph, kcl, ka, a, m, W, H, Lc, A,
                                   q_new, q_lo)  # fmt: skip
                j_prm = 1
                f0, kk, ph, kcl = prm[l, 1, 0], prm[l, 1, 1], prm[l, 1, 2], kc[l, 1]
                _qs_relax(q, Xc, bd, n, f0, kk, ph, kcl, ka, a, m, W, H, Lc, A)
                X = Xc
            acc += _qs_advance(q, X, X_b, bd, n, f0, kk, ph, kcl, ka, a, m, W, H, Lc, A,
                               q_new, q_lo)  # fmt: skip
            X = X_b
            if not rec:
                acc = 0.0
            elif (step - n_w + 1) % n_sub == 0:
                out[l, (step - n_w) // n_sub] = acc / pix
                acc = 0.0


# --------------------------------------------------------------------------------------
# public simulators
# --------------------------------------------------------------------------------------


@dataclass
class ContactTraces:
    """Pixel-averaged lines of contacts.

    Attributes
    ----------
    force_nN : ndarray (L, pixels)
        Recorded force, each pixel the mean over its support-travel window, nN.
    x_nm : ndarray (pixels,)
        Recorded position, 0 at the first pixel, nm.
    support_nm : ndarray (L, pixels)
        Absolute support position at each pixel centre (warm-up included), nm.
    dt_s : ndarray (L,)
        Time step used (Langevin; NaN for the quasi-static solver), s.
    """

    force_nN: np.ndarray
    x_nm: np.ndarray
    support_nm: np.ndarray
    dt_s: np.ndarray


def _traces(force: np.ndarray, pk: _Packed, s: PhysicalSettings, dt_s: np.ndarray):
    centres = (np.arange(s.pixels) + 0.5) * s.pixel_nm
    return ContactTraces(
        force_nN=force,
        x_nm=np.arange(s.pixels) * s.pixel_nm,
        support_nm=pk.X0[:, None] + centres[None, :],
        dt_s=dt_s,
    )


def simulate_contacts(
    lines: Sequence[ContactLine | Contact] | ContactLine | Contact,
    settings: PhysicalSettings | None = None,
    *,
    seed: int = 0,
    indices: np.ndarray | None = None,
    temperature_K: float | None = None,
) -> ContactTraces:
    """Langevin (BAOAB) lines of multi-asperity contacts and tip changes.

    Parameters
    ----------
    lines : sequence of ContactLine or Contact
        One entry per line (a bare :class:`Contact` is a line without a change).
    settings : PhysicalSettings, optional
        Mass (total, split as in the module docs), damping, velocity, temperature,
        lattice, time step and recording (default: the paper preset, 296 K).
    seed : int
        Run seed; line ``i`` draws from the stream of ``(seed, indices[i])``.
    indices : array_like of int, optional
        Global line indices (default ``0..L-1``).
    temperature_K : float, optional
        Overrides ``settings.temperature_K`` (0: noiseless dynamics).

    Returns
    -------
    ContactTraces
    """
    s = settings or PhysicalSettings()
    T = s.temperature_K if temperature_K is None else float(temperature_K)
    if T < 0:
        raise SettingsError(f"temperature must be >= 0 K (got {T})")
    ln = _as_lines(lines)
    pk = _pack(ln, s)
    idx = np.arange(len(ln)) if indices is None else np.asarray(indices, np.int64)
    r0, r1 = rng_states(seed, idx)
    out = np.zeros((len(ln), s.pixels))
    _langevin_kernel(
        pk.body, pk.n_asp, pk.prm, pk.kc, pk.mass, 1.0 / pk.a, pk.X_change, pk.dt, pk.n_pp,
        pk.n_warm, pk.dX, s.damping_per_s * PER_S_TO_PER_NS, T * KB_NN_NM_PER_K, r0, r1,
        s.pixels, out,
    )  # fmt: skip
    return _traces(out, pk, s, pk.dt / S_TO_NS)


def quasistatic_contacts(
    lines: Sequence[ContactLine | Contact] | ContactLine | Contact,
    settings: PhysicalSettings | None = None,
    *,
    substeps: int = QS_SUBSTEPS,
) -> ContactTraces:
    """Noiseless T = 0 quasi-static waveforms (the truth convention's waveform).

    Same support positions as :func:`simulate_contacts` with the same settings (pixel
    ``p`` spans ``[X0 + p dx, X0 + (p + 1) dx]``). Only the lattice, recording and mass
    ratios of ``settings`` matter.
    """
    s = settings or PhysicalSettings()
    ln = _as_lines(lines)
    pk = _pack(ln, s)
    out = np.zeros((len(ln), s.pixels))
    _quasistatic_kernel(
        pk.body, pk.n_asp, pk.prm, pk.kc, pk.mass, pk.a, pk.X_change, pk.X0, s.pixel_nm,
        s.pixels, int(substeps), out,
    )  # fmt: skip
    return _traces(out, pk, s, np.full(len(ln), np.nan))


# --------------------------------------------------------------------------------------
# exact quasi-static single-point PT and the effective fit
# --------------------------------------------------------------------------------------


@nb.njit(cache=True)
def _pt_root(target, lo, hi, x, f0K, ka):
    """Root of ``x + f0K sin(ka x) = target`` in ``[lo, hi]`` (increasing there)."""
    if not lo <= x <= hi:
        x = 0.5 * (lo + hi)
    for _ in range(100):
        r = x + f0K * math.sin(ka * x) - target
        if r > 0.0:
            hi = x
        else:
            lo = x
        d = 1.0 + f0K * ka * math.cos(ka * x)
        xn = x - r / d if d > 0.0 else 0.5 * (lo + hi)
        if not lo < xn < hi:
            xn = 0.5 * (lo + hi)
        if abs(xn - x) < 1e-15 * (1.0 + abs(x)) or hi - lo < 1e-15 * (1.0 + abs(x)):
            return xn
        x = xn
    return x


@nb.njit(cache=True)
def _pt_pixels(f0, K, a, s, pix, n_pix, out):
    """Pixel means of quasi-static T = 0 PT over ``[s + p pix, s + (p + 1) pix]``."""
    ka = 2.0 * math.pi / a
    f0K = f0 / K
    eta = f0K * ka
    if eta > 1.0:
        xc = math.acos(-1.0 / eta) / ka
        Xs = xc + f0K * math.sin(ka * xc)
        xs = _pt_root(Xs, a - xc, a + xc, a, f0K, ka)
        xe = xc + a
    else:
        xs, Xs, xe = 0.0, 0.0, a
    s_ = math.sin(ka * xs)
    Gs = -(f0 / ka) * math.cos(ka * xs) + 0.5 * (f0 * s_) ** 2 / K
    s_ = math.sin(ka * xe)
    Ge = -(f0 / ka) * math.cos(ka * xe) + 0.5 * (f0 * s_) ** 2 / K
    A = Ge - Gs
    x = xs
    r_prev = -1.0
    I_prev = 0.0
    for p in range(n_pix + 1):
        u = s + p * pix - Xs
        nper = math.floor(u / a)
        r = u - nper * a
        guess = x if r >= r_prev else xs
        x = _pt_root(Xs + r, xs, xe, guess, f0K, ka)
        r_prev = r
        s_ = math.sin(ka * x)
        I = nper * A + (-(f0 / ka) * math.cos(ka * x) + 0.5 * (f0 * s_) ** 2 / K) - Gs
        if p > 0:
            out[p - 1] = (I - I_prev) / pix
        I_prev = I


def pt_quasistatic_force(
    U0_eV: float,
    K_N_m: float,
    phase_nm: float,
    pixel_nm: float,
    pixels: int,
    lattice_nm: float,
) -> np.ndarray:
    """Exact pixel means of quasi-static T = 0 single-point PT, nN.

    Pixel ``p`` is the mean force over support positions
    ``[phase_nm + p pixel_nm, phase_nm + (p + 1) pixel_nm]`` in the steady state, with
    ``U(x) = -(U0/2) cos(2 pi x / a)`` and every slip landing in the next well.
    """
    out = np.empty(int(pixels))
    f0 = np.pi * U0_eV * EV_TO_NN_NM / lattice_nm
    _pt_pixels(float(f0), float(K_N_m), float(lattice_nm), float(phase_nm), float(pixel_nm),
               int(pixels), out)  # fmt: skip
    return out


@dataclass
class EffectiveFit:
    """Effective PT parameters of lines (the truth convention of the module docs).

    Attributes
    ----------
    U0_eV, K_N_m, eta : ndarray (L,)
        Best-fitting single-point PT barrier (eV), stiffness (N/m) and its eta.
    phase_nm : ndarray (L,)
        Support offset of the fitted model, in ``[0, a)``, nm.
    rms_nN : ndarray (L,)
        RMS of model minus line, nN.
    misfit_fraction : ndarray (L,)
        ``rms_nN`` over the line's force range (max - min).
    """

    U0_eV: np.ndarray
    K_N_m: np.ndarray
    eta: np.ndarray
    phase_nm: np.ndarray
    rms_nN: np.ndarray
    misfit_fraction: np.ndarray

    @property
    def described(self) -> np.ndarray:
        """Whether one PT describes the line (``misfit_fraction <= MISFIT_LIMIT``)."""
        return self.misfit_fraction <= MISFIT_LIMIT


_ETA_GRID = (0.5, 1.1, 1.6, 2.5, 4.0, 6.5, 10.0, 16.0, 25.0, 40.0, 70.0)
_U0_SCALES = (1.0, 0.75)
_X_SCALE = np.array([0.1, 0.1, 0.02])


def _fit_one(
    F: np.ndarray, pix: float, a: float, n_starts: int
) -> tuple[float, float, float, float]:
    P = F.size
    ka = 2.0 * np.pi / a
    xc = (np.arange(P) + 0.5) * pix
    basis = np.exp(-1j * ka * xc)
    c_data = np.dot(F - F.mean(), basis)
    model = np.empty(P)

    def pixels(lf0: float, lK: float, s_over_a: float) -> np.ndarray:
        _pt_pixels(math.exp(lf0), math.exp(lK), a, s_over_a * a, pix, P, model)
        return model

    def aligned(lf0: float, lK: float) -> tuple[float, float]:
        m = pixels(lf0, lK, 0.0)
        c_m = np.dot(m - m.mean(), basis)
        s = (np.angle(c_data) - np.angle(c_m)) / (2.0 * np.pi) % 1.0
        r = pixels(lf0, lK, s) - F
        return s, float(np.dot(r, r))

    f0_guess = max(float(F.max()), 1e-6 * max(float(np.abs(F).max()), 1e-12), 1e-9)
    grid = []
    for scale in _U0_SCALES:
        lf0 = math.log(f0_guess * scale)
        for eta in _ETA_GRID:
            lK = math.log(f0_guess * scale * ka / eta)
            s, cost = aligned(lf0, lK)
            grid.append((cost, lf0, lK, s))
    grid.sort()

    def resid(th: np.ndarray) -> np.ndarray:
        return pixels(th[0], th[1], th[2]) - F

    best_cost, th = math.inf, np.array(grid[0][1:])
    for _, lf0, lK, s in grid[:n_starts]:
        res = least_squares(resid, np.array([lf0, lK, s]), method="lm", x_scale=_X_SCALE)
        if res.cost < best_cost:
            best_cost, th = res.cost, res.x
    r = resid(th)
    return math.exp(th[0]), math.exp(th[1]), th[2] % 1.0 * a, float(np.sqrt(np.mean(r * r)))


def fit_effective_pt(
    force_nN: np.ndarray, pixel_nm: float, lattice_nm: float, *, n_starts: int = 3
) -> EffectiveFit:
    """Effective PT parameters of noiseless lines (least squares over U0, K, phase).

    Parameters
    ----------
    force_nN : ndarray (L, pixels) or (pixels,)
        Pixel-averaged lines (contiguous pixels), nN; use the T = 0 waveform for truth.
    pixel_nm : float
        Support travel per pixel, nm.
    lattice_nm : float
        Lattice spacing a, nm.
    n_starts : int
        Least-squares runs, from the best points of a grid over eta (0.5-70) and two
        barrier guesses (``a max(F) / pi`` and 0.75 of it), each with the phase that
        aligns the lattice-frequency Fourier components of model and line.

    Returns
    -------
    EffectiveFit
    """
    F = np.atleast_2d(np.asarray(force_nN, float))
    L = F.shape[0]
    U0, K, ph, rms = (np.empty(L) for _ in range(4))
    for i in range(L):
        f0, K[i], ph[i], rms[i] = _fit_one(F[i], float(pixel_nm), float(lattice_nm), n_starts)
        U0[i] = f0 * lattice_nm / (np.pi * EV_TO_NN_NM)
    span = F.max(axis=1) - F.min(axis=1)
    return EffectiveFit(
        U0_eV=U0,
        K_N_m=K,
        eta=eta_from(U0, K, lattice_nm),
        phase_nm=ph,
        rms_nN=rms,
        misfit_fraction=rms / np.maximum(span, 1e-300),
    )


# --------------------------------------------------------------------------------------
# evaluation sets
# --------------------------------------------------------------------------------------

#: Ranges of the evaluation sets (the project's training range, eta from 1.5).
SET_U0_EV = (0.3, 6.0)
SET_K_N_M = (1.0, 50.0)
SET_ETA = (1.5, 40.0)
_KIND_CODE = {"multi": 1, "tip_change": 2}


@dataclass
class ContactSet:
    """An evaluation set of contact lines (:func:`contact_set`).

    Attributes
    ----------
    x_nm : ndarray (pixels,)
        Recorded position, nm.
    force_nN : ndarray (n, pixels)
        Lines at the settings' temperature (Langevin), nN.
    force_T0_nN : ndarray (n, pixels)
        Their noiseless T = 0 quasi-static waveforms (the truth's), nN.
    truth : dict of ndarray (n,)
        Per-line truth (see :func:`contact_set`).
    lines : list of ContactLine
        The contacts themselves.
    """

    x_nm: np.ndarray
    force_nN: np.ndarray
    force_T0_nN: np.ndarray
    truth: dict[str, np.ndarray]
    lines: list[ContactLine] = field(default_factory=list)


def _in_box(U0: float, K: float, a: float) -> bool:
    eta = float(eta_from(U0, K, a))
    return (
        SET_U0_EV[0] <= U0 <= SET_U0_EV[1]
        and SET_K_N_M[0] <= K <= SET_K_N_M[1]
        and SET_ETA[0] <= eta <= SET_ETA[1]
    )


def _draw_pt(rng: np.random.Generator, a: float) -> tuple[float, float]:
    while True:
        U0 = rng.uniform(*SET_U0_EV)
        K = rng.uniform(*SET_K_N_M)
        if _in_box(U0, K, a):
            return U0, K


def _draw_multi(rng: np.random.Generator, a: float) -> tuple[ContactLine, dict]:
    """A multi-asperity contact whose nominal (U0, K) lies in the set's box."""
    n = int(rng.integers(2, MAX_ASPERITIES + 1))
    registry = ("coherent", "partial", "random")[int(rng.integers(3))]
    spread = {"coherent": 0.0, "partial": rng.uniform(0.1, 0.6), "random": 1.0}[registry]
    phi0 = rng.uniform(0, 2 * np.pi)
    phases = phi0 + spread * rng.uniform(-np.pi, np.pi, n)
    w_u = rng.dirichlet(np.full(n, 2.0))  # barrier shares
    # stiffness shares follow the barriers loosely (bigger asperity, stiffer contact)
    w_k = w_u**0.5 * rng.lognormal(0.0, 0.3, n)
    w_k /= w_k.sum()
    coherent_amp = float(np.abs(np.sum(w_u * np.exp(1j * phases))))
    while True:
        U0_t, K_t = _draw_pt(rng, a)
        if coherent_amp < 0.3:  # nearly cancelling registry: redraw it
            phases = phi0 + spread * rng.uniform(-np.pi, np.pi, n)
            coherent_amp = float(np.abs(np.sum(w_u * np.exp(1j * phases))))
            continue
        U0_sum = U0_t / coherent_amp
        ratio = math.exp(rng.uniform(math.log(0.5), math.log(30.0)))  # sum k_i / k_c
        kc = K_t * (1.0 + 1.0 / ratio)
        k_sum = ratio * kc
        contact = Contact(
            U0_eV=tuple(U0_sum * w_u),
            k_N_m=tuple(k_sum * w_k),
            phase_rad=tuple(np.mod(phases, 2 * np.pi)),
            cantilever_N_m=kc,
        )
        info = {"registry": registry, "phase_spread_rad": spread * np.pi,
                "stiffness_ratio": ratio}  # fmt: skip
        return ContactLine(contact), info


def _draw_change(rng: np.random.Generator, a: float, length_nm: float):
    while True:
        U0, K = _draw_pt(rng, a)
        which = int(rng.integers(3))  # 0: U0, 1: K, 2: both
        fu = rng.uniform(1.3, 2.0) ** rng.choice([-1.0, 1.0]) if which != 1 else 1.0
        fk = rng.uniform(1.3, 2.0) ** rng.choice([-1.0, 1.0]) if which != 0 else 1.0
        if _in_box(U0 * fu, K * fk, a):
            change = rng.uniform(0.25, 0.75) * length_nm
            return tip_change(U0, K, change, fu, fk), {"U0_factor": fu, "K_factor": fk}


def contact_set(
    n: int,
    kind: str,
    seed: int,
    settings: PhysicalSettings | None = None,
    *,
    langevin: bool = True,
    max_tries: int = 20,
) -> ContactSet:
    """Evaluation set of multi-asperity (``"multi"``) or tip-change (``"tip_change"``) lines.

    Multi-asperity: 2-6 asperities, registry coherent, partial (phases spread over
    0.1-0.6 of the circle) or random (1/3 each), barrier shares Dirichlet(2), contact
    springs ``sum k_i / k_c`` log-uniform in [0.5, 30], with the coherent-sum barrier and
    the series stiffness drawn uniformly in the box U0 0.3-6 eV, K 1-50 N/m,
    eta 1.5-40. A draw is kept when its effective fit lies in that box too, or when no
    single PT describes it (misfit above :data:`MISFIT_LIMIT`; up to ``max_tries`` draws,
    then the last one is kept). Tip change: single-point PT in the box, U0, K or both
    multiplied by 1.3-2x (up or down, staying in the box) at a support position uniform
    over the middle half of the line.

    Parameters
    ----------
    n : int
        Number of lines.
    kind : {"multi", "tip_change"}
    seed : int
        Seed of the draws and of the thermal noise (the set depends only on
        ``(n, kind, seed, settings)``).
    settings : PhysicalSettings, optional
        Recording and dynamics (default: the paper preset, 296 K).
    langevin : bool
        Simulate the finite-temperature lines (else ``force_nN`` is the T = 0 waveform).

    Returns
    -------
    ContactSet
        ``truth`` holds, per line: ``kind``, ``U0_eV``, ``K_N_m``, ``eta`` (effective
        fit of the T = 0 waveform), ``misfit_fraction``, ``described`` (one PT describes
        the line: multi-asperity lines within :data:`MISFIT_LIMIT`; never a tip change),
        ``n_asperities``, ``registry``, ``phase_spread_rad``, ``stiffness_ratio``
        (``sum k_i / k_c``), ``U0_sum_eV``, ``K_series_N_m``, ``change_nm`` (NaN without a
        change), ``U0_before_eV``, ``K_before_N_m``, ``U0_after_eV``, ``K_after_N_m``,
        ``U0_factor``, ``K_factor``, ``mean_force_nN`` (mean of ``force_nN``).
    """
    if kind not in _KIND_CODE:
        raise SettingsError(f"kind must be 'multi' or 'tip_change' (got {kind!r})")
    s = settings or PhysicalSettings()
    a = s.lattice_nm
    rng = np.random.default_rng([int(seed), _KIND_CODE[kind], 40])
    lines: list[ContactLine] = []
    infos: list[dict] = []
    F0 = np.empty((n, s.pixels))
    fits: list[tuple] = []
    for i in range(n):
        for _ in range(max_tries):
            if kind == "multi":
                line, info = _draw_multi(rng, a)
            else:
                line, info = _draw_change(rng, a, s.length_nm)
            f = quasistatic_contacts([line], s).force_nN[0]
            ft = fit_effective_pt(f, s.pixel_nm, a)
            ok = kind == "tip_change" or (
                _in_box(float(ft.U0_eV[0]), float(ft.K_N_m[0]), a) or not bool(ft.described[0])
            )
            if ok:
                break
        lines.append(line)
        infos.append(info)
        F0[i] = f
        fits.append((ft.U0_eV[0], ft.K_N_m[0], ft.eta[0], ft.misfit_fraction[0]))
    fit = np.array(fits, float).reshape(n, 4)
    if langevin:
        F = simulate_contacts(lines, s, seed=int(seed) * 8 + _KIND_CODE[kind]).force_nN
    else:
        F = F0.copy()
    nan = np.full(n, np.nan)
    truth: dict[str, np.ndarray] = {
        "kind": np.full(n, kind),
        "U0_eV": fit[:, 0],
        "K_N_m": fit[:, 1],
        "eta": fit[:, 2],
        "misfit_fraction": fit[:, 3],
        "described": (fit[:, 3] <= MISFIT_LIMIT) & (kind == "multi"),
        "n_asperities": np.array([ln.contact.n_asperities for ln in lines]),
        "registry": np.array([inf.get("registry", "") for inf in infos]),
        "phase_spread_rad": np.array([inf.get("phase_spread_rad", 0.0) for inf in infos]),
        "stiffness_ratio": np.array([inf.get("stiffness_ratio", np.nan) for inf in infos]),
        "U0_sum_eV": np.array([ln.contact.barrier_sum_eV for ln in lines]),
        "K_series_N_m": np.array([ln.contact.series_N_m for ln in lines]),
        "change_nm": np.array(
            [np.nan if ln.change_nm is None else ln.change_nm for ln in lines]
        ),  # fmt: skip
        "U0_before_eV": nan.copy(),
        "K_before_N_m": nan.copy(),
        "U0_after_eV": nan.copy(),
        "K_after_N_m": nan.copy(),
        "U0_factor": np.array([inf.get("U0_factor", np.nan) for inf in infos]),
        "K_factor": np.array([inf.get("K_factor", np.nan) for inf in infos]),
        "mean_force_nN": F.mean(axis=1),
    }
    if kind == "tip_change":
        for i, ln in enumerate(lines):
            truth["U0_before_eV"][i] = ln.contact.barrier_sum_eV
            truth["K_before_N_m"][i] = ln.contact.series_N_m
            truth["U0_after_eV"][i] = ln.after.barrier_sum_eV
            truth["K_after_N_m"][i] = ln.after.series_N_m
    return ContactSet(x_nm=np.arange(s.pixels) * s.pixel_nm, force_nN=F, force_T0_nN=F0,
                      truth=truth, lines=lines)  # fmt: skip


def described_dataset(x_nm: np.ndarray, force_nN: np.ndarray, truth: dict[str, np.ndarray],
                      settings: PhysicalSettings | None = None) -> Dataset:  # fmt: skip
    """The lines of a contact set (:func:`contact_set`: its ``x_nm``, ``force_nN`` and
    ``truth``) that one effective PT describes, as a dataset whose params are their
    truths, as a randomised set's are.

    ``U0_eV``, ``K_N_m`` and ``eta`` are the effective fit (the task's truth),
    ``F_mean_nN`` the line's mean force, and the recording's ``lattice_nm``,
    ``velocity_nm_per_s``, ``temperature_K``, ``damping_per_s`` and ``mass_kg`` those of
    ``settings`` (the set's own; default the paper preset). Lines no single PT
    describes (misfit above :data:`MISFIT_LIMIT`) and tip changes are left out: they
    have no one (U0, K) for an interval to hold.
    """
    s = settings or PhysicalSettings()
    keep = np.flatnonzero(np.asarray(truth["described"], bool))
    F = np.asarray(force_nN, float)[keep]
    n = keep.size
    params = {
        "U0_eV": np.asarray(truth["U0_eV"], float)[keep],
        "K_N_m": np.asarray(truth["K_N_m"], float)[keep],
        "eta": np.asarray(truth["eta"], float)[keep],
        "F_mean_nN": F.mean(axis=1),
        "lattice_nm": np.full(n, s.lattice_nm),
        "velocity_nm_per_s": np.full(n, s.velocity_nm_per_s),
        "temperature_K": np.full(n, s.temperature_K),
        "damping_per_s": np.full(n, s.damping_per_s),
        "mass_kg": np.full(n, s.mass_kg),
    }
    return Dataset(F, np.asarray(x_nm, float), params, {"kind": "contacts-described", "n": n})


def cached_contact_set(n: int, kind: str, seed: int, work: str | os.PathLike | None
                       ) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:  # fmt: skip
    """``(x_nm, force_nN, truth)`` of :func:`contact_set` ``(n, kind, seed)`` (paper preset),
    simulated once into ``work/{kind}_{n}_{seed}.npz`` (written whole, then renamed) and
    read from there after; the truth's numeric columns only. ``work`` None: simulated
    and returned, nothing written."""
    if work is None:
        cs = contact_set(n, kind, seed, PhysicalSettings())
        return np.asarray(cs.x_nm, float), np.asarray(cs.force_nN, float), cs.truth
    path = Path(work) / f"{kind}_{n}_{seed}.npz"
    if not path.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
        cs = contact_set(n, kind, seed, PhysicalSettings())
        out = {"x_nm": np.asarray(cs.x_nm, float), "force_nN": np.asarray(cs.force_nN, float)}
        for key, val in cs.truth.items():
            arr = np.asarray(val)
            if arr.dtype.kind in "fiub":
                out[f"truth_{key}"] = arr.astype(float)
        part = path.with_name(path.name + ".partial.npz")
        np.savez_compressed(part, **out)
        os.replace(part, path)
    with np.load(path, allow_pickle=False) as z:
        truth = {k[len("truth_"):]: z[k] for k in z.files if k.startswith("truth_")}
        return z["x_nm"], z["force_nN"], truth
