"""Train the bundled whole-line model (CNN ensemble with uncertainty), reproducibly.

1. Simulates domain-randomised training sets, one per seed (stickslip.simulators.randomised:
   lattices 0.235-0.335 nm with 30 % exactly on graphite's, 30-90 nm/s, modulated and
   defective substrates), cached under --work (a cached file is reused only if its
   stored config is the one asked for); --typical trajectories on a typical careful
   measurement's substrate (randomised.lab_config: the same parameters, lattices and
   velocities, milder modulation and defects; seed --typical-seed); and --paper clean
   paper-preset trajectories (graphite lattice, 60 nm/s, flat substrate: the expert's
   own conditions, so the members learn how far to trust it there and how small their
   spread can be; seed --paper-seed, apart from the expert's and the benchmarks' seeds).
2. Trains the ensemble with on-the-fly detector effects (and, on a --families fraction of
   the non-pristine lines, default 0.5, a draw of the effect families) and calibrates its
   spread on a held-out split. The effects' prior (line_training.training_effects) gives a
   --typical-fraction of lines a typical careful measurement's effects (instrument.LAB)
   and the rest the broad ranges (line_training.TRAIN_EFFECTS). The members read an
   expert input and learn when to trust it (stickslip.estimators.line.ensemble): by default the
   paper's pi MLP trained on clean paper-preset simulations (the bundled window model's
   data and recipe, without its noise augmentation: the most precise expert on a clean
   line, and plainly wrong on a noisy one), trained here and cached; --expert bundled
   reads the bundled window model, --expert none trains without.
3. Saves it to src/stickslip/resources/line_model.pt (or --out). The bundled file is then
   calibrated on the effect families (benchmarks/families.py --write) and its domain
   reference refitted (benchmarks/domain.py --write-reference): ``make line-model``.

A thin wrapper over :mod:`stickslip.jobs.train` (``bundled_line_data``, ``expert_model``,
``train_line``): with its defaults it trains what
``stickslip train --kind line --recipe bundled --expert clean --seed 102 --out M.pt``
trains; the flags here also vary the recipe's data and the training settings the
command line leaves at their defaults.

--recalibrate MODEL skips step 2's training: it re-fits only the spread calibration of
MODEL (trained by this script with the same arguments, the calibration's own settings
--calibration-draws and --spread-power aside) on the same validation trajectories.

Usage: python scripts/train_line_model.py [--n 4000] [--seeds 102 103 105] [--typical 1500]
       [--typical-seed 104] [--log-fraction 0] [--typical-fraction 0.8] [--paper 1500]
       [--paper-seed 5]
       [--members 3] [--epochs 45] [--expert clean|bundled|none|PATH]
       [--spread-hidden 128] [--calibration-draws 8] [--no-spread-power] [--families 0.5]
       [--work build/line-train] [--out PATH] [--recalibrate MODEL]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from stickslip.estimators.line.modelfile import line_metadata, load_line_model, save_line_model
from stickslip.estimators.line.training import (
    CALIBRATION_FIELDS,
    TYPICAL_FRACTION,
    LineTrainConfig,
    family_settings,
    recalibrate_line_ensemble,
    training_effects,
)
from stickslip.jobs.train import (
    BundledRecipe,
    TrainingDataError,
    bundled_line_data,
    expert_model,
    train_line,
)

ROOT = Path(__file__).resolve().parents[1]
RECIPE = BundledRecipe()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=RECIPE.n)
    ap.add_argument("--seeds", type=int, nargs="+", default=list(RECIPE.seeds))
    ap.add_argument("--paper", type=int, default=RECIPE.paper,
                    help="clean paper-preset trajectories added to the training data")
    ap.add_argument("--paper-seed", type=int, default=RECIPE.paper_seed)
    ap.add_argument("--typical", type=int, default=RECIPE.typical,
                    help="trajectories on a typical measurement's substrate (lab_config) added")
    ap.add_argument("--typical-seed", type=int, default=RECIPE.typical_seed)
    ap.add_argument("--log-fraction", type=float, default=RECIPE.log_fraction,
                    help="share of the randomised and typical trajectories whose U0 and K "
                         "are drawn log-uniform (the rest uniform, as in the paper)")  # fmt: skip
    ap.add_argument("--typical-fraction", type=float, default=TYPICAL_FRACTION,
                    help="fraction of lines given a typical instrument's detector effects")
    ap.add_argument("--members", type=int, default=LineTrainConfig.members)
    ap.add_argument("--epochs", type=int, default=LineTrainConfig.epochs)
    ap.add_argument("--beta", type=float, default=LineTrainConfig.beta,
                    help="beta-NLL weight of the means' gradient")
    ap.add_argument("--beta-var", type=float, default=LineTrainConfig.beta_var,
                    help="beta-NLL weight of the variances' gradient")
    ap.add_argument("--spread-hidden", type=int, default=LineTrainConfig.spread_hidden,
                    help="width of a spread head of its own (0: rows of the means' head)")
    ap.add_argument("--calibration-draws", type=int, default=LineTrainConfig.calibration_draws,
                    help="draws of the detector effects on the validation lines to calibrate on")
    ap.add_argument("--spread-power", action=argparse.BooleanOptionalAction,
                    default=LineTrainConfig.spread_power,
                    help="calibrated std c * sd**gamma per class (--no-spread-power: gamma 1)")
    ap.add_argument("--families", type=float, default=0.5, metavar="FRACTION",
                    help="put the effect families (the broad nuisance prior, 'train' "
                         "implementations) on this fraction of the non-pristine training "
                         "lines (0: none)")  # fmt: skip
    ap.add_argument("--coarse", type=float, default=RECIPE.coarse_fraction, metavar="FRACTION",
                    help="re-pixelate this fraction of the lines coarser (1-4x the "
                         "simulated pixel), as larger detector pixels record them")  # fmt: skip
    ap.add_argument("--expert", default="clean",
                    help="window model read as expert input: clean, bundled, none, or a file")
    ap.add_argument("--recalibrate", type=Path, default=None,
                    help="re-fit only the spread calibration of this model (no training)")
    ap.add_argument("--work", type=Path, default=ROOT / "build" / "line-train")
    ap.add_argument("--out", type=Path,
                    default=ROOT / "src" / "stickslip" / "resources" / "line_model.pt")
    args = ap.parse_args()
    recipe = BundledRecipe(n=args.n, seeds=tuple(args.seeds), typical=args.typical,
                           typical_seed=args.typical_seed, paper=args.paper,
                           paper_seed=args.paper_seed,
                           log_fraction=args.log_fraction)  # fmt: skip
    try:
        training = bundled_line_data(args.work, recipe)
    except TrainingDataError as e:
        ap.error(str(e))
    # the seed of the first randomised set seeds the split and the optimiser (the
    # command line's --seed 102)
    cfg = LineTrainConfig(members=args.members, epochs=args.epochs, seed=args.seeds[0],
                          beta=args.beta, beta_var=args.beta_var,
                          spread_hidden=args.spread_hidden,
                          effects=training_effects(args.typical_fraction),
                          calibration_draws=args.calibration_draws,
                          spread_power=args.spread_power, coarse_fraction=args.coarse,
                          **family_settings(args.families))  # fmt: skip
    if args.recalibrate is not None:
        recalibrate(ap, args, training.data, training.parts, cfg)
        return
    report = train_line(training, args.out, cfg, expert_model(args.expert, args.work, recipe),
                        args.expert)  # fmt: skip
    print(json.dumps(report, indent=1))
    print(f"wrote {args.out} ({args.out.stat().st_size / 1e6:.2f} MB)")


def recalibrate(ap: argparse.ArgumentParser, args: argparse.Namespace, data, parts: list,
                cfg: LineTrainConfig) -> None:  # fmt: skip
    """Re-fit only the spread calibration of ``args.recalibrate`` and save it to ``args.out``."""
    meta = line_metadata(args.recalibrate)
    # the validation split is only held out if the data and the training settings are
    # the ones the model was trained with (the calibration settings may differ)
    trained = {k: v for k, v in meta["train_config"].items() if k not in CALIBRATION_FIELDS}
    asked = {k: v for k, v in cfg.to_dict().items() if k not in CALIBRATION_FIELDS}
    if meta["dataset"].get("sets") != parts or json.dumps(
        trained, sort_keys=True) != json.dumps(asked, sort_keys=True):  # fmt: skip
        ap.error(f"{args.recalibrate} was not trained with these data and settings")
    ens = load_line_model(args.recalibrate)
    report = recalibrate_line_ensemble(ens, data.force_nN.astype(float), data.x_nm, data.params,
                                       cfg)  # fmt: skip
    metrics = {**meta["metrics"], **report, "recalibrated_from": str(args.recalibrate)}
    save_line_model(ens, args.out, cfg.channels, cfg.to_dict(), meta["dataset"], metrics)
    print(json.dumps(report, indent=1))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
