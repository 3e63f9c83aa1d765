"""What sets the width of a single line's U0 interval: the calibration lines' errors.

The bundled line model's intervals are calibrated on the lines of
:func:`stickslip.estimators.line.families.family_calibration_lines` (the
calibration pool of ``benchmarks/families.py``: 600 clean trajectories of the training
prior, seed 501, with the multi-asperity contact lines that one PT describes; four
draws of the nuisance prior, ``"train"`` implementations, each line's offset restated
from the documented offset prior; four draws of the members' own training effects).
This benchmark reads the same lines with the bundled model and prints:

- the |error| of ln U0 (median and 95 % quantile) over all lines, over the training-effect
  lines, over the prior's lines that carry no family, and with and without each family,
  each with the median half-width the first interval below gives those lines;
- two ways to size the 95 % interval, fitted on the lines of even trajectories and
  scored on the odd ones (coverage, median half-width, mean interval score; overall, on
  lines without an offset, and per third of the line's estimated ``F_max = pi U0 / a``):
  one power law of the ensemble's spread on the whole error (the shape the bundled
  calibration has, in one class), and a power law on the error less the line's offset
  (``ln(1 + o / F_max)``, what the members read the offset as:
  ``benchmarks/offset_response.py``) with the documented offset prior added over each
  line's estimated ``F_max`` (the way <F>'s interval carries its offset).

The pools are the ones ``benchmarks/families.py`` caches under ``--work`` (simulated
here where missing). Nothing here is fitted into the model; it is a diagnostic.

    python benchmarks/u0_width.py [--work build/families]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch
from _machine import machine_line

from stickslip.diagnostics.metrics import interval_score
from stickslip.estimators.line.ensemble import predict_std_lines
from stickslip.estimators.line.families import (
    FamilyCalibration,
    contact_lines,
    family_calibration_lines,
)
from stickslip.estimators.line.modelfile import load_line_model
from stickslip.estimators.line.training import power_fit
from stickslip.estimators.offsets import friction_bounds
from stickslip.jobs.train import BundledRecipe
from stickslip.simulators import effects as fx
from stickslip.simulators.randomised import RandomisedConfig, cached_randomised_set
from stickslip.units import fmax_nN

ROOT = Path(__file__).resolve().parents[1]
Z95 = 1.959964
#: the calibration pool of benchmarks/families.py
CAL_N, CAL_SEED, CONTACTS = 600, 501, 640


def _scores(err: np.ndarray, half: np.ndarray) -> str:
    """Coverage, median half-width and mean interval score (alpha 0.05), log units."""
    score = interval_score(err, -half, half, 0.05)
    return (f"coverage {np.mean(np.abs(err) <= half):.3f}, half-width {np.median(half):.3f}, "
            f"interval score {np.mean(score):.3f} ({err.size} lines)")


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--work", type=Path, default=ROOT / "build" / "families")
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    print(machine_line())
    args.work.mkdir(parents=True, exist_ok=True)
    ens = load_line_model(None)
    settings = FamilyCalibration(contacts=CONTACTS)
    pool = cached_randomised_set(BundledRecipe().prior(RandomisedConfig(n=CAL_N, seed=CAL_SEED)),
                                 args.work)  # fmt: skip
    parts = family_calibration_lines(ens, pool, settings, contact_lines(settings, args.work))
    lines, mild = parts.prior, parts.training
    j = 1  # ln U0 (in the mapped frame; differences are ln U0's)
    err, sd = [], []
    for cs, Y in ((parts.prior_set, parts.prior_Y), (parts.training_set, parts.training_Y)):
        mu, s = predict_std_lines(ens, cs.lines, cs.C)
        err.append(mu[:, j] * float(ens.y_std[j]) + float(ens.y_mean[j]) - Y[:, j])
        sd.append(s[:, j] * float(ens.y_std[j]))
    e, s = np.concatenate(err), np.concatenate(sd)
    n_prior = lines.data.n
    traj = np.concatenate([lines.rows, mild.rows])
    offset = np.concatenate([np.asarray(lines.data.params["offset_nN"], float),
                             np.zeros(mild.data.n)])  # fmt: skip
    p = {k: np.concatenate([lines.data.params[k], mild.data.params[k]])
         for k in ("U0_eV", "lattice_nm")}  # fmt: skip
    fmax = fmax_nN(p["U0_eV"], p["lattice_nm"])
    fmax_hat = fmax * np.exp(e)
    applied = np.vstack([lines.applied, np.zeros((mild.data.n, lines.applied.shape[1]), bool)])
    a = np.abs(e)
    prior_rows = np.arange(a.size) < n_prior

    fit, test = traj % 2 == 0, traj % 2 == 1
    w = np.ones(int(fit.sum()))
    scale, power = power_fit(a[fit, None], s[fit, None], w)
    one = Z95 * scale[0] * s ** power[0]

    def q(m: np.ndarray) -> str:
        return (f"{np.median(a[m]):.3f} / {np.quantile(a[m], 0.95):.3f}, 95 % half-width "
                f"{np.median(one[m]):.3f}")  # fmt: skip

    print(f"\n{a.size} calibration lines ({n_prior} of the nuisance prior, offsets on "
          f"{np.mean(offset != 0):.2f} of all; {mild.data.n} with the members' training "
          f"effects); |error| of ln U0, median / 95 % quantile, and the median 95 % half-width of "
          "one power law of the spread (below):")  # fmt: skip
    print(f"  all {q(np.ones(a.size, bool))}; training-effect lines {q(~prior_rows)}; prior "
          f"lines without any family {q(prior_rows & ~applied.any(axis=1))}")  # fmt: skip
    for k, f in enumerate(fx.FAMILIES):
        m = applied[:, k]
        if m.any():
            print(f"  {f:18s} with {q(m)} ({m.sum()} lines); prior lines without it "
                  f"{q(prior_rows & ~m)}")  # fmt: skip
    shown = np.abs(e - np.log1p(np.clip(offset / fmax, -0.9, None)))
    scale, power = power_fit(shown[fit, None], s[fit, None], w)
    model = Z95 * scale[0] * s ** power[0]
    _, hi = friction_bounds(model * fmax_hat, 0.95, settings.offset)
    with_offset = hi / fmax_hat
    edges = np.quantile(fmax_hat[test], [1 / 3, 2 / 3])
    print(f"\n95 % interval of ln U0, fitted on even trajectories, scored on the "
          f"{int(test.sum())} lines of odd ones: coverage, median half-width, mean interval "
          "score")  # fmt: skip
    for name, half in (("one power law of the spread", one),
                       ("model part + offset prior over F_max", with_offset)):  # fmt: skip
        none = test & (offset == 0)
        cells = [f"all: {_scores(e[test], half[test])}",
                 f"without an offset: {_scores(e[none], half[none])}"]
        for lo, hi_ in ((0.0, edges[0]), (edges[0], edges[1]), (edges[1], np.inf)):
            m = test & (fmax_hat >= lo) & (fmax_hat < hi_)
            cells.append(f"F_max {lo:.1f}-{hi_:.1f} nN: {_scores(e[m], half[m])}")
        print(f"  {name}:")
        for c in cells:
            print(f"    {c}")


if __name__ == "__main__":
    main()
