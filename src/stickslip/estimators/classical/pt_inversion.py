"""Inversion of the Prandtl-Tomlinson relations, with the finite-temperature correction.

Conventions of ../shared/PHYSICS.md: ``U(x) = -(U0/2) cos(2 pi x/a)``, ``F = K (X - x)``,
``eta = 2 pi^2 U0/(K a^2)``, ``F_max = pi U0/a``, so ``K eta = 2 pi F_max/a``.

Stick slope along the whole rising branch
    On the branch ``F = F_max sin(theta)``, ``X = (a/2 pi) theta + F/K`` (theta = 2 pi x/a),
    so ``1/(dF/dX) = 1/K + a/(2 pi F_max c)``, ``c = sqrt(1 - (F/F_max)^2)``: the slope is
    ``K eta c/(1 + eta c)``. A straight line fitted to a stick segment from ``F_lo`` to
    ``F_hi`` is the secant of the branch, hence
    ``1/k_seg = 1/K + (a/2 pi) [asin(F_hi/F_max) - asin(F_lo/F_max)]/(F_hi - F_lo)``,
    which gives K for each segment once F_max is known. At ``F_lo = F_hi = 0`` this is the
    textbook ``k_exp = K eta/(1 + eta)``.

Thermal activation (finite T)
    The measured peak lies below F_max because slips come early. At support position X
    the tip sits at ``theta`` on the branch and has to cross the barrier
    ``dE/U0 = -(cos th_b - cos th)/2 + [(th_b - th - eta sin th)^2 - (eta sin th)^2]/(4 eta)``
    to the saddle ``th_b`` (root of ``sin th_b - sin th + (th_b - th)/eta = 0`` beyond the
    inflection ``cos th_c = -1/eta``). The escape rate is Kramers' (Kramers-Grote-Hynes
    form, valid from moderate to strong damping)
    ``r = (w_min/2 pi) (sqrt(Gamma^2/4 + w_b^2) - Gamma/2)/w_b exp(-dE/kT)``,
    ``w_min^2 = K (1 + eta cos th)/m``, ``w_b^2 = -K (1 + eta cos th_b)/m``, and the
    branch is swept at ``dt = (a/2 pi)(1 + eta cos th)/v dth``. Integrating the hazard
    from the landing point gives the distribution of the slip point. Between slips the
    tip fluctuates in its well far faster than a pixel lasts, so the recorded force is
    the well's Boltzmann mean (:func:`thermal_force`), not the T = 0 branch
    ``F_max sin(th)``: where the well is shallow against kT (a stiff contact, eta below
    about 3, a low barrier) its softer forward side holds the tip ahead of the minimum
    and the mean force falls several per cent below the branch near the slips. The
    expected peak is the highest mean force up to the slip point, averaged over the slip
    points (it is ``E[F_max sin(min(th_slip, pi/2))]`` as kT goes to 0). F_max is the
    value for which this expectation equals the measured mean peak (fixed-point
    iteration; K is re-derived from the slopes at each step). T, v and a are the
    user's; m and Gamma default to the paper preset and enter only through the
    logarithmic prefactor.

Pixel averaging
    Handled on the measurement side (:mod:`stickslip.estimators.classical.slips`): the slip force
    is the pre-slip branch evaluated at the sub-pixel slip position, so the averaging of
    the slip pixel does not lower the peak. The pre-slip branch is a quadratic over the
    stick, so what remains is where the force bends away from it near the slip: on a
    stiff contact (eta below about 2) the stick's fitted top reads about 3 % low even
    at T = 0, and at room temperature, where the mean force flattens just before the
    slip (eta 4-6), the stick's trend carried to the slip reads about 1 % above it.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from stickslip.robust import median
from stickslip.units import EV_TO_NN_NM, KB_NN_NM_PER_K

N_GRID = 160  # branch points of the thermal model
MAX_ITER = 12
N_WELL = 16  # quadrature points across the tip's well (the thermal mean force)
WELL_SIGMAS = 8.0  # half-width of that quadrature, in the well's thermal spreads
SLIP_SHARE_MIN = 1e-12  # shares of the sticks slipping below this add nothing to the mean peak


@njit(cache=True, error_model="numpy")
def k_from_segment(k_seg: float, F_lo: float, F_hi: float, Fmax: float, a: float) -> float:
    """Contact stiffness K (N/m) from a segment's secant slope (NaN if inconsistent)."""
    if not (k_seg > 0) or not (Fmax > 0):
        return np.nan
    r_lo = min(max(F_lo / Fmax, -1.0), 1.0)
    r_hi = min(max(F_hi / Fmax, -1.0), 1.0)
    if r_hi - r_lo > 1e-6:
        g = (np.arcsin(r_hi) - np.arcsin(r_lo)) / (r_hi - r_lo)
    else:  # derivative of asin at the midpoint
        rm = min(max(0.5 * (r_lo + r_hi), -0.999999), 0.999999)
        g = 1.0 / np.sqrt(1.0 - rm * rm)
    inv = 1.0 / k_seg - a / (2.0 * np.pi * Fmax) * g
    return 1.0 / inv if inv > 0 else np.nan


@njit(cache=True, error_model="numpy")
def _saddle(th: float, eta: float, th_c: float, guess: float) -> float:
    """Saddle phase ahead of the minimum at ``th`` (NaN if there is none).

    Safeguarded Newton on ``h = sin th_b - sin th + (th_b - th)/eta``, which decreases
    on ``[th_c, 2 pi - th_c]``; ``guess`` is the previous grid point's saddle.
    """
    lo = th_c
    hi = 2.0 * np.pi - th_c
    s = np.sin(th)
    if np.sin(hi) - s + (hi - th) / eta > 0:
        return np.nan
    t = guess if lo < guess < hi else 0.5 * (lo + hi)
    for _ in range(60):
        h = np.sin(t) - s + (t - th) / eta
        if h > 0:
            lo = t
        else:
            hi = t
        dh = np.cos(t) + 1.0 / eta
        tn = t - h / dh if dh < 0 else 0.5 * (lo + hi)
        if not (lo < tn < hi):
            tn = 0.5 * (lo + hi)
        if abs(tn - t) < 1e-11:
            return tn
        t = tn
    return t


@njit(cache=True, error_model="numpy", inline="always")
def _energy(phi: float, th: float, eta: float) -> float:
    """Energy over U0 of a tip at phase ``phi`` while the support holds the T = 0 minimum
    at ``th``: ``-cos(phi)/2 + (th - phi + eta sin th)^2/(4 eta)``."""
    d = th - phi + eta * np.sin(th)
    return -0.5 * np.cos(phi) + d * d / (4.0 * eta)


@njit(cache=True, error_model="numpy")
def thermal_force(th: float, thb: float, eta: float, u_kT: float) -> float:
    """Mean lateral force over ``F_max`` of a tip in equilibrium in its well.

    The tip's T = 0 minimum is at phase ``th`` (support at ``X = (a/2 pi)(th + eta sin
    th)``); it fluctuates in the energy ``U0 [-cos(phi)/2 + (th - phi + eta sin th)^2/
    (4 eta)]`` with Boltzmann weight ``exp(-U0 E/kT)`` (``u_kT = U0/kT``), up to the saddle
    ``thb`` ahead (NaN: none). A pixel averages many such fluctuations, so the recorded
    force is this mean, ``sin(th) - <phi - th>/eta``; the well's forward side softens
    as the slip nears, so the mean falls below ``sin(th)`` where the well is shallow
    against kT (low eta, low U0).
    """
    c = 1.0 + eta * np.cos(th)  # the well's curvature, in units of U0/(2 eta)
    st = np.sin(th)
    if not (c > 0 and u_kT > 0):
        return st
    spread = np.sqrt(2.0 * eta / (u_kT * c))
    lo = max(th - WELL_SIGMAS * spread, -np.arccos(-1.0 / eta) if eta > 1.0 else -np.pi)
    hi = th + WELL_SIGMAS * spread
    if thb < hi:  # NaN compares false: no saddle, no cut
        hi = thb
    if not hi > lo:
        return st
    e0 = _energy(th, th, eta)
    sw = 0.0
    sm = 0.0
    for j in range(N_WELL):
        phi = lo + (hi - lo) * (j + 0.5) / N_WELL
        w = np.exp(-u_kT * (_energy(phi, th, eta) - e0))
        sw += w
        sm += w * (phi - th)
    return st - sm / (sw * eta) if sw > 0 else st


@njit(cache=True, error_model="numpy")
def expected_peak(Fmax: float, K: float, theta_lo: float, a: float, T: float, v: float,
                  mass_kg: float, gamma: float) -> float:  # fmt: skip
    """Mean peak force (nN) of a stick phase at temperature T (see module docstring).

    Parameters
    ----------
    Fmax : float
        ``pi U0/a`` in nN.
    K : float
        Contact stiffness in N/m.
    theta_lo : float
        Phase ``2 pi x/a`` where the stick starts (landing after the previous slip).
    a, T, v : float
        Lattice (nm), temperature (K), support velocity (nm/s).
    mass_kg, gamma : float
        Effective mass and damping rate (1/s).
    """
    eta = 2.0 * np.pi * Fmax / (a * K)
    if T <= 0 or eta <= 1.0:
        return Fmax
    U0 = a * Fmax / np.pi  # nN nm
    kT = KB_NN_NM_PER_K * T
    th_c = np.arccos(-1.0 / eta)
    th_lo = min(theta_lo, th_c - 1e-6)
    w2 = K / mass_kg  # K/m in 1/s^2
    u_kT = U0 / kT
    ths = np.empty(N_GRID)
    thbs = np.empty(N_GRID)
    # the mean force at each grid point, over F_max, evaluated only where it is needed:
    # where sticks slip, and back from there to the branch's highest point before
    tops = np.full(N_GRID, np.nan)
    S_prev = 1.0
    H = 0.0
    total = 0.0
    rate_dt_prev = 0.0
    th_prev = th_lo
    thb = np.nan
    top = -np.inf  # the highest mean force along the stick so far
    for j in range(N_GRID):
        u = j / (N_GRID - 1.0)
        # points crowd towards th_c, where the barrier vanishes
        th = th_c - (th_c - th_lo) * (1.0 - u) ** 2
        rate_dt = 0.0
        lin = 1.0 + eta * np.cos(th)
        thb = _saddle(th, eta, th_c, thb) if j < N_GRID - 1 else np.nan
        ths[j] = th
        thbs[j] = thb
        if lin > 0 and not np.isnan(thb):
            e = _energy(thb, th, eta) - _energy(th, th, eta)
            wmin = np.sqrt(w2 * lin)
            wb = np.sqrt(max(-w2 * (1.0 + eta * np.cos(thb)), 1e-30))
            kgh = (np.sqrt(0.25 * gamma * gamma + wb * wb) - 0.5 * gamma) / wb
            pref = wmin / (2.0 * np.pi) * kgh
            # hazard per unit phase: rate x dt/dtheta
            rate_dt = pref * np.exp(-U0 * e / kT) * (a / (2.0 * np.pi)) * lin / v
        if j > 0:
            H += 0.5 * (rate_dt + rate_dt_prev) * (th - th_prev)
            S = np.exp(-H)
            if S_prev - S > SLIP_SHARE_MIN:
                if top == -np.inf:  # the first slips: the stick's top so far
                    top = _top_before(j, ths, thbs, tops, eta, u_kT)
                tops[j] = thermal_force(th, thb, eta, u_kT)
                top = max(top, tops[j])
                total += (S_prev - S) * Fmax * top
            S_prev = S
            if S < SLIP_SHARE_MIN:
                # every stick has slipped but a share below SLIP_SHARE_MIN, whose peaks
                # would change the mean by less than that share of F_max
                return total
        rate_dt_prev = rate_dt
        th_prev = th
    # whatever survives slips at th_c > pi/2, past the branch's top: its peak is the
    # highest mean force along the whole branch
    for j in range(N_GRID):
        if np.isnan(tops[j]):
            tops[j] = thermal_force(ths[j], thbs[j], eta, u_kT)
        top = max(top, tops[j])
    return total + S_prev * Fmax * top


@njit(cache=True, error_model="numpy")
def _top_before(j: int, ths: np.ndarray, thbs: np.ndarray, tops: np.ndarray, eta: float,
                u_kT: float) -> float:  # fmt: skip
    """The highest mean force of the grid points before ``j`` (filling ``tops``), read
    backwards from ``j - 1`` for as long as it rises: the branch's mean force has one
    maximum, so where it falls backwards the points further back are lower still."""
    k = j - 1
    tops[k] = thermal_force(ths[k], thbs[k], eta, u_kT)
    best = tops[k]
    while k > 0:
        tops[k - 1] = thermal_force(ths[k - 1], thbs[k - 1], eta, u_kT)
        if tops[k - 1] <= tops[k]:
            break
        best = max(best, tops[k - 1])
        k -= 1
    return best


@njit(cache=True, error_model="numpy")
def median_k(k_seg: np.ndarray, F_lo: np.ndarray, F_hi: np.ndarray, Fmax: float,
             a: float, out: np.ndarray) -> float:  # fmt: skip
    """Median over segments of :func:`k_from_segment`; ``out`` receives each segment's K."""
    for i in range(k_seg.size):
        out[i] = k_from_segment(k_seg[i], F_lo[i], F_hi[i], Fmax, a)
    vals = out[~np.isnan(out)]
    return median(vals) if vals.size > 0 else np.nan


@njit(cache=True, error_model="numpy")
def invert(F_peak: float, F_after: float, k_seg: np.ndarray, F_lo: np.ndarray,
           F_hi: np.ndarray, a: float, T: float, v: float, mass_kg: float, gamma: float,
           K_out: np.ndarray) -> tuple[float, float]:  # fmt: skip
    """Solve for ``(F_max, K)`` from the mean peak force and the segment slopes.

    ``K_out`` receives the per-segment K at the final F_max. Returns NaNs when the
    slopes are inconsistent with the peak (no positive K).
    """
    Fmax = F_peak
    K = np.nan
    for _ in range(MAX_ITER):
        K = median_k(k_seg, F_lo, F_hi, Fmax, a, K_out)
        if np.isnan(K) or T <= 0:
            break
        th_lo = np.arcsin(min(max(F_after / Fmax, -1.0), 1.0))
        pred = expected_peak(Fmax, K, th_lo, a, T, v, mass_kg, gamma)
        ratio = F_peak / pred
        Fmax *= ratio
        if abs(ratio - 1.0) < 1e-4:
            break
    K = median_k(k_seg, F_lo, F_hi, Fmax, a, K_out)
    return Fmax, K


def u0_eV_from_fmax(Fmax_nN, lattice_nm):
    """``U0 = a F_max/pi`` in eV (array-friendly)."""
    return np.asarray(lattice_nm) * np.asarray(Fmax_nN) / np.pi / EV_TO_NN_NM
