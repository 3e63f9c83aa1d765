"""How the line model reads an offset of the force's zero: as a change of the barrier.

A constant offset of the lateral signal (topography crosstalk, a detector offset) that
does not reverse with the scan is, on one line, indistinguishable from friction
(PHYSICS.md). This benchmark measures what it does to the bundled line model's U0 and
K: clean finite-temperature PT lines at the paper preset (graphite, 11 nm as 512 px,
60 nm/s, 296 K; eta 2-30 drawn by ``sample_parameters``, seed ``--seed``, default 47101,
used by nothing else), each estimated as simulated and with offsets of -0.4 to +0.4 nN
added. Printed per offset: the median change of ln U0 and of ln K, each also over
``o / F_max`` (``F_max = pi U0 / a``, the truth's largest force), and the share in
domain.

Then, for the lines as simulated, the single-line 95 % half-width of ln U0 against the
half-width the documented offset prior alone asks for at each line's estimated
``F_max`` (:class:`stickslip.estimators.offsets.OffsetPrior` from the crosstalk family:
the 95 % quantile of ``|o|`` over ``F_max``): the part of a single line's U0 interval
that is the offset's, which the trace/retrace pair and the per-map pooling cancel and
no single line can.

    python benchmarks/offset_response.py [--n 64] [--seed 47101]
"""

from __future__ import annotations

import argparse

import numpy as np
from _machine import machine_line

from stickslip.estimators.load import load_estimator
from stickslip.estimators.offsets import OffsetPrior
from stickslip.simulators import PhysicalSettings, simulate
from stickslip.simulators import effects as fx
from stickslip.simulators.config import ParameterRange
from stickslip.simulators.sampling import sample_parameters
from stickslip.traces.trace import Trace
from stickslip.units import fmax_nN

OFFSETS_NN = (-0.4, -0.2, -0.1, 0.1, 0.2, 0.4)


def offset_quantile(prior: OffsetPrior, level: float = 0.95) -> float:
    """The ``level`` quantile of ``|o|`` under ``prior`` (none with probability ``1 - p``,
    else uniform in ``mean_nN``), nN."""
    lo, hi = prior.mean_nN
    tail = (1.0 - level) / prior.p  # P(|o| > x) = p (hi - x) / (hi - lo)
    return hi - tail * (hi - lo) if tail < 1.0 else 0.0


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--n", type=int, default=64, help="lines")
    ap.add_argument("--seed", type=int, default=47101)
    args = ap.parse_args()
    print(machine_line())
    s = PhysicalSettings()
    a = s.lattice_nm
    U0, K = sample_parameters(ParameterRange(eta=(2.0, 30.0)), args.n, args.seed, a)
    force = simulate(U0, K, s, seed=args.seed).force_nN
    x = (np.arange(force.shape[1]) + 0.5) * s.pixel_nm
    est = load_estimator(None)
    meta = {"lattice_nm": a, "velocity_nm_per_s": s.velocity_nm_per_s,
            "temperature_K": s.temperature_K}  # fmt: skip

    def rows(offset: float) -> list[dict]:
        traces = [Trace(x, f + offset, f"line{i}", "sim", meta) for i, f in enumerate(force)]
        return est.predict(traces).rows

    def col(rs: list[dict], key: str) -> np.ndarray:
        return np.array([r.get(key, np.nan) for r in rs], float)

    base = rows(0.0)
    fmax = fmax_nN(U0, a)
    print(f"{args.n} clean lines (paper preset, eta 2-30, seed {args.seed}); F_max "
          f"{np.min(fmax):.2f}-{np.max(fmax):.2f} nN (median {np.median(fmax):.2f})")
    print(f"{'offset nN':>9} | {'d ln U0':>8} {'/(o/F_max)':>10} | {'d ln K':>8} "
          f"{'/(o/F_max)':>10} | in domain")  # fmt: skip
    for o in OFFSETS_NN:
        r = rows(o)
        dU = np.log(col(r, "U0_eV") / col(base, "U0_eV"))
        dK = np.log(col(r, "K_N_m") / col(base, "K_N_m"))
        share = o / fmax
        print(f"{o:+9.1f} | {np.nanmedian(dU):+8.3f} {np.nanmedian(dU / share):+10.2f} | "
              f"{np.nanmedian(dK):+8.3f} {np.nanmedian(dK / share):+10.2f} | "
              f"{np.mean([bool(v.get('in_domain')) for v in r]):.2f}")  # fmt: skip
    prior = OffsetPrior.from_family(fx.Crosstalk())
    q = offset_quantile(prior)
    fmax_hat = fmax_nN(col(base, "U0_eV"), a)
    half = 0.5 * np.log(col(base, "U0_eV_hi95") / col(base, "U0_eV_lo95"))
    need = np.log1p(q / fmax_hat)
    err = np.abs(np.log(col(base, "U0_eV") / U0))
    print(f"\nthe lines as simulated: ln U0 error median {np.nanmedian(err):.4f}; 95 % "
          f"half-width median {np.nanmedian(half):.3f}; the offset prior alone (p = "
          f"{prior.p:g}, |o| {prior.mean_nN[0]:g}-{prior.mean_nN[1]:g} nN: 95 % quantile "
          f"{q:.3f} nN) over each line's estimated F_max asks for {np.nanmedian(need):.3f} "
          f"(median); the half-width is below that on {np.nanmean(half < need):.2f} of "
          "the lines")  # fmt: skip


if __name__ == "__main__":
    main()
