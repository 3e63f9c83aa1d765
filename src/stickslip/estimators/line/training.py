"""Training of whole-line models with domain randomisation and calibration.

Every batch passes the clean simulated traces through the instrument chain of
:mod:`stickslip.simulators.instrument` (detector noise, 1/f noise, low-pass, offset
drift, precursor softening, digitisation), with effects drawn afresh, so the network
never sees the same corruption twice and cannot rely on clean-simulation artefacts.
The split is by trajectory; the validation traces get one fixed draw of the effects,
and the predictive spread is calibrated on them.

The effects' prior. Trained on the broad ranges alone (:data:`TRAIN_EFFECTS`), the
network is right on a careful measurement but its intervals there are too wide (the
95 % interval of K covered 99 % of the lab bench's truths): the calibration is then
fitted mostly on lines noisier and more smeared than a careful measurement gives. The
default prior (:func:`training_effects`) draws a :data:`TYPICAL_FRACTION` of lines
from a typical careful measurement (:data:`~stickslip.simulators.instrument.LAB`, a
corner of the broad ranges) and the rest from the broad ranges, which stay as a tail.

Pristine lines. A line with no detector effects on a flat substrate (as in a clean
simulation) is a case of its own: nothing in it is ambiguous, so the network can and
should be far more precise there than on a corrupted line. With effects drawn
independently such lines would be rare in training (a few per cent), and the network
would treat a pristine-looking line as a corrupted one that happens to look clean,
with the corrupted lines' spread. A ``pristine_fraction`` of every batch is therefore
drawn from the flat-substrate trajectories and left without detector effects: a spike
in the prior at "no corruption". The calibration then weighs pristine and corrupted
validation lines equally and reports the coverage of each.

Classes of lines. One scale per target cannot fit every line: the spread is several
times too wide on quiet lines (no detector noise) and about right on noisy ones, and
the ratio moves with the noise level. The calibration therefore fits a scale per
target and per class of line (:class:`~stickslip.estimators.line.ensemble.SpreadClasses`, read off
the line itself: quiet on the reference lattice, quiet and resampled, noisy by noise
level), so that the 95 % interval covers 95 % of the validation truths in each class.

Calibration lines. A 95 % quantile read off one draw of the effects on the validation
trajectories (a few hundred lines per class) carries a sampling error of about 0.01 in
coverage, as large as the differences it is meant to fix. The calibration therefore
reads ``calibration_draws`` independent draws of the detector effects on the same
validation trajectories (the first is the validation set that training follows).
Within a class the calibrated std is ``c * sd ** gamma`` (:func:`power_fit`: the 95 %
quantile of the error, regressed on the ensemble's own spread), and the calibrated
lines' standardised errors give the intervals' shape at every level
(:meth:`~stickslip.estimators.line.ensemble.LineEnsemble.z_at`).

Effect families in training (optional, off by default). With ``families`` set (a
:class:`~stickslip.simulators.effects.NuisancePrior`), a ``family_fraction`` of the
non-pristine lines of every training batch carry effects drawn from that prior with the
``"train"`` implementation of every family (:func:`~stickslip.simulators.effects.draw`
and :func:`~stickslip.simulators.effects.apply`, as the calibration on the families
draws them) instead of the detector effects; their truths follow PHYSICS.md: the <F>
target is the mean of the contact force (:func:`~stickslip.simulators.effects.
contact_force`: precursor softening lowers it, every other family is an instrument
artefact) and the conditioning reads the *stated* velocity the draw gives. The
validation and calibration lines of the run stay as without it (the detector effects):
a model trained this way is meant to be calibrated on the families afterwards
(:func:`~stickslip.estimators.line.families.calibrate_on_families`).
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from functools import partial
from typing import Any

import numpy as np
import torch
from scipy import optimize, sparse
from tqdm.auto import tqdm

from stickslip.estimators.calibration import Z95
from stickslip.estimators.evidence import line_evidence
from stickslip.estimators.line.ensemble import (
    LOCATED_TARGETS,
    N_EXPERT,
    SHAPE_LEVELS,
    TARGETS,
    LineCNN,
    LineEnsemble,
    LineSpec,
    SpreadClasses,
    conditioning,
    gaussian_nll,
    line_inputs,
    map_line,
    n_conditions,
    predict_std_lines,
)
from stickslip.estimators.line.streaming import LineBatches, StreamSettings, batch_loader
from stickslip.estimators.mapping import MAX_PIXEL_RATIO, resample_mean
from stickslip.estimators.noise import log_noise_ratio
from stickslip.estimators.offsets import FRICTION_LEVELS, fit_friction_factor
from stickslip.estimators.split import split_indices
from stickslip.estimators.window.modelfile import TrainedModel
from stickslip.simulators import effects as fx
from stickslip.simulators.instrument import (
    LAB,
    EffectsMixture,
    InstrumentEffects,
    apply_instrument,
)
from stickslip.traces.dataset import Rows, as_rows
from stickslip.units import eta_from

#: Domain randomisation of training: broader than the laboratory bench.
TRAIN_EFFECTS = InstrumentEffects(
    white_nN=(0.0, 0.12),
    pink_nN=(0.0, 0.08),
    lowpass_px=(0.0, 3.0),
    drift_nN=(0.0, 0.15),
    softening=(0.0, 0.5),
    bits=16,
)


#: Fraction of training lines given a typical careful measurement's detector effects.
TYPICAL_FRACTION = 0.8

#: Settings only the spread calibration reads: a trained model can be re-calibrated
#: with other values (``scripts/train_line_model.py --recalibrate``).
CALIBRATION_FIELDS = ("spread_classes", "calibration_draws", "spread_power")

#: Most validation trajectories held out (their lines, under every calibration draw, are
#: kept in memory; beyond this the held-out share goes to training, so memory does not
#: grow with the set). The sampling error of a 95 % coverage over n lines is
#: sqrt(0.05 * 0.95 / n): 0.005 at 2000, before the calibration draws.
MAX_VAL_LINES = 2000

#: Exponents tried by :func:`power_fit`.
EXPONENTS = np.linspace(0.5, 2.0, 61)


def training_effects(typical_fraction: float) -> InstrumentEffects | EffectsMixture:
    """Detector effects of training: :data:`TRAIN_EFFECTS`, or a mixture in which a
    ``typical_fraction`` of lines draw from a typical careful measurement
    (:data:`~stickslip.simulators.instrument.LAB`, a corner of the broad ranges) and
    the rest from the broad ranges."""
    if typical_fraction <= 0:
        return TRAIN_EFFECTS
    return EffectsMixture((LAB, TRAIN_EFFECTS), (typical_fraction, 1.0 - typical_fraction))


@dataclass(frozen=True)
class LineTrainConfig:
    """Settings of a line-model training run (saved in the model file)."""

    members: int = 3
    epochs: int = 45
    batch_size: int = 128
    lr: float = 3e-3
    weight_decay: float = 1e-4
    beta: float = 0.5  # beta-NLL weight of the means' gradient (gaussian_nll)
    beta_var: float = 0.0  # ... of the variances': each line pulls on its variance equally
    mse_epochs: int = 2
    clean_fraction: float = 0.2  # traces left without detector effects, so the model
    # also learns how sure it can be on a clean line
    pristine_fraction: float = 0.25  # of each batch: flat substrate and no effects
    own_weight: float = 0.5  # weight of the CNN's own mean in the loss (with an expert)
    val_fraction: float = 0.1
    seed: int = 0
    channels: tuple[int, ...] = (16, 32, 48, 64)
    spread_hidden: int = 128  # > 0: the log-variances get a head of their own (LineCNN)
    # classes of lines calibrated separately (None: one scale per target for all lines)
    spread_classes: SpreadClasses | None = field(default_factory=SpreadClasses)
    calibration_draws: int = 8  # draws of the detector effects on the validation lines
    spread_power: bool = True  # calibrated std c * sd**gamma (False: gamma = 1)
    # detector effects: a typical measurement's for most lines, the broad ranges for the rest
    effects: InstrumentEffects | EffectsMixture = field(
        default_factory=lambda: training_effects(TYPICAL_FRACTION)
    )
    # effect families drawn on a family_fraction of the non-pristine training lines
    # (None: none, the bundled recipe; see the module notes)
    families: fx.NuisancePrior | None = None
    family_fraction: float = 0.5
    # lines re-pixelated coarser, as a detector with larger pixels records them (each
    # pixel the mean force over its travel: exact from the fine simulation), by a
    # log-uniform factor up to COARSE_MAX (and the mapping's limit), then mapped back
    coarse_fraction: float = 0.0

    def to_dict(self) -> dict:
        """Plain dict of the settings (saved in the model file). Without ``families``
        neither it nor ``family_fraction`` is written, so a run without families is
        described as before the option existed; with it, ``families`` is the prior's
        :meth:`~stickslip.simulators.effects.NuisancePrior.to_dict` (read back with
        :func:`training_families`)."""
        d = dataclasses.asdict(self)
        if self.families is None:
            del d["families"], d["family_fraction"]
        else:
            d["families"] = self.families.to_dict()
        return d


def family_settings(fraction: float) -> dict[str, Any]:
    """:class:`LineTrainConfig` keywords for the broad nuisance prior's families on a
    ``fraction`` of the non-pristine training lines (0: no families)."""
    if fraction > 0:
        return {"families": fx.NuisancePrior(), "family_fraction": float(fraction)}
    return {"families": None, "family_fraction": LineTrainConfig.family_fraction}


def training_families(train_config: dict) -> tuple[fx.NuisancePrior | None, float]:
    """The effect-family prior and fraction of a saved training config
    (:meth:`LineTrainConfig.to_dict`): ``(None, 0.0)`` for a run without families."""
    prior = train_config.get("families")
    if prior is None:
        return None, 0.0
    return fx.NuisancePrior.from_dict(prior), float(train_config["family_fraction"])


def line_targets(U0_eV, K_N_m, F_mean_nN, lattice_nm, spec: LineSpec) -> np.ndarray:
    """Target matrix (N, 4) in the mapped frame: F, ln U0', ln K', ln eta."""
    s = np.asarray(lattice_nm, float) / spec.lattice_nm
    U0, K = np.asarray(U0_eV, float), np.asarray(K_N_m, float)
    return np.column_stack(
        [F_mean_nN, np.log(U0 / s), np.log(K * s), np.log(eta_from(U0, K, lattice_nm))]
    )


#: the coarsest re-pixelation of a training line (x the simulated pixel)
COARSE_MAX = 4.0


def coarse_factors(lattice_nm: np.ndarray, fraction: float, rng: np.random.Generator,
                   spec: LineSpec) -> np.ndarray:  # fmt: skip
    """Per line, the factor by which it is re-pixelated (1: not): a ``fraction`` of them
    log-uniform between 1 and :data:`COARSE_MAX`, and never so coarse that the mapped
    pixel passes 95 % of the mapping's limit (:data:`~stickslip.estimators.mapping.
    MAX_PIXEL_RATIO`)."""
    a = np.asarray(lattice_nm, float)
    factors = np.ones(a.size)
    if fraction <= 0:
        return factors
    on = rng.random(a.size) < fraction
    hi = np.minimum(COARSE_MAX, 0.95 * MAX_PIXEL_RATIO * a / spec.lattice_nm)
    u = rng.random(a.size)
    factors[on] = np.exp(u[on] * np.log(np.maximum(hi[on], 1.0)))
    return factors


def pixel_and_map(x_nm: np.ndarray, force_nN: np.ndarray, lattice_nm: float, spec: LineSpec,
                  factor: float = 1.0) -> np.ndarray:  # fmt: skip
    """:func:`map_line` of the line as recorded with pixels ``factor`` times larger
    (:func:`~stickslip.estimators.mapping.resample_mean`: each new pixel the mean force
    over its travel)."""
    if factor <= 1.0:
        return map_line(x_nm, force_nN, lattice_nm, spec)
    x = np.asarray(x_nm, float)
    pixel = (x[1] - x[0]) * factor
    f = resample_mean(x, force_nN, pixel)
    return map_line(x[0] + np.arange(f.size) * pixel, f, lattice_nm, spec)


def corrupt_and_map(force_nN, lattice_nm, x_nm, spec, effects, rng, clean_fraction=0.0,
                    keep_clean: np.ndarray | None = None,
                    coarse_fraction: float = 0.0):  # fmt: skip
    """Corrupt a batch (a ``clean_fraction`` of traces, and those marked in
    ``keep_clean``, left clean), re-pixelate a ``coarse_fraction`` of it
    (:func:`coarse_factors`) and map it: the mapped lines and each corrupted trace's
    mean (the friction target is the clean mean minus it: see :data:`TARGETS`)."""
    F, _ = apply_instrument(force_nN, effects, rng)
    clean = rng.random(F.shape[0]) < clean_fraction
    if keep_clean is not None:
        clean |= keep_clean
    F[clean] = force_nN[clean]
    factors = coarse_factors(lattice_nm, coarse_fraction, rng, spec)
    lines = [pixel_and_map(x_nm, f, a, spec, c)
             for f, a, c in zip(F, lattice_nm, factors, strict=True)]  # fmt: skip
    return lines, F.mean(axis=1)


def prepare_batch(force_nN, lattice_nm, velocity_nm_per_s, x_nm, spec, effects, rng,
                  crop: int | None, clean_fraction: float = 0.0,
                  keep_clean: np.ndarray | None = None, temperature_K=None,
                  coarse_fraction: float = 0.0):  # fmt: skip
    """:func:`corrupt_and_map`, then stacked: input and conditioning tensors (lines
    cropped to ``crop``, at random, or centred on the shortest when None) and the
    corrupted traces' means."""
    lines, observed = corrupt_and_map(force_nN, lattice_nm, x_nm, spec, effects, rng,
                                      clean_fraction, keep_clean,
                                      coarse_fraction)  # fmt: skip
    X = line_inputs(lines, spec, length=crop, rng=rng if crop else None)
    return X, conditioning(lattice_nm, velocity_nm_per_s, spec, temperature_K), observed


def prepare_family_batch(force_nN, lattice_nm, velocity_nm_per_s, F_mean_nN, x_nm, spec,
                         config: LineTrainConfig, rng, crop: int | None,
                         keep_clean: np.ndarray | None = None,
                         temperature_K=None):  # fmt: skip
    """:func:`prepare_batch` with effect families (``config.families``) on a
    ``config.family_fraction`` of the lines not marked in ``keep_clean``.

    Those lines get a draw of the prior with the ``"train"`` implementation
    (:func:`~stickslip.simulators.effects.apply`) instead of the detector effects and are
    conditioned on the stated velocity; the other lines are as in :func:`prepare_batch`.
    The third value is, per line, the reference the friction target is taken from (the
    training loop's target is ``F_mean_nN - reference``): the corrupted trace's mean on
    lines without families, and ``observed + F_mean_nN - contact`` on family lines, where
    ``contact`` is the mean of the contact force
    (:func:`~stickslip.simulators.effects.contact_force`, the <F> truth of PHYSICS.md), so
    that their target is ``contact - observed``.
    """
    force_nN = np.asarray(force_nN, float)
    n = force_nN.shape[0]
    on = rng.random(n) < config.family_fraction
    if keep_clean is not None:
        on &= ~keep_clean
    lines, reference = corrupt_and_map(force_nN, lattice_nm, x_nm, spec, config.effects, rng,
                                       config.clean_fraction, keep_clean,
                                       config.coarse_fraction)  # fmt: skip
    v = np.array(velocity_nm_per_s, float)
    T = np.array(np.broadcast_to(spec.temperature_K if temperature_K is None else temperature_K,
                                 (n,)), float)  # fmt: skip
    sel = np.flatnonzero(on)
    if sel.size:
        d = fx.draw(config.families, sel.size, rng, "train")
        F, said = fx.apply(d, x_nm, force_nN[sel], v[sel], rng, temperature_K=T[sel])
        contact = fx.contact_force(d, force_nN[sel]).mean(axis=1)
        factors = coarse_factors(np.asarray(lattice_nm)[sel], config.coarse_fraction, rng, spec)
        for j, i in enumerate(sel):
            lines[i] = pixel_and_map(x_nm, F[j], lattice_nm[i], spec, factors[j])
        v[sel] = said.velocity_nm_per_s
        T[sel] = said.temperature_K
        reference[sel] = F.mean(axis=1) + np.asarray(F_mean_nN, float)[sel] - contact
    X = line_inputs(lines, spec, length=crop, rng=rng if crop else None)
    return X, conditioning(lattice_nm, v, spec, T), reference


def _temperatures(params: dict[str, np.ndarray], rows: np.ndarray) -> np.ndarray | None:
    """The rows' temperatures (None where the set does not store them: the reference's)."""
    return np.asarray(params["temperature_K"])[rows] if "temperature_K" in params else None


def flat_substrate(params: dict[str, np.ndarray]) -> np.ndarray:
    """Trajectories simulated without barrier modulation or defects (all, if unknown)."""
    n = np.asarray(params["U0_eV"]).size
    flat = np.ones(n, bool)
    if "mod_amplitude" in params:
        flat &= np.asarray(params["mod_amplitude"]) == 0
    if "defect_count" in params:
        flat &= np.asarray(params["defect_count"]) == 0
    return flat


def _stratum_weights(strata: np.ndarray) -> np.ndarray:
    """Row weights with which every stratum weighs the same whatever its size."""
    w = np.zeros(strata.size)
    for g in np.unique(strata):
        w[strata == g] = 1.0 / np.sum(strata == g)
    return w


def _weighted_quantile(values: np.ndarray, weights: np.ndarray, level):
    """Quantile(s) of ``values`` at ``level`` (a float or an array), rows weighted."""
    order = np.argsort(values)
    cw = np.cumsum(weights[order]) / weights.sum()
    return values[order][np.minimum(np.searchsorted(cw, level), cw.size - 1)]


def balanced_scale(z_abs: np.ndarray, strata: np.ndarray, level: float = 0.95) -> np.ndarray:
    """Per-column scale ``c`` such that ``|z| / c <= Z95`` holds for ``level`` of the rows,
    each stratum weighing the same whatever its size (a weighted quantile of ``|z|``)."""
    w = _stratum_weights(strata)
    return np.array([_weighted_quantile(z_abs[:, j], w, level) / Z95
                     for j in range(z_abs.shape[1])])  # fmt: skip


def power_fit(err_abs: np.ndarray, sd: np.ndarray, weights: np.ndarray, level: float = 0.95,
              exponents: np.ndarray = EXPONENTS) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Calibrated spread ``scale * sd ** exponent`` per column of (N, T) errors and stds.

    ``Z95 * scale * sd ** exponent`` is a linear quantile regression at ``level`` of
    ``ln |error|`` on ``ln sd`` (weighted rows; the exponent from a grid, the one of least
    pinball loss, the offset then exact): the ``level`` quantile of ``|error|`` given the
    spread, since quantiles commute with ``ln``. Exponent 1 is a plain scale factor.

    Returns
    -------
    scale, exponent : ndarray (T,)
    """
    w = weights / weights.sum()
    scale, exponent = np.empty(err_abs.shape[1]), np.empty(err_abs.shape[1])
    for j in range(err_abs.shape[1]):
        le, ls = np.log(err_abs[:, j] + 1e-12), np.log(sd[:, j])
        best = np.inf
        for g in exponents:
            r = le - g * ls
            a = _weighted_quantile(r, w, level)
            u = r - a
            loss = np.sum(w * np.maximum(level * u, (level - 1.0) * u))
            if loss < best - 1e-12:
                best, scale[j], exponent[j] = loss, np.exp(a) / Z95, g
    return scale, exponent


def _standardise_friction(Y: np.ndarray, observed_mean: np.ndarray, y_mean, y_std):
    """Standardised targets with the friction column made relative to the trace's mean."""
    Y = Y.copy()
    Y[:, 0] -= observed_mean
    return torch.from_numpy(((Y - y_mean) / y_std).astype(np.float32))


@dataclass
class ValidationSet:
    """Held-out lines as the network sees them, in two strata.

    ``lines`` are the mapped lines, whole (calibration reads them as inference does),
    ``C`` the conditioning, ``rows`` the source trajectories (the flat-substrate ones twice),
    ``strata`` 0 for a corrupted line (drawn like training ones, same clean fraction)
    and 1 for a pristine one, ``observed_mean`` each input line's mean force.
    """

    lines: list[np.ndarray]
    C: torch.Tensor
    rows: np.ndarray
    strata: np.ndarray
    observed_mean: np.ndarray
    #: each line's :func:`~stickslip.estimators.offsets.compression_moment` on its own
    #: samples (nN), which sizes the <F> compression term (None: 0)
    m3_nN: np.ndarray | None = None


def validation_set(force_nN, x_nm, params, val: np.ndarray, config: LineTrainConfig,
                   spec: LineSpec, draw: int = 0) -> ValidationSet:  # fmt: skip
    """The validation lines of :func:`train_line_ensemble` (one fixed draw of effects;
    ``draw`` > 0: another independent one, for the calibration)."""
    val_rng = np.random.default_rng([config.seed, 999, draw] if draw else [config.seed, 999])
    val_p = val[flat_substrate(params)[val]]
    a = params["lattice_nm"]
    f_val, f_p = (np.asarray(force_nN[r], float) for r in (val, val_p))  # rows read here
    corrupted, mean_c = corrupt_and_map(f_val, a[val], x_nm, spec, config.effects, val_rng,
                                        config.clean_fraction,
                                        coarse_fraction=config.coarse_fraction)  # fmt: skip
    pristine, mean_p = corrupt_and_map(f_p, a[val_p], x_nm, spec, config.effects, val_rng,
                                       keep_clean=np.ones(val_p.size, bool))  # fmt: skip
    rows = np.concatenate([val, val_p])
    return ValidationSet(
        lines=corrupted + pristine,
        C=conditioning(a[rows], params["velocity_nm_per_s"][rows], spec,
                       _temperatures(params, rows)),
        rows=rows,
        strata=np.repeat([0, 1], [val.size, val_p.size]),
        observed_mean=np.concatenate([mean_c, mean_p]),
    )


def calibration_set(vs: ValidationSet, force_nN, x_nm, params, config: LineTrainConfig,
                    spec: LineSpec) -> ValidationSet:  # fmt: skip
    """The validation trajectories under ``config.calibration_draws`` independent draws of
    the detector effects, as one set: ``vs`` (:func:`validation_set`'s first draw) and
    the draws after it."""
    val = vs.rows[vs.strata == 0]
    sets = [vs] + [validation_set(force_nN, x_nm, params, val, config, spec, draw=k)
                   for k in range(1, config.calibration_draws)]  # fmt: skip
    return ValidationSet(
        lines=[f for s in sets for f in s.lines],
        C=torch.cat([s.C for s in sets]),
        rows=np.concatenate([s.rows for s in sets]),
        strata=np.concatenate([s.strata for s in sets]),
        observed_mean=np.concatenate([s.observed_mean for s in sets]),
    )


def held_out(force_nN, x_nm, params, config: LineTrainConfig, spec: LineSpec,
             rng: np.random.Generator) -> tuple[np.ndarray, ValidationSet, np.ndarray]:  # fmt: skip
    """Training indices, validation lines and the target matrix (:func:`line_targets`) of
    a run with ``config``; ``rng`` is the run's, its first draw the split (:func:`split`),
    so training and re-calibration see the same validation lines. At most
    :data:`MAX_VAL_LINES` trajectories are held out (the rest of the share trains)."""
    train, val = split_indices(force_nN.shape[0], config.val_fraction, rng)
    if val.size > MAX_VAL_LINES:
        train, val = np.concatenate([train, val[MAX_VAL_LINES:]]), val[:MAX_VAL_LINES]
    vs = validation_set(force_nN, x_nm, params, val, config, spec)
    Y = line_targets(params["U0_eV"], params["K_N_m"], params["F_mean_nN"],
                     params["lattice_nm"], spec)  # fmt: skip
    return train, vs, Y


#: slopes tried for each evidence coefficient (:func:`evidence_fit`)
EVIDENCE_SLOPES = np.linspace(0.0, 1.0, 21)


def evidence_fit(r: np.ndarray, e: np.ndarray, weights: np.ndarray, level: float = 0.95,
                 slopes: np.ndarray = EVIDENCE_SLOPES) -> np.ndarray:  # fmt: skip
    """Coefficients ``(b0, b)`` of the ``level`` quantile of ``r`` given the evidence
    ``e``: ``b0 + b . e``, with each ``b >= 0`` on a grid (coordinate-wise, twice round)
    and ``b0`` then exact, the one of least pinball loss.

    ``r`` is ``ln |error| - ln(calibrated std)`` of the calibration lines, so the fit is
    a linear quantile regression of the interval's half-width on what the line shows:
    its pinball loss is, up to a constant factor, the mean interval score of the
    central ``2 level - 1`` interval (Gneiting and Raftery 2007).

    Parameters
    ----------
    r : ndarray (N,)
    e : ndarray (N, k)
    weights : ndarray (N,)

    Returns
    -------
    ndarray (1 + k,)
    """
    w = weights / weights.sum()

    def loss(b: np.ndarray) -> tuple[float, float]:
        u = r - e @ b
        b0 = float(_weighted_quantile(u, w, level))
        u = u - b0
        return float(np.sum(w * np.maximum(level * u, (level - 1.0) * u))), b0

    b = np.zeros(e.shape[1])
    best, b0 = loss(b)
    for _ in range(2):
        for j in range(b.size):
            for g in slopes:
                trial = b.copy()
                trial[j] = g
                value, c = loss(trial)
                if value < best - 1e-12:
                    best, b0, b = value, c, trial
    return np.concatenate([[b0], b])


def class_fit(err_abs: np.ndarray, sd: np.ndarray, classes: np.ndarray, n_classes: int,
              strata: np.ndarray, power: bool = True,
              min_lines: int = 30) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Calibrated spread per class, (scale, exponent) each (n_classes, n_targets): 95 % of
    each class's lines inside the interval (its lines weighing equally: the class, not
    the stratum, now says what kind of line it is); :func:`power_fit` when ``power``,
    else a plain scale (exponent 1). A class with fewer than ``min_lines`` lines gets the
    pooled fit, strata weighing equally."""

    def fit(m: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if power:
            return power_fit(err_abs[m], sd[m], w)
        z = err_abs[m] / sd[m]
        return np.array([_weighted_quantile(z[:, j], w, 0.95) / Z95
                         for j in range(z.shape[1])]), np.ones(z.shape[1])  # fmt: skip

    pooled = fit(np.ones(classes.size, bool), _stratum_weights(strata))
    scale, exponent = (np.tile(p, (n_classes, 1)) for p in pooled)
    for c in range(n_classes):
        m = classes == c
        if m.sum() >= min_lines:
            scale[c], exponent[c] = fit(m, np.ones(int(m.sum())))
    return scale, exponent


def median_fit(r: np.ndarray, u: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Coefficients ``(c0, c)`` of the weighted median of ``r`` given ``u``: the linear
    quantile regression at 0.5 (least weighted absolute error, the proper score of a
    median; Koenker and Bassett 1978), solved exactly as a linear programme.

    Parameters
    ----------
    r : ndarray (N,)
    u : ndarray (N, k)
    weights : ndarray (N,)

    Returns
    -------
    ndarray (1 + k,)
    """
    X = np.column_stack([np.ones(r.size), u])
    n, k = X.shape
    w = weights / weights.sum()
    # r = X c + p - q with p, q >= 0: minimise sum w (p + q) / 2
    cost = np.concatenate([np.zeros(k), 0.5 * w, 0.5 * w])
    eq = sparse.hstack([sparse.csr_matrix(X), sparse.eye(n), -sparse.eye(n)]).tocsr()
    bounds = [(None, None)] * k + [(0.0, None)] * (2 * n)
    res = optimize.linprog(cost, A_eq=eq, b_eq=r, bounds=bounds, method="highs")
    if not res.success:  # degenerate inputs: a plain weighted median, no slopes
        return np.concatenate([[_weighted_quantile(r, w, 0.5)], np.zeros(k - 1)])
    return res.x[:k]


def fit_location(ens: LineEnsemble, cs: ValidationSet, mu: np.ndarray, sd: np.ndarray,
                 Y_std: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Fit ``ens.location`` (and its range) on calibration lines: per target of
    :data:`~stickslip.estimators.line.ensemble.LOCATED_TARGETS`, the weighted median of
    the members' error given what the line shows
    (:data:`~stickslip.estimators.line.ensemble.LOCATION_INPUTS`; :func:`median_fit`),
    one fit over every class of line (a class alone spans too little of the noise); the
    other targets keep no shift. Returns the means with the shift taken off
    (standardised units, as ``mu``)."""
    noise = np.array([float(log_noise_ratio(f)) for f in cs.lines])
    u = ens.location_inputs(noise, mu, sd)
    coef = np.zeros((len(TARGETS), 1 + u.shape[2]))
    for name in LOCATED_TARGETS:
        j = TARGETS.index(name)
        coef[j] = median_fit(mu[:, j] - Y_std[:, j], u[:, j], weights)
    ens.location = coef
    ens.location_range = np.array([u.min(axis=0), u.max(axis=0)])
    return mu - ens.location_shift(noise, mu, sd)


def calibrate(ens: LineEnsemble, cs: ValidationSet, Y_cal: np.ndarray,
              classes: SpreadClasses | None = None, power: bool = True,
              evidence: bool = True, location: bool = True):  # fmt: skip
    """Fit the calibration of ``ens`` on calibration lines (targets ``Y_cal`` in
    :func:`line_targets` units). With ``location``, first the median error of the
    members' mean given what the line shows (:func:`fit_location`), which every
    prediction then takes off; without it, the model's location calibration is kept
    as it is. Then the spread: per class of line when ``classes`` is given (else one
    class, strata weighing equally), :func:`class_fit`, then the standardised errors'
    quantiles (``ens.shape``); where the model has <F> offset or compression terms,
    also the factor those intervals take on the model's own half-width
    (:func:`~stickslip.estimators.offsets.fit_friction_factor`, on ``cs.m3_nN``). With
    ``evidence``, each line's calibrated std then takes a factor on what the line shows
    (:func:`evidence_fit`, :mod:`stickslip.estimators.evidence`).
    Returns the standardised predictive means, the calibrated ``|z|`` and the class of
    every calibration line."""
    ens.scale, ens.exponent, ens.shape, ens.classes = np.ones(len(TARGETS)), None, None, classes
    ens.friction_factor = ens.evidence = ens.evidence_range = None
    if location:
        ens.location = ens.location_range = None
    mu, sd = predict_std_lines(ens, cs.lines, cs.C)
    Y_std = _standardise_friction(Y_cal, cs.observed_mean, ens.y_mean, ens.y_std).numpy()
    per_class = classes is not None
    # weighed as in the fits: lines equally within classes, strata equally without
    w = np.ones(len(cs.lines)) if per_class else _stratum_weights(cs.strata)
    if classes is None:
        cls, n_classes = np.zeros(len(cs.lines), int), 1
    else:
        cls = classes.classify_lines(cs.lines, cs.C[:, 0].numpy().astype(float) + 1.0)
        n_classes = classes.n
    if location:
        mu = fit_location(ens, cs, mu, sd, Y_std, w)
    err = np.abs(mu - Y_std)
    scale, exponent = class_fit(err, sd, cls, n_classes, cs.strata, power)
    std = scale[cls] * sd ** exponent[cls]
    ens.scale, ens.exponent = (scale, exponent) if per_class else (scale[0], exponent[0])
    if evidence:
        e = line_evidence(cs.lines, ens.spec.lattice_nm / ens.spec.pixel_nm)
        ens.evidence_range = np.array([e.min(axis=0), e.max(axis=0)])
        r = np.log(err + 1e-12) - np.log(std)
        ens.evidence = np.array([evidence_fit(r[:, j], e, w) for j in range(err.shape[1])])
        std = std * ens.evidence_factor(e)
    z_cal = err / std
    ens.shape = np.array([_weighted_quantile(z_cal[:, j], w, SHAPE_LEVELS)
                          for j in range(z_cal.shape[1])])  # fmt: skip
    if ens.offset is not None or ens.compression is not None:
        sd_F = std[:, 0] * float(ens.y_std[0])  # nN
        # signed error against what the line shows (friction + offset), both relative to
        # the line's own mean as the members answer it
        target = Y_cal[:, 0] - cs.observed_mean
        r = target - (mu[:, 0] * float(ens.y_std[0]) + float(ens.y_mean[0]))
        m3 = 0.0 if cs.m3_nN is None else cs.m3_nN
        factors = fit_friction_factor(r, lambda q: float(ens.z_at(q)[0]) * sd_F, ens.offset,
                                      ens.compression, m3, w)  # fmt: skip
        ens.friction_factor = np.array([FRICTION_LEVELS, factors])
    return mu, z_cal, cls


def calibrate_and_report(ens: LineEnsemble, cs: ValidationSet, Y_cal: np.ndarray,
                         classes: SpreadClasses | None = None, power: bool = True,
                         groups: dict[str, np.ndarray] | None = None) -> dict:  # fmt: skip
    """Calibrate ``ens`` on calibration lines (:func:`calibrate`) and report its errors and
    interval coverage there, overall, per stratum (corrupted, pristine), per class and,
    under ``"val_per_group"``, on the lines of each of ``groups`` (name: boolean mask
    over the calibration lines, e.g. the lines that carry one effect family)."""
    mu, z_cal, cls = calibrate(ens, cs, Y_cal, classes, power)
    z68, z95 = ens.z_at(0.68), ens.z_at(0.95)
    pred = mu * ens.y_std + ens.y_mean
    pred[:, 0] += cs.observed_mean
    rel = np.exp(pred[:, 1:] - Y_cal[:, 1:]) - 1.0

    def named(values) -> dict:
        names = TARGETS if len(values) == len(TARGETS) else TARGETS[1:]
        return dict(zip(names, np.asarray(values).tolist(), strict=True))

    report = {
        "n_calibration": len(cs.lines),
        "val_rmse_F_mean_nN": float(np.sqrt(np.mean((pred[:, 0] - Y_cal[:, 0]) ** 2))),
        "val_rel_rmse": named(np.sqrt(np.mean(rel**2, axis=0))),
        "val_coverage95": named(np.mean(z_cal <= z95, axis=0)),
        "val_coverage68": named(np.mean(z_cal <= z68, axis=0)),
        "interval_z68": named(z68),
    }
    if ens.friction_factor is not None:
        levels, factors = ens.friction_factor
        report["friction_factor"] = {f"{q:g}": float(f) for q, f in zip(levels, factors,
                                                                         strict=True)}  # fmt: skip
    if classes is None:
        report["calibration_scale"] = named(ens.scale)
        report["calibration_exponent"] = named(ens.exponent)
    else:
        report["spread_classes"] = classes.to_dict()
        report["calibration_scale"] = [named(row) for row in ens.scale]
        report["calibration_exponent"] = [named(row) for row in ens.exponent]
        report["val_per_class"] = [
            {"class": c, "n": int(np.sum(cls == c)),
             "coverage95": named(np.mean(z_cal[cls == c] <= z95, axis=0))}
            for c in range(classes.n) if np.any(cls == c)
        ]  # fmt: skip
    if groups:
        report["val_per_group"] = {
            name: {"n": int(m.sum()), "coverage95": named(np.mean(z_cal[m] <= z95, axis=0))}
            for name, m in groups.items() if m.any()
        }  # fmt: skip
    for g, name in ((0, "corrupted"), (1, "pristine")):
        m = cs.strata == g
        if not m.any():  # e.g. calibration on the nuisance prior: no pristine stratum
            continue
        report[f"val_{name}"] = {
            "n": int(m.sum()),
            "rel_rmse": named(np.sqrt(np.mean(rel[m] ** 2, axis=0))),
            "coverage95": named(np.mean(z_cal[m] <= z95, axis=0)),
            "coverage68": named(np.mean(z_cal[m] <= z68, axis=0)),
        }
    return report


def calibrate_on_validation(ens: LineEnsemble, vs: ValidationSet, Y: np.ndarray,
                            force_nN: np.ndarray | Rows, x_nm: np.ndarray,
                            params: dict[str, np.ndarray],
                            config: LineTrainConfig) -> dict:  # fmt: skip
    """:func:`calibrate_and_report` on the calibration lines of a run's validation
    trajectories (:func:`calibration_set`; ``vs`` and ``Y`` from :func:`held_out`)."""
    cs = calibration_set(vs, force_nN, x_nm, params, config, ens.spec)
    return calibrate_and_report(ens, cs, Y[cs.rows], config.spread_classes, config.spread_power)


def recalibrate_line_ensemble(ens: LineEnsemble, force_nN: np.ndarray | Rows, x_nm: np.ndarray,
                              params: dict[str, np.ndarray],
                              config: LineTrainConfig) -> dict:  # fmt: skip
    """Re-fit the spread calibration of an ensemble that :func:`train_line_ensemble` trained
    on these traces with this ``config`` (the calibration settings, ``CALIBRATION_FIELDS``,
    may differ), on the same validation trajectories (the members are left as they
    are); returns the report of :func:`calibrate_and_report`."""
    _, vs, Y = held_out(force_nN, x_nm, params, config, ens.spec,
                        np.random.default_rng(config.seed))  # fmt: skip
    return calibrate_on_validation(ens, vs, Y, force_nN, x_nm, params, config)


def _prepare_rows(
    force_nN: np.ndarray,
    rows: np.ndarray,
    keep_clean: np.ndarray,
    rng: np.random.Generator,
    *,
    params: dict[str, np.ndarray],
    x_nm: np.ndarray,
    spec: LineSpec,
    config: LineTrainConfig,
) -> tuple[torch.Tensor, torch.Tensor, np.ndarray]:
    """:func:`prepare_batch` of training rows (run in the loader's workers)."""
    a, v = params["lattice_nm"][rows], params["velocity_nm_per_s"][rows]
    T = _temperatures(params, rows)
    if config.families is not None:
        return prepare_family_batch(force_nN, a, v, params["F_mean_nN"][rows], x_nm, spec,
                                    config, rng, crop=spec.crop, keep_clean=keep_clean,
                                    temperature_K=T)  # fmt: skip
    return prepare_batch(force_nN, a, v, x_nm, spec, config.effects, rng, crop=spec.crop,
                         clean_fraction=config.clean_fraction, keep_clean=keep_clean,
                         temperature_K=T, coarse_fraction=config.coarse_fraction)  # fmt: skip


def train_line_ensemble(
    force_nN: np.ndarray | Rows,
    x_nm: np.ndarray,
    params: dict[str, np.ndarray],
    config: LineTrainConfig = LineTrainConfig(),
    spec: LineSpec = LineSpec(),
    progress: bool = True,
    expert: TrainedModel | None = None,
    stream: StreamSettings = StreamSettings(),
) -> tuple[LineEnsemble, dict]:
    """Train an ensemble on simulated traces; returns it and a report (losses, metrics).

    The training rows are streamed a chunk at a time
    (:mod:`stickslip.estimators.line.streaming`), so only the validation rows (at most
    :data:`MAX_VAL_LINES`), the parameters and a shuffle buffer per loader worker are
    held in memory, whatever the size of the set.

    Parameters
    ----------
    force_nN : ndarray (N, P) or Rows
        Clean simulated traces: in memory, or read from a file
        (:func:`~stickslip.traces.dataset.open_dataset`).
    x_nm : ndarray (P,)
        Their positions.
    params : dict
        Per-trace ``U0_eV``, ``K_N_m``, ``F_mean_nN``, ``lattice_nm``,
        ``velocity_nm_per_s``.
    expert : TrainedModel, optional
        A window model whose estimates the members read and gate (see
        :mod:`stickslip.estimators.line.ensemble`); it must read the reference lattice and pixel.
    stream : StreamSettings
        Loader workers, shuffle buffer and an optional cap on the steps of an epoch.
    """
    if expert is not None and (
        not np.isclose(expert.features.pixel_nm, spec.pixel_nm)
        or not np.isclose(expert.features.lattice_nm, spec.lattice_nm)
    ):
        raise ValueError("the expert must read lines on the line model's lattice and pixel")
    torch.manual_seed(config.seed)
    rng = np.random.default_rng(config.seed)
    source = as_rows(force_nN)
    train, vs, Y = held_out(source, x_nm, params, config, spec, rng)
    # friction: the network predicts the correction to the observed mean (~ the offset)
    y_mean, y_std = Y[train].mean(axis=0), Y[train].std(axis=0)
    y_mean[0], y_std[0] = 0.0, 0.05
    ens = LineEnsemble(members=[], spec=spec, y_mean=y_mean, y_std=y_std, expert=expert)
    Xv = line_inputs(vs.lines, spec)  # cropped to a common length, to follow the loss
    Cv, Ev = vs.C, ens.expert_for(Xv)
    Yv = _standardise_friction(Y[vs.rows], vs.observed_mean, y_mean, y_std)
    columns = tuple(k for k in ("lattice_nm", "velocity_nm_per_s", "temperature_K")
                    if k in params)  # fmt: skip
    if config.families is not None:
        columns += ("F_mean_nN",)
    prepare = partial(_prepare_rows, params={k: params[k] for k in columns}, x_nm=x_nm,
                      spec=spec, config=config)  # fmt: skip
    history = []
    t0 = time.perf_counter()
    for k in range(config.members):
        batches = LineBatches(source, train, flat_substrate(params), prepare, config.batch_size,
                              config.pristine_fraction, config.seed, k, stream)  # fmt: skip
        steps_per_epoch = max(1, batches.batches_per_epoch())
        net = LineCNN(channels=config.channels, n_cond=n_conditions(spec),
                      n_expert=N_EXPERT if expert else 0,
                      spread_hidden=config.spread_hidden)  # fmt: skip
        opt = torch.optim.AdamW(net.parameters(), lr=config.lr, weight_decay=config.weight_decay)
        sched = torch.optim.lr_scheduler.OneCycleLR(
            opt, max_lr=config.lr, total_steps=config.epochs * steps_per_epoch
        )
        bar = tqdm(range(config.epochs), desc=f"member {k + 1}/{config.members}",
                   disable=not progress)  # fmt: skip
        for epoch in bar:
            net.train()
            batches.epoch = epoch  # the loader's workers copy it when they start
            total, steps = 0.0, 0
            for X, C, idx, obs in batch_loader(batches):
                mean, log_var, own = net.parts(X, C, ens.expert_for(X))
                y = _standardise_friction(Y[idx.numpy()], obs.numpy(), y_mean, y_std)
                if epoch < config.mse_epochs:
                    loss = ((mean - y) ** 2).sum(dim=1).mean()
                else:
                    loss = gaussian_nll(mean, log_var, y, config.beta, config.beta_var)
                if net.n_expert:  # the own mean must stay an estimate (LineCNN.parts)
                    loss = loss + config.own_weight * gaussian_nll(own, log_var.detach(), y,
                                                                   config.beta)  # fmt: skip
                opt.zero_grad()
                loss.backward()
                opt.step()
                sched.step()
                total += loss.item()
                steps += 1
                if steps == steps_per_epoch:  # a capped epoch: leave the rest unread
                    break
            net.eval()
            with torch.inference_mode():
                mv, _ = net(Xv, Cv, Ev)
                val_mse = float(((mv - Yv) ** 2).mean())
            history.append({"member": k, "epoch": epoch, "loss": total / max(steps, 1),
                            "val_mse": val_mse})  # fmt: skip
            bar.set_postfix(loss=f"{total / max(steps, 1):.3f}", val_mse=f"{val_mse:.4f}")
        ens.members.append(net)
    report = {
        **calibrate_on_validation(ens, vs, Y, source, x_nm, params, config),
        "history": history,
        "train_seconds": time.perf_counter() - t0,
        "n_train": int(train.size),
        "n_val": int(vs.rows.size),
        "loader": dataclasses.asdict(stream),
    }
    source.close()
    return ens, report
