"""Production BAOAB kernel: numba, parallel over blocks of trajectories.

Layout for speed: trajectories are processed in blocks of ``LANES`` (32); the innermost
loop runs over the lanes of a block with a compile-time trip count, so LLVM emits wide
SIMD code for it. The hot loop calls no libm function: sine is an odd polynomial after
range reduction, the logarithm of Box-Muller uses the leading-zero count of the random
integer for the exponent and a short series for the mantissa, and every lane carries its
own xoroshiro128++ generator. The augmented substrate (modulation, defects) is compiled
as a separate specialisation that uses libm; plain PT runs never pay for it.

All arithmetic is float64 in internal units (nm, ns, nN); see :mod:`stickslip.units`.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np
from numba.cpython.unsafe.numbers import leading_zeros

from stickslip.simulation.lanes import Lanes

LANES = 32

_TWO_PI = 2.0 * math.pi
_HALF_PI = 0.5 * math.pi
_LN2 = math.log(2.0)
_SQRT2 = math.sqrt(2.0)
_2M52 = 2.0**-52
_2M53 = 2.0**-53
# Taylor coefficients of sin(s)/s in s^2, accurate to ~1e-11 on |s| <= pi/2
_S3, _S5, _S7 = -1.0 / 6.0, 1.0 / 120.0, -1.0 / 5040.0
_S9, _S11, _S13 = 1.0 / 362880.0, -1.0 / 39916800.0, 1.0 / 6227020800.0
_S15 = -1.0 / 1307674368000.0

_U11 = np.uint64(11)
_U17 = np.uint64(17)
_U21 = np.uint64(21)
_U28 = np.uint64(28)
_U36 = np.uint64(36)
_U43 = np.uint64(43)
_U47 = np.uint64(47)
_U49 = np.uint64(49)
_U1 = np.uint64(1)
_U15 = np.uint64(15)

_jit = nb.njit(cache=True, fastmath=True, inline="always")


@_jit
def sin_2pi(t):
    """sin(2 pi t) for any float t, polynomial (no libm)."""
    r = t - math.floor(t + 0.5)  # r in [-0.5, 0.5]
    s = _TWO_PI * r
    s = max(min(s, math.pi - s), -math.pi - s)  # fold to [-pi/2, pi/2]
    s2 = s * s
    p = _S15
    p = p * s2 + _S13
    p = p * s2 + _S11
    p = p * s2 + _S9
    p = p * s2 + _S7
    p = p * s2 + _S5
    p = p * s2 + _S3
    return s + s * s2 * p


@_jit
def neg2log_unit(r):
    """-2 ln(u) for u = r * 2^-64 in (0, 1), r a random uint64 (no libm)."""
    r = r | _U1
    lz = leading_zeros(r)
    mant = float((r << lz) >> _U11) * _2M52  # in [1, 2)
    big = mant > _SQRT2
    m = mant * 0.5 if big else mant
    e = -(float(lz) + 1.0) + (1.0 if big else 0.0)
    s = (m - 1.0) / (m + 1.0)
    s2 = s * s
    p = 1.0 / 13.0
    p = p * s2 + 1.0 / 11.0
    p = p * s2 + 1.0 / 9.0
    p = p * s2 + 1.0 / 7.0
    p = p * s2 + 1.0 / 5.0
    p = p * s2 + 1.0 / 3.0
    p = p * s2 + 1.0
    return -2.0 * (2.0 * s * p + e * _LN2)


@_jit
def _rotl(v, k, k_comp):
    return (v << k) | (v >> k_comp)


@_jit
def xoroshiro_pair(a0, a1):
    """Two outputs of xoroshiro128++ and the advanced state."""
    ra = _rotl(a0 + a1, _U17, _U47) + a0
    a1 ^= a0
    a0 = _rotl(a0, _U49, _U15) ^ a1 ^ (a1 << _U21)
    a1 = _rotl(a1, _U28, _U36)
    rb = _rotl(a0 + a1, _U17, _U47) + a0
    a1 ^= a0
    a0 = _rotl(a0, _U49, _U15) ^ a1 ^ (a1 << _U21)
    a1 = _rotl(a1, _U28, _U36)
    return ra, rb, a0, a1


@_jit
def box_muller(ra, rb):
    """Two independent standard normals from two random uint64 (no libm)."""
    rad = math.sqrt(neg2log_unit(ra))
    t = float(rb >> _U11) * _2M53
    return rad * sin_2pi(t), rad * sin_2pi(t + 0.25)


@_jit
def substrate_force(aug, x, f0, inv_a, half_U0, i):
    """-dU/dx of the substrate at tip position ``x`` for lane ``i``.

    ``aug`` is None for the plain sinusoid (numba prunes the other branch at compile
    time, so plain runs keep the libm-free vector code), else the tuple
    ``(modulation (N, 3) [amplitude, q, phase], defect x, defect H, defect 1/(2w^2))``.
    """
    if aug is None:
        return -f0 * sin_2pi(x * inv_a)
    mod, def_x, def_H, def_c = aug
    amp, q, ph = mod[i, 0], mod[i, 1], mod[i, 2]
    kx = _TWO_PI * x * inv_a
    qx = q * x + ph
    fs = -f0 * (1.0 + amp * math.cos(qx)) * math.sin(kx)
    fs -= half_U0 * amp * q * math.sin(qx) * math.cos(kx)
    for j in range(def_x.shape[1]):
        d = x - def_x[i, j]
        fs += 2.0 * def_H[i, j] * def_c[i, j] * d * math.exp(-def_c[i, j] * d * d)
    return fs


@_jit
def baoab(aug, xx, uu, XX, ff, g, f0, ia, hU, K, hdt, hdtm, c, sig, dX, i):
    """One BAOAB step; ``ff`` is the total force at the start. Returns the new state,
    the new total force and the recorded force ``K (X - x)``."""
    uu = uu + hdtm * ff
    xx = xx + hdt * uu
    uu = c * uu + sig * g
    xx = xx + hdt * uu
    XX = XX + dX
    fk = K * (XX - xx)
    ff = substrate_force(aug, xx, f0, ia, hU, i) + fk
    uu = uu + hdtm * ff
    return xx, uu, XX, ff, fk


@_jit
def two_steps(aug, a0, a1, xx, uu, XX, ff, f0, ia, hU, K, hdt, hdtm, c, sig, dX, i):
    """Two BAOAB steps sharing one Box-Muller pair; returns the new generator state,
    the new state and the sum of the two recorded forces."""
    ra, rb, a0, a1 = xoroshiro_pair(a0, a1)
    g1, g2 = box_muller(ra, rb)
    xx, uu, XX, ff, fk1 = baoab(aug, xx, uu, XX, ff, g1, f0, ia, hU, K, hdt, hdtm, c, sig, dX, i)
    xx, uu, XX, ff, fk2 = baoab(aug, xx, uu, XX, ff, g2, f0, ia, hU, K, hdt, hdtm, c, sig, dX, i)
    return a0, a1, xx, uu, XX, ff, fk1 + fk2


@nb.njit(cache=True, fastmath=True, parallel=True)
def run_blocks(
    aug, f0, inv_a, K, hdt, hdt_m, c, sig, dX, n_warm, rng0, rng1, half_U0,
    n_pp, n_sub, n_pix, record_fine, out_F, fine_x, fine_F,
):  # fmt: skip
    """Integrate all lanes, ``LANES`` at a time, one block per parallel task."""
    n = f0.size
    n_blocks = (n + LANES - 1) // LANES
    n_ps = n_pp // n_sub
    inv_npp = 1.0 / n_pp
    for b in nb.prange(n_blocks):
        lo = b * LANES
        nl = min(LANES, n - lo)
        # Per-lane copies; lanes past the end repeat the last real lane (discarded).
        idx = np.empty(LANES, np.int64)
        for l in range(LANES):
            idx[l] = lo + min(l, nl - 1)
        Lf0, Lia, LK, LhU = f0[idx], inv_a[idx], K[idx], half_U0[idx]
        Lhdt, Lhdtm, Lc, Lsig, LdX = hdt[idx], hdt_m[idx], c[idx], sig[idx], dX[idx]
        s0, s1 = rng0[idx], rng1[idx]
        warm = n_warm[idx]
        w_max = warm.max()
        # Lanes with a shorter warm-up start later and sit still until then, so a
        # lane's trajectory does not depend on the other lanes of its block.
        start = w_max - warm
        x = np.zeros(LANES)
        u = np.zeros(LANES)
        X = np.zeros(LANES)
        acc = np.zeros(LANES)
        ft = np.zeros(LANES)
        for l in range(LANES):
            ft[l] = substrate_force(aug, 0.0, Lf0[l], Lia[l], LhU[l], idx[l])

        for i2 in range(0, w_max, 2):  # warm-up
            for l in range(LANES):
                a0, a1, xx, uu, XX, ff, _ = two_steps(
                    aug, s0[l], s1[l], x[l], u[l], X[l], ft[l], Lf0[l], Lia[l], LhU[l],
                    LK[l], Lhdt[l], Lhdtm[l], Lc[l], Lsig[l], LdX[l], idx[l],
                )  # fmt: skip
                act = i2 >= start[l]
                s0[l] = a0 if act else s0[l]
                s1[l] = a1 if act else s1[l]
                x[l] = xx if act else x[l]
                u[l] = uu if act else u[l]
                X[l] = XX if act else X[l]
                ft[l] = ff if act else ft[l]

        for p in range(n_pix):  # recording: a pixel is the mean force over its steps
            acc[:] = 0.0
            for sub in range(n_sub):
                for _ in range(n_ps // 2):
                    for l in range(LANES):
                        a0, a1, xx, uu, XX, ff, fsum = two_steps(
                            aug, s0[l], s1[l], x[l], u[l], X[l], ft[l], Lf0[l], Lia[l], LhU[l],
                            LK[l], Lhdt[l], Lhdtm[l], Lc[l], Lsig[l], LdX[l], idx[l],
                        )  # fmt: skip
                        s0[l] = a0
                        s1[l] = a1
                        x[l] = xx
                        u[l] = uu
                        X[l] = XX
                        ft[l] = ff
                        acc[l] += fsum
                if record_fine:
                    for l in range(nl):
                        fine_x[lo + l, p * n_sub + sub] = x[l]
                        fine_F[lo + l, p * n_sub + sub] = LK[l] * (X[l] - x[l])
            for l in range(nl):
                out_F[lo + l, p] = acc[l] * inv_npp


def integrate_numba(lanes: Lanes, record_fine: bool = False):
    """Run the numba kernel on lanes with a common steps-per-pixel.

    Returns
    -------
    force_nN : ndarray (N, pixels)
        Pixel-averaged recorded force ``K (X - x)``.
    fine_x_nm, fine_force_nN : ndarray (N, pixels * samples_per_pixel) or None
        Instantaneous tip position and force at the end of each sub-pixel sample.
    """
    n_pp = np.unique(lanes.steps_per_pixel)
    if n_pp.size != 1:
        raise ValueError("integrate_numba needs a common steps_per_pixel; group lanes first")
    n, n_sub, n_pix = lanes.n, lanes.samples_per_pixel, lanes.pixels
    out = np.zeros((n, n_pix))
    shape = (n, n_pix * n_sub) if record_fine else (1, 1)
    fine_x, fine_F = np.zeros(shape), np.zeros(shape)
    aug = None
    if lanes.augmented:
        mod = np.ascontiguousarray(np.column_stack([lanes.mod_amp, lanes.mod_q, lanes.mod_phase]))
        aug = (mod, lanes.def_x, lanes.def_H, lanes.def_c)
    run_blocks(
        aug, lanes.f0, lanes.inv_a, lanes.K, lanes.hdt, lanes.hdt_m, lanes.c, lanes.sig,
        lanes.dX, lanes.n_warm, lanes.rng0, lanes.rng1, lanes.half_U0,
        int(n_pp[0]), n_sub, n_pix, record_fine, out, fine_x, fine_F,
    )  # fmt: skip
    if record_fine:
        return out, fine_x, fine_F
    return out, None, None
