"""CUDA backend: the BAOAB kernel on an NVIDIA GPU (numba.cuda), one thread per trajectory.

Each thread integrates one trajectory with its state in registers and draws from the same
xoroshiro128++ stream as the CPU kernel (:mod:`.kernel`), derived from (seed, index), with
the same Box-Muller pairing (one pair per two steps), the same polynomial sine and
logarithm, and so the same Gaussian numbers. The augmented substrate (barrier modulation
and Gaussian defects) is evaluated on the device, pixels are averaged on the device, and
only the pixels (and, with ``record_fine``, the sub-pixel samples) are copied back.

Positions are kept relative: the tip as (lattice cell, offset in the cell) and the support
relative to the tip's cell origin, recomputed in float64 from the step count at the start
of every pixel (or sub-pixel sample, or warm-up segment) and whenever the tip changes cell.
This is what makes float32 usable: the support moves ~6e-7 nm per step, below float32's
resolution at 11 nm (~1e-6 nm), so an absolute float32 support position would stall.
Pixel sums are accumulated in float64 in both precisions.

Precision. ``float64`` (backend ``cuda``) is the default. It differs from the CPU kernel
only in rounding (relative positions here; on a device also fused multiply-adds). On
numba's CUDA simulator (IEEE arithmetic, no fused multiply-add) its pixels equal the CPU
kernel's to <= 7e-11 nN, at T = 0 and at 296 K alike (same streams, same Gaussian
numbers). On a device the rounding differs slightly (fused multiply-adds), so at finite
T a thermally activated slip may go the other way at some point; from there the traces
agree statistically. Measured on an NVIDIA H100 (``benchmarks/cuda_agreement.py``,
2026-11-26): largest pixel difference from the CPU kernel 8.9e-14 of F_max at T = 0 and
9.7e-14 at 296 K on the short cases of the tests, and 1.7e-6 of F_max on 64 whole
paper-preset lines at 296 K (2e7 steps each), with the same 3,168 slips.

``float32`` (backend ``cuda-float32``) measured against ``float64`` on the CUDA simulator,
same streams, the paper's settings except as stated (``python`` scripts at the level of
``tests/simulators/test_cuda.py``; the simulator is too slow for whole paper lines):

- 6e4 nm/s, 24 pixels of 0.03 nm after the default warm-up, 16 (U0, K) over U0 0.5-4 eV,
  K 2-40 N/m, 1.2 <= eta <= 40: largest pixel difference 1.2e-5 nN (1.9e-6 of F_max) at
  T = 0 and 6.8e-6 nN (2.9e-6 of F_max) at 296 K; mean force per line within 5e-7 nN;
  the same 52 slips.
- 600 nm/s, 0.45 nm from rest, U0/K = 0.5/10 and 2/40: <= 1.2e-6 nN at T = 0 and at 296 K.
- 60 nm/s (the paper's velocity), 0.2 nm from rest through the first slip, U0 = 0.5 eV,
  K = 10 N/m, T = 0: 1.1e-6 nN (1.1e-6 of F_max).

On the H100, the same 64 whole paper-preset lines at 296 K in float32: largest pixel
difference 1.2e-4 of F_max from the CPU kernel (mean force per line within 1.2e-6 of
F_max), the same 3,168 slips; on the short cases 5.9e-7 (T = 0) and 1.5e-6 (296 K).

So float32 is accurate enough wherever ~1e-4 of F_max does not matter: that is below
the thermal spread of a pixel (paper preset, 296 K, 16 trajectories of one (U0, K): median
pixel std 2.3e-3 to 2.9e-3 nN on the CPU kernel) and any detector noise, so it suits
training sets; use float64 where traces are compared one to one with the CPU kernel. The
tests hold float32 to 2e-5 of F_max.

The device code is generated per precision by :func:`_build_kernel` (constants of the
working precision: a bare Python float would silently promote float32 arithmetic to
float64). Under the CUDA simulator (``NUMBA_ENABLE_CUDASIM=1``, used by the tests) the
same code runs as Python, with two differences: device functions are called as plain
functions (the simulator's per-call wrapper costs more than their arithmetic), and the
64-bit count-leading-zeros, which the simulator implements for 32-bit values only, is an
exact Python version.
"""

from __future__ import annotations

import functools
import math
import warnings

import numpy as np

# numba-cuda 0.30.4 (in maintenance, NVIDIA/numba-cuda#907) registers an overload of
# np.row_stack when numba.cuda is first imported, and numpy 2.5 removed that alias: the
# import then fails and no kernel can run. The alias it expects is np.vstack's.
if not hasattr(np, "row_stack"):
    np.row_stack = np.vstack  # noqa: NPY201  (restores the removed alias)

from numba import cuda  # noqa: E402  (after the alias above)
from numba.core import config as numba_config

from stickslip.simulators.config import SettingsError
from stickslip.simulators.lanes import MAX_DEFECTS, Lanes

# the device code writes out four defects per line, as the CPU kernel does
assert MAX_DEFECTS == 4

PRECISIONS = ("float64", "float32")
#: Threads per block: small blocks spread a few thousand trajectories over all SMs.
THREADS_PER_BLOCK = 64

_U1 = np.uint64(1)
_U11, _U15, _U17, _U21 = np.uint64(11), np.uint64(15), np.uint64(17), np.uint64(21)
_U28, _U36, _U40 = np.uint64(28), np.uint64(36), np.uint64(40)
_U47, _U49 = np.uint64(47), np.uint64(49)


class CudaUnavailableError(SettingsError):
    """The CUDA backend was asked for but no usable CUDA device is present."""


def cuda_available() -> bool:
    """True when numba.cuda finds a usable device (or the CUDA simulator is on)."""
    try:
        return bool(cuda.is_available())
    except Exception:  # a broken driver or toolkit counts as no device
        return False


def device_name() -> str:
    """Name of the current CUDA device (``"CUDA simulator"`` under the simulator)."""
    if numba_config.ENABLE_CUDASIM:
        return "CUDA simulator"
    name = cuda.get_current_device().name
    return name.decode() if isinstance(name, bytes) else str(name)


def _clz64_sim(v):
    # the simulator's cuda.clz counts within 32 bits only
    return np.uint64(64 - int(v).bit_length())


@functools.cache
def _build_kernel(precision: str, augmented: bool):
    """The BAOAB kernel for one working precision, plain or augmented substrate."""
    F = np.float64 if precision == "float64" else np.float32
    D = np.float64
    f64 = precision == "float64"
    ZERO, HALF, ONE, TWO = F(0.0), F(0.5), F(1.0), F(2.0)
    QUARTER, FORTY, INV64 = F(0.25), F(40.0), F(1.0 / 64.0)
    TWO_PI, PI, INV_2PI = F(2.0 * math.pi), F(math.pi), F(1.0 / (2.0 * math.pi))
    LN2, SQRT2 = F(math.log(2.0)), F(math.sqrt(2.0))
    S3, S5, S7 = F(-1.0 / 6.0), F(1.0 / 120.0), F(-1.0 / 5040.0)
    S9, S11, S13 = F(1.0 / 362880.0), F(-1.0 / 39916800.0), F(1.0 / 6227020800.0)
    S15 = F(-1.0 / 1307674368000.0)
    L13, L11, L9 = F(1.0 / 13.0), F(1.0 / 11.0), F(1.0 / 9.0)
    L7, L5, L3 = F(1.0 / 7.0), F(1.0 / 5.0), F(1.0 / 3.0)
    E = [F(1.0 / math.factorial(k)) for k in range(3, 13)]
    E3, E4, E5, E6, E7, E8, E9, E10, E11, E12 = E
    # random bits -> mantissa: the top 53 bits in float64, 24 in float32
    M_SHIFT = _U11 if f64 else _U40
    M_SCALE = F(2.0**-52) if f64 else F(2.0**-23)  # normalised bits -> [1, 2)
    T_SCALE = F(2.0**-53) if f64 else F(2.0**-24)  # top bits -> [0, 1)

    if numba_config.ENABLE_CUDASIM:
        # plain calls: the simulator wraps each device-function call in a swap of the
        # module's globals that costs more than the arithmetic
        def device(f):
            return f

        clz64 = _clz64_sim
    else:
        device = cuda.jit(device=True)

        @device
        def clz64(v):
            return cuda.clz(v)

    @device
    def sin_2pi(t):
        r = t - F(math.floor(t + HALF))  # r in [-0.5, 0.5]
        s = TWO_PI * r
        s = max(min(s, PI - s), -PI - s)  # fold to [-pi/2, pi/2]
        s2 = s * s
        p = S15
        p = p * s2 + S13
        p = p * s2 + S11
        p = p * s2 + S9
        p = p * s2 + S7
        p = p * s2 + S5
        p = p * s2 + S3
        return s + s * s2 * p

    @device
    def neg2log_unit(r):
        r = r | _U1
        lz = clz64(r)
        mant = F((r << lz) >> M_SHIFT) * M_SCALE  # in [1, 2)
        big = mant > SQRT2
        m = mant * HALF if big else mant
        e = -(F(lz) + ONE) + (ONE if big else ZERO)
        s = (m - ONE) / (m + ONE)
        s2 = s * s
        p = L13
        p = p * s2 + L11
        p = p * s2 + L9
        p = p * s2 + L7
        p = p * s2 + L5
        p = p * s2 + L3
        p = p * s2 + ONE
        return -TWO * (TWO * s * p + e * LN2)

    @device
    def xoroshiro_pair(a0, a1):
        ra = (((a0 + a1) << _U17) | ((a0 + a1) >> _U47)) + a0
        a1 ^= a0
        a0 = ((a0 << _U49) | (a0 >> _U15)) ^ a1 ^ (a1 << _U21)
        a1 = (a1 << _U28) | (a1 >> _U36)
        rb = (((a0 + a1) << _U17) | ((a0 + a1) >> _U47)) + a0
        a1 ^= a0
        a0 = ((a0 << _U49) | (a0 >> _U15)) ^ a1 ^ (a1 << _U21)
        a1 = (a1 << _U28) | (a1 >> _U36)
        return ra, rb, a0, a1

    @device
    def box_muller(ra, rb):
        rad = F(math.sqrt(neg2log_unit(ra)))
        t = F(rb >> M_SHIFT) * T_SCALE  # in [0, 1)
        return rad * sin_2pi(t), rad * sin_2pi(t + QUARTER)

    @device
    def exp_neg(z):
        t = -min(z, FORTY) * INV64
        p = E12
        p = p * t + E11
        p = p * t + E10
        p = p * t + E9
        p = p * t + E8
        p = p * t + E7
        p = p * t + E6
        p = p * t + E5
        p = p * t + E4
        p = p * t + E3
        p = p * t + HALF
        p = p * t + ONE
        p = p * t + ONE
        p = p * p
        p = p * p
        p = p * p
        p = p * p
        p = p * p
        return p * p

    @device
    def defect(xa, x_j, H_j, c_j):
        d = xa - x_j
        return TWO * H_j * c_j * d * exp_neg(c_j * d * d)

    if augmented:

        @device
        def load_sub(S, i):
            return (
                S[i, 0], S[i, 1], S[i, 2], S[i, 3], S[i, 4], S[i, 5], S[i, 6], S[i, 7],
                S[i, 8], S[i, 9], S[i, 10], S[i, 11], S[i, 12], S[i, 13], S[i, 14],
            )  # fmt: skip

        @device
        def substrate_force(xf, origin, f0, inv_a, hU, sub):
            # -dU/dx; the lattice term from the in-cell offset, the rest from the absolute x
            xa = origin + xf
            amp, q = sub[0], sub[1]
            w = q * xa * INV_2PI + sub[2]
            t = xf * inv_a
            s_k, c_k = sin_2pi(t), sin_2pi(t + QUARTER)
            fs = -f0 * (ONE + amp * sin_2pi(w + QUARTER)) * s_k
            fd = defect(xa, sub[3], sub[7], sub[11]) + defect(xa, sub[4], sub[8], sub[12])
            fd += defect(xa, sub[5], sub[9], sub[13]) + defect(xa, sub[6], sub[10], sub[14])
            return fs - hU * amp * q * sin_2pi(w) * c_k + fd

    else:

        @device
        def load_sub(S, i):
            return (ZERO,)

        @device
        def substrate_force(xf, origin, f0, inv_a, hU, sub):
            return -f0 * sin_2pi(xf * inv_a)

    @device
    def wrap(xf, cell, a_w):
        # keep the tip's offset in [0, a): the step moves the tip far less than a cell
        if xf >= a_w:
            return xf - a_w, cell + 1, True
        if xf < ZERO:
            return xf + a_w, cell - 1, True
        return xf, cell, False

    @device
    def run(n2, k0, s0, s1, xf, uu, ff, cell, sub, p):
        """``2 n2`` BAOAB steps from global step ``k0``; returns the state and the sum of
        the recorded forces ``K (X - x)`` (float64)."""
        f0, ia, hU, K, hdt, hdtm, c, sig, dXw, dX64, a64, a_w = p
        Xb = F(D(k0) * dX64 - D(cell) * a64)  # support at k0, from the cell origin
        origin = F(D(cell) * a64)
        jf = ZERO
        acc = D(0.0)
        for _ in range(n2):
            ra, rb, s0, s1 = xoroshiro_pair(s0, s1)
            g1, g2 = box_muller(ra, rb)
            uu = uu + hdtm * ff
            xf = xf + hdt * uu
            uu = c * uu + sig * g1
            xf = xf + hdt * uu
            jf += ONE
            xf, cell, moved = wrap(xf, cell, a_w)
            if moved:
                Xb = F(D(k0) * dX64 - D(cell) * a64)
                origin = F(D(cell) * a64)
            fk1 = K * (Xb + jf * dXw - xf)
            ff = substrate_force(xf, origin, f0, ia, hU, sub) + fk1
            uu = uu + hdtm * ff
            uu = uu + hdtm * ff
            xf = xf + hdt * uu
            uu = c * uu + sig * g2
            xf = xf + hdt * uu
            jf += ONE
            xf, cell, moved = wrap(xf, cell, a_w)
            if moved:
                Xb = F(D(k0) * dX64 - D(cell) * a64)
                origin = F(D(cell) * a64)
            fk2 = K * (Xb + jf * dXw - xf)
            ff = substrate_force(xf, origin, f0, ia, hU, sub) + fk2
            uu = uu + hdtm * ff
            acc += D(fk1 + fk2)
        return s0, s1, xf, uu, ff, cell, acc

    @cuda.jit
    def kernel(
        f0, inv_a, K, hdt, hdt_m, c, sig, dXw, half_U0, a_w, dX64, a64, n_warm, rng0, rng1,
        S, n_pp, n_sub, n_pix, record_fine, out_F, fine_x, fine_F,
    ):  # fmt: skip
        i = cuda.grid(1)
        if i >= out_F.shape[0]:
            return
        p = (
            f0[i], inv_a[i], half_U0[i], K[i], hdt[i], hdt_m[i], c[i], sig[i], dXw[i],
            dX64[i], a64[i], a_w[i],
        )  # fmt: skip
        sub = load_sub(S, i)
        s0, s1 = rng0[i], rng1[i]
        xf = ZERO
        uu = ZERO
        cell = 0
        ff = substrate_force(ZERO, ZERO, p[0], p[1], p[2], sub)
        nw = n_warm[i]
        k = 0
        while k < nw:  # warm-up, in segments so the support offset is refreshed
            n2 = min(n_pp, nw - k) // 2
            s0, s1, xf, uu, ff, cell, _ = run(n2, k, s0, s1, xf, uu, ff, cell, sub, p)
            k += 2 * n2
        n2 = n_pp // n_sub // 2
        inv_npp = 1.0 / n_pp
        for px in range(n_pix):  # a pixel is the mean force over its steps
            acc = D(0.0)
            for j in range(n_sub):
                s0, s1, xf, uu, ff, cell, a_ = run(n2, k, s0, s1, xf, uu, ff, cell, sub, p)
                k += 2 * n2
                acc += a_
                if record_fine:
                    x_abs = D(cell) * a64[i] + D(xf)
                    fine_x[i, px * n_sub + j] = x_abs
                    fine_F[i, px * n_sub + j] = D(K[i]) * (D(k) * dX64[i] - x_abs)
            out_F[i, px] = acc * inv_npp

    return kernel


def _blocks(n: int) -> tuple[int, int]:
    tpb = THREADS_PER_BLOCK
    return (n + tpb - 1) // tpb, tpb


def integrate_cuda(
    lanes: Lanes, record_fine: bool = False, precision: str = "float64"
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """Run the CUDA kernel on lanes with a common steps-per-pixel.

    Parameters
    ----------
    lanes : Lanes
        Trajectories to integrate (one common ``steps_per_pixel``).
    record_fine : bool
        Also return the instantaneous tip position and force at the end of each
        sub-pixel sample.
    precision : {"float64", "float32"}
        Working precision of the integrator (pixel sums are float64 in both).

    Returns
    -------
    force_nN : ndarray (N, pixels)
        Pixel-averaged recorded force ``K (X - x)``.
    fine_x_nm, fine_force_nN : ndarray (N, pixels * samples_per_pixel) or None
        Tip position and force at the end of each sub-pixel sample.

    Raises
    ------
    CudaUnavailableError
        No CUDA device is present.
    """
    if precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {PRECISIONS} (got '{precision}')")
    if not cuda_available():
        raise CudaUnavailableError(
            "no CUDA device found (backend 'cuda' needs an NVIDIA GPU with its driver and "
            "pip install 'stickslip[gpu]'; use backend 'cpu' or 'auto')"
        )
    n_pp = np.unique(lanes.steps_per_pixel)
    if n_pp.size != 1:
        raise ValueError("integrate_cuda needs a common steps_per_pixel; group lanes first")
    n, n_sub, n_pix = lanes.n, lanes.samples_per_pixel, lanes.pixels
    F = np.dtype(precision)
    a = 1.0 / lanes.inv_a
    a_w = a.astype(F)  # the cell width in the working precision ...
    a64 = a_w.astype(np.float64)  # ... so cell bookkeeping and wrapping agree exactly
    if lanes.augmented:
        pad = ((0, 0), (0, MAX_DEFECTS - lanes.def_x.shape[1]))
        S = np.column_stack([
            lanes.mod_amp, lanes.mod_q, lanes.mod_phase / (2 * np.pi),
            np.pad(lanes.def_x, pad), np.pad(lanes.def_H, pad),  # height 0: no force
            np.pad(lanes.def_c, pad, constant_values=1.0),
        ]).astype(F)  # fmt: skip
    else:
        S = np.zeros((1, 1), F)
    kernel = _build_kernel(precision, lanes.augmented)

    def dev(x, dtype):
        return cuda.to_device(np.ascontiguousarray(x, dtype=dtype))

    shape = (n, n_pix * n_sub) if record_fine else (1, 1)
    out_F = cuda.device_array((n, n_pix), np.float64)
    fine_x = cuda.device_array(shape, np.float64)
    fine_F = cuda.device_array(shape, np.float64)
    grid, tpb = _blocks(n)
    with warnings.catch_warnings():
        if numba_config.ENABLE_CUDASIM:  # numpy warns on the generator's wrapping uint64 adds
            warnings.filterwarnings("ignore", "overflow encountered", RuntimeWarning)
        kernel[grid, tpb](
            dev(lanes.f0, F), dev(lanes.inv_a, F), dev(lanes.K, F), dev(lanes.hdt, F),
            dev(lanes.hdt_m, F), dev(lanes.c, F), dev(lanes.sig, F), dev(lanes.dX, F),
            dev(lanes.half_U0, F), dev(a_w, F), dev(lanes.dX, np.float64), dev(a64, np.float64),
            dev(lanes.n_warm, np.int64), dev(lanes.rng0, np.uint64), dev(lanes.rng1, np.uint64),
            dev(S, F), int(n_pp[0]), int(n_sub), int(n_pix), bool(record_fine),
            out_F, fine_x, fine_F,
        )  # fmt: skip
    force = out_F.copy_to_host()
    if record_fine:
        return force, fine_x.copy_to_host(), fine_F.copy_to_host()
    return force, None, None
