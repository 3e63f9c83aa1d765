"""Soft contacts on coarse pixels: the line model's K and U0 by true stiffness and pixel.

Why: a line that says little about K (coarse pixels, noise) leaves the network to fall
back on what it learned from its training prior, and the bundled model reads soft
contacts on coarse scans too stiff. This benchmark measures that bias, per level of
pixel coarseness and per band of the true K, for any line model, so that two models
(or two priors: ``scripts/train_line_model.py --log-fraction``) are compared on the
same lines.

How the set is made: by ``benchmarks/acquisition.py``'s own generator (its ``Draw``:
U0 log-uniform 0.3-5 eV, K log-uniform 2-50 N/m, eta 2-35, lattice 0.24-0.33 nm, white
noise 0-0.05 nN; every other factor at the paper preset), not by the training's
sampling code, on seed 48117 (the documented set; ``--seed`` draws another). Seed 48101
drew the development set: a mean correction for coarse pixels was fitted and judged on
it (docs/explanation/learned-model.md, "Alternatives considered"), so its figures are a
tuning set's. Three levels, 128 lines each:

- ``512 px 11 nm``: the reference pixel (about 1x once mapped);
- ``512 px 22 nm``: pixels 2x the reference's (1.6-2x once the lattice is mapped);
- ``384 px 25 nm``: pixels 3x the reference's (2.3-3.1x once mapped).

Each pixel is the mean force over its travel, as the simulator records it. The set is
cached in ``--cache`` (default build/soft_contacts/). Scored through
``stickslip.predict`` as a user calls it, every condition stated right.

Printed per level and per bin of true K (2-5, 5-10, 10-20, 20-50 N/m): lines answered,
the median relative bias and the relative RMSE of K and U0, and the 95 % coverage
(``nan`` for an estimator without intervals: ``--model classical`` scores the classical
estimator on the same lines).

Usage: python benchmarks/soft_contacts.py [--model PATH|classical] [--json OUT] [--seed N]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from _machine import machine_line
from acquisition import Draw, Level, SetSpec, cached_set, group_metrics, predict_set

from stickslip.atomic import write_text_atomic

ROOT = Path(__file__).resolve().parents[1]
SEED = 48117
K_BINS = ((2.0, 5.0), (5.0, 10.0), (10.0, 20.0), (20.0, 50.0))
LEVELS = tuple(Level(f"{p} px {length:g} nm", 128, {"pixels": p, "length_nm": length})
               for p, length in ((512, 11.0), (512, 22.0), (384, 25.0)))  # fmt: skip


def set_spec(seed: int = SEED) -> SetSpec:
    """The soft-contact set drawn on ``seed`` (cached as ``soft_<seed>.h5``)."""
    return SetSpec(f"soft_{seed}", seed, LEVELS)



def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", default=None,
                    help="a line model file, or 'classical' (default: the bundled line model)")
    ap.add_argument("--cache", type=Path, default=ROOT / "build" / "soft_contacts")
    ap.add_argument("--json", type=Path, default=None, help="write the figures here")
    ap.add_argument("--seed", type=int, default=SEED,
                    help=f"draw the set on this seed (default {SEED})")
    args = ap.parse_args()
    spec = set_spec(args.seed)

    machine = machine_line()
    print(machine)
    ls = cached_set(spec, Draw(), args.cache)
    rows, truth, seconds = predict_set(ls, args.model)
    p = ls.params
    print(f"model: {args.model or 'bundled'}; {len(rows)} lines read in {seconds:.1f} s")
    print(f"{'level':14s} {'K bin':>8s} {'n':>4s} {'answ':>5s} | {'K bias':>7s} {'K rRMSE':>7s} "
          f"{'K cov':>5s} | {'U0 bias':>7s} {'U0 rRMSE':>8s} {'U0 cov':>6s}")  # fmt: skip
    out: dict[str, dict[str, dict]] = {}
    for j, lv in enumerate(spec.levels):
        out[lv.label] = {}
        bins = [(f"{lo:g}-{hi:g}", (p["K_N_m"] >= lo) & (p["K_N_m"] < hi)) for lo, hi in K_BINS]
        for name, in_bin in [*bins, ("all", np.ones(spec.n, bool))]:
            mask = (p["level"] == j) & in_bin
            g = group_metrics(rows, truth, mask)
            out[lv.label][name] = g
            k, u = g["answered"]["K_N_m"], g["answered"]["U0_eV"]
            answered = (g["lines"] - g["refused"]) / max(g["lines"], 1)
            print(f"{lv.label:14s} {name:>8s} {g['lines']:4d} {answered:5.2f} | "
                  f"{k.get('bias_median', np.nan):+7.3f} {k.get('rel_rmse', np.nan):7.3f} "
                  f"{k.get('coverage95', np.nan):5.2f} | {u.get('bias_median', np.nan):+7.3f} "
                  f"{u.get('rel_rmse', np.nan):8.3f} "
                  f"{u.get('coverage95', np.nan):6.2f}")  # fmt: skip
    if args.json:
        doc = {"command": "python benchmarks/soft_contacts.py"
                          + (f" --model {args.model}" if args.model else "")
                          + (f" --seed {args.seed}" if args.seed != SEED else ""),
               "machine": machine, "seed": args.seed, "model": args.model or "bundled",
               "seconds": seconds, "levels": out}  # fmt: skip
        write_text_atomic(args.json, json.dumps(doc, indent=1, default=float))


if __name__ == "__main__":
    main()
