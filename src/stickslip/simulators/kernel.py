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
from numba import types
from numba.cpython.unsafe.numbers import leading_zeros
from numba.extending import overload

from stickslip.simulators.lanes import MAX_DEFECTS, Lanes

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
_INV_2PI = 1.0 / (2.0 * math.pi)
_E3, _E4, _E5, _E6, _E7, _E8, _E9, _E10, _E11, _E12 = (
    1.0 / math.factorial(k) for k in range(3, 13)
)
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
def exp_neg(z):
    """exp(-z) for 0 <= z <= 40 (no libm): Taylor series at z/64, squared six times."""
    t = -min(z, 40.0) * (1.0 / 64.0)
    p = _E12
    p = p * t + _E11
    p = p * t + _E10
    p = p * t + _E9
    p = p * t + _E8
    p = p * t + _E7
    p = p * t + _E6
    p = p * t + _E5
    p = p * t + _E4
    p = p * t + _E3
    p = p * t + 0.5
    p = p * t + 1.0
    p = p * t + 1.0
    p = p * p
    p = p * p
    p = p * p
    p = p * p
    p = p * p
    return p * p


@_jit
def defect_force(sub, x, l, j):
    """Force of Gaussian defect ``j`` of lane ``l`` (``H exp(-(x-x_j)^2 / (2 w^2))``)."""
    d = x - sub[3 + j, l]
    cj = sub[3 + 2 * MAX_DEFECTS + j, l]
    return 2.0 * sub[3 + MAX_DEFECTS + j, l] * cj * d * exp_neg(cj * d * d)


def local_substrate(aug, idx):
    """Block-local copy of the augmented-substrate parameters (None when plain).

    Rows: amplitude, q [rad/nm], phase / 2 pi, then ``MAX_DEFECTS`` rows each of defect
    positions [nm], heights H [nN nm] and 1/(2 w^2) [1/nm^2]; one column per lane.
    Dispatched on the type of ``aug`` at compile time (see the overload below).
    """
    raise NotImplementedError("numba-only")


def substrate_force(sub, x, f0, inv_a, half_U0, l):
    """-dU/dx of the substrate at tip position ``x`` for lane ``l`` of a block.

    ``sub`` is None for the plain sinusoid, else the block-local array of
    :func:`local_substrate`. The choice is made at compile time from the type of
    ``sub``, so plain runs carry no augmented code, and polynomial sine and exponential
    keep the augmented kernel vectorised too.
    """
    raise NotImplementedError("numba-only")


@overload(local_substrate, inline="always")
def _ov_local_substrate(aug, idx):
    if isinstance(aug, types.NoneType):
        return lambda aug, idx: None

    def impl(aug, idx):
        mod, def_x, def_H, def_c = aug
        out = np.zeros((3 + 3 * MAX_DEFECTS, LANES))
        for l in range(LANES):
            i = idx[l]
            out[0, l] = mod[i, 0]
            out[1, l] = mod[i, 1]
            out[2, l] = mod[i, 2]
            for j in range(MAX_DEFECTS):
                out[3 + j, l] = def_x[i, j]
                out[3 + MAX_DEFECTS + j, l] = def_H[i, j]
                out[3 + 2 * MAX_DEFECTS + j, l] = def_c[i, j]
        return out

    return impl


@overload(substrate_force, inline="always", jit_options={"fastmath": True})
def _ov_substrate_force(sub, x, f0, inv_a, half_U0, l):
    if isinstance(sub, types.NoneType):
        return lambda sub, x, f0, inv_a, half_U0, l: -f0 * sin_2pi(x * inv_a)

    def impl(sub, x, f0, inv_a, half_U0, l):
        t = x * inv_a
        amp, q = sub[0, l], sub[1, l]
        u = q * x * _INV_2PI + sub[2, l]
        s_k, c_k = sin_2pi(t), sin_2pi(t + 0.25)
        fs = -f0 * (1.0 + amp * sin_2pi(u + 0.25)) * s_k
        fd = defect_force(sub, x, l, 0) + defect_force(sub, x, l, 1)
        fd += defect_force(sub, x, l, 2) + defect_force(sub, x, l, 3)
        return fs - half_U0 * amp * q * sin_2pi(u) * c_k + fd

    return impl


@_jit
def baoab(sub, xx, uu, XX, ff, g, f0, ia, hU, K, hdt, hdtm, c, sig, dX, i):
    """One BAOAB step; ``ff`` is the total force at the start. Returns the new state,
    the new total force and the recorded force ``K (X - x)``."""
    uu = uu + hdtm * ff
    xx = xx + hdt * uu
    uu = c * uu + sig * g
    xx = xx + hdt * uu
    XX = XX + dX
    fk = K * (XX - xx)
    ff = substrate_force(sub, xx, f0, ia, hU, i) + fk
    uu = uu + hdtm * ff
    return xx, uu, XX, ff, fk


@_jit
def two_steps(sub, a0, a1, xx, uu, XX, ff, f0, ia, hU, K, hdt, hdtm, c, sig, dX, i):
    """Two BAOAB steps sharing one Box-Muller pair; returns the new generator state,
    the new state and the sum of the two recorded forces."""
    ra, rb, a0, a1 = xoroshiro_pair(a0, a1)
    g1, g2 = box_muller(ra, rb)
    xx, uu, XX, ff, fk1 = baoab(sub, xx, uu, XX, ff, g1, f0, ia, hU, K, hdt, hdtm, c, sig, dX, i)
    xx, uu, XX, ff, fk2 = baoab(sub, xx, uu, XX, ff, g2, f0, ia, hU, K, hdt, hdtm, c, sig, dX, i)
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
        sub = local_substrate(aug, idx)
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
            ft[l] = substrate_force(sub, 0.0, Lf0[l], Lia[l], LhU[l], l)

        for i2 in range(0, w_max, 2):  # warm-up
            for l in range(LANES):
                a0, a1, xx, uu, XX, ff, _ = two_steps(
                    sub, s0[l], s1[l], x[l], u[l], X[l], ft[l], Lf0[l], Lia[l], LhU[l],
                    LK[l], Lhdt[l], Lhdtm[l], Lc[l], Lsig[l], LdX[l], l,
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
            for j_sub in range(n_sub):
                for _ in range(n_ps // 2):
                    for l in range(LANES):
                        a0, a1, xx, uu, XX, ff, fsum = two_steps(
                            sub, s0[l], s1[l], x[l], u[l], X[l], ft[l], Lf0[l], Lia[l], LhU[l],
                            LK[l], Lhdt[l], Lhdtm[l], Lc[l], Lsig[l], LdX[l], l,
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
                        fine_x[lo + l, p * n_sub + j_sub] = x[l]
                        fine_F[lo + l, p * n_sub + j_sub] = LK[l] * (X[l] - x[l])
            for l in range(nl):
                out_F[lo + l, p] = acc[l] * inv_npp


#: The compiled kernels behind :func:`integrate_numba` (:func:`stickslip.compiled.cached`).
KERNELS = (run_blocks,)


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
        mod = np.column_stack([lanes.mod_amp, lanes.mod_q, lanes.mod_phase / (2 * np.pi)])
        pad = ((0, 0), (0, MAX_DEFECTS - lanes.def_x.shape[1]))
        aug = (
            np.ascontiguousarray(mod),
            np.pad(lanes.def_x, pad),
            np.pad(lanes.def_H, pad),  # zero height: padded defects exert no force
            np.pad(lanes.def_c, pad, constant_values=1.0),
        )
    run_blocks(
        aug, lanes.f0, lanes.inv_a, lanes.K, lanes.hdt, lanes.hdt_m, lanes.c, lanes.sig,
        lanes.dX, lanes.n_warm, lanes.rng0, lanes.rng1, lanes.half_U0,
        int(n_pp[0]), n_sub, n_pix, record_fine, out, fine_x, fine_F,
    )  # fmt: skip
    if record_fine:
        return out, fine_x, fine_F
    return out, None, None
