"""Calibrate a line model's intervals on the broad nuisance prior (effect families).

The members of the bundled line model were trained with the older detector effects
(:mod:`stickslip.simulators.instrument`), and its spread was first calibrated on fresh
draws of those same effects, so its intervals measured in-distribution coverage only.
Lines that carry the effect families of :mod:`stickslip.simulators.effects` (precursor
softening, piezo creep, cantilever ringing, crosstalk, ...) are not like those: on
them the first calibration's 95 % intervals covered a fraction of the truths
(``benchmarks/families.py`` prints it).

This module re-fits the spread calibration (:func:`~stickslip.estimators.line.training.
calibrate`: the class and power-law scale, the error shape) on calibration lines drawn
from the nuisance prior with the ``"train"`` implementation of every family, on
trajectories of their own. The members stay as they are. Evaluation then uses the
``"eval"`` implementations on other trajectories; leaving a family out of the prior
given here (:meth:`~stickslip.simulators.effects.NuisancePrior.without`) gives the
leave-one-family-out check: the intervals on lines that carry an effect the
calibration never saw.

The settings (prior, seed, number of draws, left-out families) are stored with the
model (:func:`family_calibration_record`), so a calibrated file says how it was made.
"""

from __future__ import annotations

import copy
import dataclasses
import os
from dataclasses import dataclass

import numpy as np
import torch

from stickslip.estimators.line.ensemble import LineEnsemble, conditioning
from stickslip.estimators.line.training import (
    TYPICAL_FRACTION,
    LineTrainConfig,
    ValidationSet,
    calibrate,
    calibrate_and_report,
    coarse_factors,
    line_targets,
    pixel_and_map,
    training_effects,
)
from stickslip.estimators.offsets import CompressionPrior, OffsetPrior, compression_moment
from stickslip.simulators import effects as fx
from stickslip.simulators.contacts import cached_contact_set, described_dataset
from stickslip.simulators.instrument import apply_instrument
from stickslip.traces.dataset import Dataset, concat_datasets

#: Multi-asperity lines simulated per seed for the calibration (:func:`contact_lines`).
CONTACT_CHUNK = 320


@dataclass(frozen=True)
class FamilyCalibration:
    """How a spread calibration on the nuisance prior was drawn.

    Attributes
    ----------
    prior : the nuisance prior the calibration lines are drawn from.
    seed : seed of the draws (effects and their realisations).
    draws : independent draws of the effects per trajectory.
    implementation : ``"train"`` (default) or ``"eval"``; evaluation sets use the other.
    offset : the offsets one line cannot tell from friction, added to the single-line
        <F> interval (:mod:`stickslip.estimators.offsets`; by default the crosstalk
        family's documented range, whether or not the prior holds that family: it is
        not fitted). Every calibration line's constant offset is drawn afresh from it
        (:func:`restate_offsets`), so the calibration of U0, K and eta, which the
        members read partly off the force's level, meets offsets at the documented
        rate even where the prior leaves crosstalk out. The calibration then fits the
        model's <F> error against the friction plus each line's offset, what the line
        shows. None: no such term, and the offsets are left to the fitted
        calibration.
    compression : compressions of large signals, which one line cannot tell from a
        softer contact, added to the single-line <F> interval (:class:`~stickslip.
        estimators.offsets.CompressionPrior`; by default the saturation family's
        documented range, whether or not the prior holds that family: it is not
        fitted). The <F> target stays the friction (plus the offset): the members were
        trained to read the friction through a compression, so their error is
        measured against it. Where the calibration's prior holds saturation the term
        is on top of the error it saw (conservative); where it does not, the term is
        what sizes it. None: no such term.
    training_draws : draws per trajectory of the members' own training effects
        (:func:`~stickslip.estimators.line.training.training_effects`, a fifth of the
        lines left clean, as in training) added to the calibration lines, weighing as
        much as the prior's lines in the pooled fit: milder lines, as a careful
        measurement records, so that their intervals are not sized by the prior's
        harshest corruptions alone (0: the prior's lines only).
    contacts : multi-asperity lines that one effective PT describes
        (:func:`~stickslip.simulators.contacts.contact_set`, kind ``"multi"``, seed
        ``contacts_seed``, paper preset; those within the misfit limit kept,
        :func:`~stickslip.simulators.contacts.described_dataset`) added to the clean
        trajectories before the effects are drawn: their truth is the PT that best
        reproduces the line, which the members, trained on single-point PT, read with
        an error their spread does not show (0: none).
    contacts_seed : seed of the first :data:`CONTACT_CHUNK` of those lines (of the next
        chunk, the seed after it, and so on).
    """

    prior: fx.NuisancePrior = dataclasses.field(default_factory=fx.NuisancePrior)
    seed: int = 5101
    draws: int = 4
    implementation: str = "train"
    training_draws: int = 4
    offset: OffsetPrior | None = dataclasses.field(
        default_factory=lambda: OffsetPrior.from_family(fx.Crosstalk())
    )
    compression: CompressionPrior | None = dataclasses.field(
        default_factory=lambda: CompressionPrior.from_family(fx.Saturation())
    )
    #: calibration lines re-pixelated coarser, as in training
    #: (:func:`~stickslip.estimators.line.training.coarse_factors`)
    coarse_fraction: float = 0.3
    contacts: int = 0
    contacts_seed: int = 5111
    #: stated contacts (other than ``"any"``) calibrated again on their own lines
    #: (:attr:`~stickslip.estimators.line.ensemble.LineEnsemble.contact_calibrations`)
    stated_contacts: tuple[str, ...] = ("ideal",)

    def to_dict(self) -> dict:
        return {"prior": self.prior.to_dict(), "seed": self.seed, "draws": self.draws,
                "coarse_fraction": self.coarse_fraction, "contacts": self.contacts,
                "contacts_seed": self.contacts_seed,
                "stated_contacts": list(self.stated_contacts),
                "implementation": self.implementation, "training_draws": self.training_draws,
                "families": list(self.prior.enabled()),
                "offset": None if self.offset is None else self.offset.to_dict(),
                "compression": (None if self.compression is None
                                else self.compression.to_dict())}  # fmt: skip


@dataclass
class FamilyLines:
    """Lines drawn from a nuisance prior, with their truths.

    ``data`` is a dataset whose force is the recorded one and whose params carry the
    truths (``U0_eV``, ``K_N_m``, ``F_mean_nN`` the contact force's mean) and the
    *stated* conditions (``velocity_nm_per_s``, ``temperature_K``), as an estimator is
    told them, and ``offset_nN`` each line's crosstalk mean (the offset one line cannot
    tell from friction); ``applied`` (n, families) says which family each line got; ``rows`` the
    source trajectory of each line.
    """

    data: Dataset
    applied: np.ndarray
    rows: np.ndarray


def draw_family_lines(clean: Dataset, prior: fx.NuisancePrior, seed: int, draws: int = 1,
                      implementation: str = "eval") -> FamilyLines:  # fmt: skip
    """``draws`` independent draws of ``prior`` on every clean trajectory of ``clean``.

    Parameters
    ----------
    clean : simulated clean trajectories with their params (a randomised set).
    prior : the nuisance prior.
    seed : seed of the draws; draw ``k`` uses the stream ``[seed, k]``.
    draws : number of draws per trajectory.
    implementation : ``"train"`` or ``"eval"`` (:data:`~stickslip.simulators.effects.
        IMPLEMENTATIONS`).
    """
    p = clean.params
    force = np.asarray(clean.force_nN, float)
    T = p.get("temperature_K", np.full(clean.n, 300.0))
    parts = []
    offsets = []
    for k in range(draws):
        rng = np.random.default_rng([seed, k])
        d = fx.draw(prior, clean.n, rng, implementation)
        record: dict[str, np.ndarray] = {}
        F, said = fx.apply(d, clean.x_nm, force, p["velocity_nm_per_s"], rng, temperature_K=T,
                           record=record)  # fmt: skip
        truth_F = fx.contact_force(d, force).mean(axis=1)
        parts.append((F, said, truth_F, d.applied))
        offsets.append(record["crosstalk"].mean(axis=1))
    rows = np.tile(np.arange(clean.n), draws)
    params = {k: np.asarray(v)[rows] for k, v in p.items() if np.ndim(v) == 1}
    params["velocity_nm_per_s"] = np.concatenate([s.velocity_nm_per_s for _, s, _, _ in parts])
    params["temperature_K"] = np.concatenate([s.temperature_K for _, s, _, _ in parts])
    params["F_mean_nN"] = np.concatenate([t for _, _, t, _ in parts])
    params["offset_nN"] = np.concatenate(offsets)
    data = Dataset(np.vstack([F for F, _, _, _ in parts]), clean.x_nm, params,
                   {**clean.attrs, "kind": f"families-{implementation}"})  # fmt: skip
    return FamilyLines(data, np.vstack([a for _, _, _, a in parts]), rows)


def restate_offsets(lines: FamilyLines, prior: OffsetPrior, seed: int) -> FamilyLines:
    """The lines with each one's constant offset drawn afresh from ``prior``.

    A constant offset is an ambiguity one line cannot resolve, documented rather than
    fitted (:mod:`stickslip.estimators.offsets`): the members read the force's level, so
    it moves U0, K and eta as well as <F>. Every calibration meets it at the documented
    rate, whether or not its prior holds the crosstalk family: each line's crosstalk
    mean (``offset_nN``) is replaced by an offset of the prior (none with probability
    ``1 - p``), and ``offset_nN`` says the new one. Crosstalk's variation along the line
    stays where the family put it.
    """
    d = lines.data
    new = prior.draw(d.n, np.random.default_rng([seed, 7]))
    old = np.asarray(d.params.get("offset_nN", np.zeros(d.n)), float)
    force = np.asarray(d.force_nN, float) + (new - old)[:, None]
    data = Dataset(force, d.x_nm, {**d.params, "offset_nN": new}, d.attrs)
    return FamilyLines(data, lines.applied, lines.rows)


def draw_training_lines(clean: Dataset, seed: int, draws: int = 1) -> FamilyLines:
    """``draws`` draws of the line model's training effects on every clean trajectory
    (:func:`~stickslip.estimators.line.training.training_effects`; a
    ``LineTrainConfig.clean_fraction`` of lines left clean). No family is applied; the
    stated conditions are the true ones and <F>'s truth is the clean mean."""
    force = np.asarray(clean.force_nN, float)
    effects = training_effects(TYPICAL_FRACTION)
    parts = []
    for k in range(draws):
        rng = np.random.default_rng([seed, 1000 + k])
        F, _ = apply_instrument(force, effects, rng)
        keep = rng.random(clean.n) < LineTrainConfig.clean_fraction
        F[keep] = force[keep]
        parts.append(F)
    rows = np.tile(np.arange(clean.n), draws)
    params = {k: np.asarray(v)[rows] for k, v in clean.params.items() if np.ndim(v) == 1}
    data = Dataset(np.vstack(parts), clean.x_nm, params, {**clean.attrs, "kind": "training"})
    return FamilyLines(data, np.zeros((rows.size, len(fx.FAMILIES)), bool), rows)


def calibration_lines(ens: LineEnsemble, lines: FamilyLines, offset: bool = False,
                      coarse_fraction: float = 0.0, seed: int = 0
                      ) -> tuple[ValidationSet, np.ndarray]:  # fmt: skip
    """The lines as the calibration reads them (a ``coarse_fraction`` re-pixelated
    coarser, draws seeded by ``seed``; mapped, conditioned on the stated velocity and
    temperature) and their targets
    (:func:`~stickslip.estimators.line.training.line_targets`); with ``offset``, the <F>
    target is the friction plus the line's crosstalk mean."""
    d, spec = lines.data, ens.spec
    p = d.params
    a = p["lattice_nm"]
    factors = coarse_factors(a, coarse_fraction, np.random.default_rng([seed, 17]), spec)
    mapped = [pixel_and_map(d.x_nm, f, ai, spec, c)
              for f, ai, c in zip(d.force_nN, a, factors, strict=True)]  # fmt: skip
    cs = ValidationSet(lines=mapped, C=conditioning(a, p["velocity_nm_per_s"], spec,
                                                 p.get("temperature_K")),
                       rows=lines.rows, strata=np.zeros(d.n, int),
                       observed_mean=d.force_nN.mean(axis=1),
                       m3_nN=compression_moment(np.asarray(d.force_nN, float)))  # fmt: skip
    # with an offset term the model answers for what the line shows: friction + offset
    F = p["F_mean_nN"] + (p["offset_nN"] if offset and "offset_nN" in p else 0.0)
    return cs, line_targets(p["U0_eV"], p["K_N_m"], F, a, spec)


def contact_lines(settings: FamilyCalibration,
                  work: str | os.PathLike | None = None) -> Dataset:  # fmt: skip
    """The described multi-asperity lines of ``settings`` (``settings.contacts`` drawn,
    those one PT describes kept; :attr:`FamilyCalibration.contacts`): chunks of
    :data:`CONTACT_CHUNK` lines on seeds ``contacts_seed``, ``contacts_seed + 1``, ...
    (the last one shorter), each cached in ``work`` where given."""
    parts = []
    for k, start in enumerate(range(0, settings.contacts, CONTACT_CHUNK)):
        n, seed = min(CONTACT_CHUNK, settings.contacts - start), settings.contacts_seed + k
        parts.append(described_dataset(*cached_contact_set(n, "multi", seed, work)))
    return concat_datasets(parts) if len(parts) > 1 else parts[0]


@dataclass
class FamilyCalibrationLines:
    """The lines a family calibration is fitted on (:func:`family_calibration_lines`).

    Attributes
    ----------
    clean : the clean trajectories, the contact lines joined where the settings ask.
    prior, prior_set, prior_Y : the nuisance prior's lines as drawn (offsets restated),
        as the calibration reads them, and their targets.
    training, training_set, training_Y : the same for the members' training effects
        (None without ``training_draws``).
    n_contact_lines : contact lines among ``clean``.
    """

    clean: Dataset
    prior: FamilyLines
    prior_set: ValidationSet
    prior_Y: np.ndarray
    training: FamilyLines | None
    training_set: ValidationSet | None
    training_Y: np.ndarray | None
    n_contact_lines: int


def family_calibration_lines(ens: LineEnsemble, clean: Dataset, settings: FamilyCalibration,
                             contacts: Dataset | None = None) -> FamilyCalibrationLines:
    """Draw and read the calibration lines of ``settings`` on the clean trajectories
    ``clean`` (:func:`calibrate_on_families` fits on them; ``benchmarks/u0_width.py``
    reads them). ``contacts``: the lines of :func:`contact_lines` where already made
    (simulated here when ``settings.contacts`` asks for them and none are given); they
    join ``clean``."""
    n_contacts = 0
    if settings.contacts:
        contacts = contact_lines(settings) if contacts is None else contacts
        n_contacts = contacts.n
        # the truths and conditions both hold (a pool may lack the dynamics columns)
        clean = concat_datasets([clean, contacts],
                                columns=[k for k in contacts.params if k in clean.params])
    lines = draw_family_lines(clean, settings.prior, settings.seed, settings.draws,
                              settings.implementation)  # fmt: skip
    if settings.offset is not None:
        lines = restate_offsets(lines, settings.offset, settings.seed)
    cs, Y = calibration_lines(ens, lines, offset=settings.offset is not None,
                              coarse_fraction=settings.coarse_fraction, seed=settings.seed)
    mild = mild_set = Y_mild = None
    if settings.training_draws:
        mild = draw_training_lines(clean, settings.seed, settings.training_draws)
        mild_set, Y_mild = calibration_lines(ens, mild, coarse_fraction=settings.coarse_fraction,
                                             seed=settings.seed + 1)  # fmt: skip
    return FamilyCalibrationLines(clean, lines, cs, Y, mild, mild_set, Y_mild, n_contacts)


def calibrate_on_families(ens: LineEnsemble, clean: Dataset,
                          settings: FamilyCalibration | None = None,
                          contacts: Dataset | None = None) -> dict:  # fmt: skip
    """Re-fit the spread calibration of ``ens`` (in place) on lines drawn from the
    nuisance prior on the clean trajectories ``clean``; the members are unchanged.

    Keeps the model's classes of lines and its power law. Returns the calibration
    report (:func:`~stickslip.estimators.line.training.calibrate_and_report`) with the
    settings under ``"family_calibration"``. ``contacts``: the lines of
    :func:`contact_lines` where already made (simulated here when
    ``settings.contacts`` asks for them and none are given); they join ``clean``
    (:func:`family_calibration_lines`).
    """
    settings = settings or FamilyCalibration()
    parts = family_calibration_lines(ens, clean, settings, contacts)
    cs, Y = parts.prior_set, parts.prior_Y
    # the calibration lines that carry each family (training draws, if any, carry none)
    groups = {f: parts.prior.applied[:, j] for j, f in enumerate(fx.FAMILIES)}
    if parts.training_set is not None:
        mild, Y_mild = parts.training_set, parts.training_Y
        cs = ValidationSet(lines=cs.lines + mild.lines, C=torch.cat([cs.C, mild.C]),
                           rows=np.concatenate([cs.rows, mild.rows]),
                           strata=np.concatenate([cs.strata, np.ones(len(mild.lines), int)]),
                           observed_mean=np.concatenate([cs.observed_mean,
                                                         mild.observed_mean]),
                           m3_nN=np.concatenate([cs.m3_nN, mild.m3_nN]))  # fmt: skip
        Y = np.concatenate([Y, Y_mild])
        groups = {f: np.concatenate([m, np.zeros(len(mild.lines), bool)])
                  for f, m in groups.items()}  # fmt: skip
    power = ens.exponent is not None and not np.allclose(ens.exponent, 1.0)
    ens.offset, ens.compression = settings.offset, settings.compression
    report = calibrate_and_report(ens, cs, Y, ens.classes, power, groups)
    report["family_calibration"] = {**settings.to_dict(), "n_trajectories": parts.clean.n,
                                    "n_contact_lines": parts.n_contact_lines,
                                    "clean_fingerprint": parts.clean.fingerprint()}  # fmt: skip
    ens.contact_calibrations = {}
    for name in settings.stated_contacts:
        keep = contact_rows(name, clean, parts.n_contact_lines)[cs.rows]
        report["family_calibration"][f"n_lines_{name}"] = int(keep.sum())
        if keep.sum() < MIN_STATED_LINES:  # too few to size an interval on
            continue
        # a shallow copy: calibrate() rebinds the fields it fits; the members are shared
        stated = copy.copy(ens)
        # the members' mean keeps the location fitted on every line: a stated contact
        # sizes the intervals, it does not move the estimates
        calibrate(stated, subset_lines(cs, keep), Y[keep], ens.classes, power,
                  location=False)
        ens.contact_calibrations[name] = stated.calibration_state()
    return report


#: Fewest calibration lines a stated contact's calibration is fitted on.
MIN_STATED_LINES = 200


def contact_rows(contact: str, clean: Dataset, n_contacts: int = 0) -> np.ndarray:
    """Which calibration trajectories have the stated ``contact``: the pool's ``clean``
    rows, then ``n_contacts`` multi-asperity contact lines. ``"ideal"``: a single-point
    contact on a substrate without modulation or defects
    (:class:`~stickslip.simulators.config.SubstrateAugmentation`)."""
    if contact != "ideal":
        raise ValueError(f"no calibration lines for the contact '{contact}'")
    p = clean.params
    plain = np.ones(clean.n, bool)
    for key in ("mod_amplitude", "defect_count"):
        if key in p:
            plain &= np.asarray(p[key], float) == 0
    return np.concatenate([plain, np.zeros(n_contacts, bool)])


def subset_lines(cs: ValidationSet, keep: np.ndarray) -> ValidationSet:
    """The calibration lines ``keep`` (boolean mask) of ``cs``."""
    idx = np.flatnonzero(keep)
    return ValidationSet(lines=[cs.lines[i] for i in idx], C=cs.C[torch.from_numpy(idx)],
                         rows=cs.rows[idx], strata=cs.strata[idx],
                         observed_mean=cs.observed_mean[idx],
                         m3_nN=None if cs.m3_nN is None else cs.m3_nN[idx])  # fmt: skip
