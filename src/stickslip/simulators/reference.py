"""Plain-numpy BAOAB integrator, kept for tests only.

Same algorithm and step layout as the numba kernel, written for clarity (vectorised over
trajectories, libm functions, numpy's Generator for the noise). It agrees with the kernel
statistically, not bit for bit: the random streams differ.
"""

from __future__ import annotations

import numpy as np

from stickslip.simulators.lanes import Lanes


def substrate_force(x: np.ndarray, lanes: Lanes) -> np.ndarray:
    """-dU/dx of the (possibly augmented) substrate, nN."""
    kx = 2.0 * np.pi * x * lanes.inv_a
    qx = lanes.mod_q * x + lanes.mod_phase
    f = -lanes.f0 * (1.0 + lanes.mod_amp * np.cos(qx)) * np.sin(kx)
    f -= lanes.half_U0 * lanes.mod_amp * lanes.mod_q * np.sin(qx) * np.cos(kx)
    d = x[:, None] - lanes.def_x
    f += np.sum(2.0 * lanes.def_H * lanes.def_c * d * np.exp(-lanes.def_c * d * d), axis=1)
    return f


def integrate_reference(lanes: Lanes, seed: int = 0, record_fine: bool = False):
    """Integrate all lanes with numpy; same outputs as :func:`integrate_numba`."""
    n_pp = np.unique(lanes.steps_per_pixel)
    if n_pp.size != 1:
        raise ValueError("integrate_reference needs a common steps_per_pixel")
    n_pp = int(n_pp[0])
    rng = np.random.default_rng(seed)
    n, n_sub, n_pix = lanes.n, lanes.samples_per_pixel, lanes.pixels
    n_ps = n_pp // n_sub
    x, u, X = np.zeros(n), np.zeros(n), np.zeros(n)
    ff = substrate_force(x, lanes)

    def step(active: np.ndarray | None = None):
        nonlocal x, u, X, ff
        g = rng.standard_normal(n)
        uu = u + lanes.hdt_m * ff
        xx = x + lanes.hdt * uu
        uu = lanes.c * uu + lanes.sig * g
        xx = xx + lanes.hdt * uu
        XX = X + lanes.dX
        fk = lanes.K * (XX - xx)
        f_new = substrate_force(xx, lanes) + fk
        uu = uu + lanes.hdt_m * f_new
        if active is None:
            x, u, X, ff = xx, uu, XX, f_new
        else:
            x, u, X = np.where(active, xx, x), np.where(active, uu, u), np.where(active, XX, X)
            ff = np.where(active, f_new, ff)
        return fk

    w_max = int(lanes.n_warm.max())
    start = w_max - lanes.n_warm
    for i in range(w_max):
        step(i >= start)
    out = np.zeros((n, n_pix))
    fine_x = np.zeros((n, n_pix * n_sub)) if record_fine else None
    fine_F = np.zeros((n, n_pix * n_sub)) if record_fine else None
    for p in range(n_pix):
        acc = np.zeros(n)
        for s in range(n_sub):
            for _ in range(n_ps):
                acc += step()
            if record_fine:
                fine_x[:, p * n_sub + s] = x
                fine_F[:, p * n_sub + s] = lanes.K * (X - x)
        out[:, p] = acc / n_pp
    return out, fine_x, fine_F
