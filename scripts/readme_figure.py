"""The README's picture: a simulated friction map beside the U0 and K of its lines.

A 40-line map (paper preset, 296 K, 512 px over 11 nm, white noise 0.02 nN) whose upper
half has a higher barrier (a domain of U0 1.6 eV against 1.0 eV, K 10 N/m throughout),
estimated line by line with the bundled line model; the panels show the friction image
and each line's U0 and K with its 95 % interval.

    python scripts/readme_figure.py [--out docs/images/friction_map.png]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from stickslip.estimators.load import load_estimator  # noqa: E402
from stickslip.simulators.config import PhysicalSettings  # noqa: E402
from stickslip.simulators.simulate import simulate  # noqa: E402
from stickslip.traces.trace import Trace  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SEED = 4601  # used nowhere else
N_LINES = 40


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "images" / "friction_map.png")
    args = ap.parse_args()
    U0 = np.where(np.arange(N_LINES) < N_LINES // 2, 1.0, 1.6)
    K = np.full(N_LINES, 10.0)
    r = simulate(U0, K, PhysicalSettings(), seed=SEED)
    F = r.force_nN + np.random.default_rng(SEED).normal(0.0, 0.02, r.force_nN.shape)
    traces = [Trace(x_nm=r.x_nm, force_nN=F[i], name=f"line {i}") for i in range(N_LINES)]
    rows = load_estimator(None).predict(traces).rows
    fig, ax = plt.subplots(1, 3, figsize=(10, 3.6), gridspec_kw={"width_ratios": [3, 1, 1]},
                           sharey=True)  # fmt: skip
    im = ax[0].imshow(F, aspect="auto", origin="lower", cmap="magma",
                      extent=(r.x_nm[0], r.x_nm[-1], -0.5, N_LINES - 0.5))  # fmt: skip
    fig.colorbar(im, ax=ax[0], label="lateral force (nN)")
    ax[0].set_xlabel("x (nm)")
    ax[0].set_ylabel("scan line")
    ax[0].set_title("friction map (simulated)")
    lines = np.arange(N_LINES)
    for a, key, truth, unit in ((ax[1], "U0_eV", U0, "eV"), (ax[2], "K_N_m", K, "N/m")):
        v = np.array([row[key] for row in rows], float)
        lo = np.array([row[f"{key}_lo95"] for row in rows], float)
        hi = np.array([row[f"{key}_hi95"] for row in rows], float)
        a.errorbar(v, lines, xerr=[v - lo, hi - v], fmt="o", ms=3, lw=0.8, label="estimate, 95 %")
        a.plot(truth, lines, "k--", lw=1, label="truth")
        a.set_xlabel(f"{key.split('_')[0]} ({unit})")
        a.set_title(f"{key.split('_')[0]} per line")
    ax[1].legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=90)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
