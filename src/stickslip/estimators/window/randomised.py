"""Training data for the paper's window MLPs from the domain-randomised line-model set.

The whole-line CNN (:mod:`stickslip.estimators.line.training`) is trained on a
domain-randomised set (many lattices, velocities and substrates, see
:mod:`stickslip.simulators.randomised`) with detector effects redrawn for every batch.
The paper's window MLPs (:mod:`stickslip.estimators.window.training`) train on a static
:class:`~stickslip.traces.dataset.Dataset` of equally long traces on one lattice. To
compare the two on equal data, :func:`randomised_window_set` turns the randomised set
into such a dataset, the way the line model sees it:

- each clean trace is corrupted with the line model's detector effects
  (:data:`~stickslip.estimators.line.training.TRAIN_EFFECTS` through
  :func:`~stickslip.simulators.instrument.apply_instrument`), a ``clean_fraction`` of
  them left clean, as in :func:`~stickslip.estimators.line.training.prepare_batch`;
- it is then mapped onto the reference lattice and pixel with
  :func:`~stickslip.estimators.line.ensemble.map_line` (positions divided by ``s = a / a0``,
  forces kept, pixel means);
- the labels move to the reference frame: ``U0' = U0 / s``, ``K' = K s``; ``<F>`` and
  eta are unchanged;
- every trajectory gives ``replicas`` rows with independent corruption draws, so the
  static MLP pipeline sees varied corruption. All rows of a trajectory share its group
  id (``params["trajectory"]``); :func:`split_by_group` keeps a group on one side of the
  train/validation split.

Mapped lines are shorter on larger lattices (512 pixels at a = 0.335 nm map onto 375
reference pixels), so every row is cropped to a common length (by default the shortest
mapped line of the set) at a random offset.
"""

from __future__ import annotations

import json
from dataclasses import asdict

import numpy as np

from stickslip.estimators.line.ensemble import LineSpec, map_line
from stickslip.estimators.line.training import TRAIN_EFFECTS, LineTrainConfig
from stickslip.estimators.window.training import split_by_trajectory
from stickslip.simulators.instrument import InstrumentEffects, apply_instrument
from stickslip.traces.dataset import Dataset
from stickslip.units import eta_from

KIND = "randomised-windows"


def randomised_window_set(
    data: Dataset,
    replicas: int = 3,
    spec: LineSpec | None = None,
    effects: InstrumentEffects = TRAIN_EFFECTS,
    clean_fraction: float = LineTrainConfig.clean_fraction,
    seed: int = 0,
    pixels: int | None = None,
) -> Dataset:
    """Corrupted, mapped replicas of a randomised set, labelled in the reference frame.

    Parameters
    ----------
    data : Dataset
        Clean simulated traces on any lattice (e.g. the domain-randomised set of
        :func:`stickslip.simulators.randomised.make_randomised_set`). ``params`` needs
        ``U0_eV``, ``K_N_m``, ``F_mean_nN`` and ``lattice_nm`` per trace.
    replicas : int
        Independent corruption draws (rows) per trajectory.
    spec : LineSpec, optional
        Reference lattice and pixel of the mapping (default: the line model's
        ``LineSpec()``).
    effects : InstrumentEffects
        Detector-effect ranges (default: the line model's training effects).
    clean_fraction : float
        Probability that a row is left without detector effects (default: the line
        model's, 0.2).
    seed : int
        Seed of the corruption draws and the crop offsets.
    pixels : int, optional
        Length of every row in reference pixels (default: the shortest mapped line).

    Returns
    -------
    Dataset
        ``replicas * data.n`` rows, replica-major (row ``r * data.n + i`` is replica
        ``r`` of trajectory ``i``). ``x_nm`` is the reference pixel grid. ``params``
        holds the source's per-trajectory columns repeated, with ``U0_eV`` and
        ``K_N_m`` in the reference frame, ``lattice_nm`` the reference lattice, and
        ``eta`` recomputed there (unchanged up to rounding), plus ``source_lattice_nm``,
        ``source_U0_eV``, ``source_K_N_m``, ``trajectory`` (the source row: the group
        id), ``replica`` and ``clean`` (no detector effects).

    Raises
    ------
    ValueError
        If ``replicas < 1``, ``clean_fraction`` is outside [0, 1], or a mapped line is
        shorter than ``pixels``.
    """
    if replicas < 1:
        raise ValueError(f"replicas must be at least 1 (got {replicas})")
    if not 0.0 <= clean_fraction <= 1.0:
        raise ValueError(f"clean_fraction must be in [0, 1] (got {clean_fraction})")
    spec = spec or LineSpec()
    rng = np.random.default_rng(seed)
    n = data.n
    clean_force = np.asarray(data.force_nN, dtype=float)
    a = np.asarray(data.params["lattice_nm"], dtype=float)
    lines: list[np.ndarray] = []
    clean_rows: list[np.ndarray] = []
    for _ in range(replicas):
        # the line model's batch corruption (prepare_batch): effects, then a clean subset
        F, _ = apply_instrument(clean_force, effects, rng)
        clean = rng.random(n) < clean_fraction
        F[clean] = clean_force[clean]
        clean_rows.append(clean)
        lines += [map_line(data.x_nm, f, ai, spec) for f, ai in zip(F, a, strict=True)]
    shortest = min(f.size for f in lines)
    length = shortest if pixels is None else int(pixels)
    if length > shortest:
        raise ValueError(f"a mapped line has {shortest} pixels, fewer than pixels={length}")
    force = np.empty((len(lines), length), np.float32)
    for i, f in enumerate(lines):
        start = int(rng.integers(0, f.size - length + 1))
        force[i] = f[start : start + length]

    s = a / spec.lattice_nm
    params = {k: np.concatenate([np.asarray(v)] * replicas) for k, v in data.params.items()}
    U0_ref = np.tile(np.asarray(data.params["U0_eV"], float) / s, replicas)
    K_ref = np.tile(np.asarray(data.params["K_N_m"], float) * s, replicas)
    params.update(
        source_lattice_nm=params["lattice_nm"],
        source_U0_eV=params["U0_eV"],
        source_K_N_m=params["K_N_m"],
        U0_eV=U0_ref,
        K_N_m=K_ref,
        lattice_nm=np.full(U0_ref.size, spec.lattice_nm),
        eta=eta_from(U0_ref, K_ref, spec.lattice_nm),
        trajectory=np.tile(np.arange(n), replicas),
        replica=np.repeat(np.arange(replicas), n),
        clean=np.concatenate(clean_rows),
    )
    config = {
        "replicas": replicas,
        "clean_fraction": clean_fraction,
        "seed": seed,
        "pixels": length,
        "spec": spec.to_dict(),
        "effects": asdict(effects),
        "source_config": data.config_json,
        "source_fingerprint": data.fingerprint(),
    }
    attrs = {"kind": KIND, "config": json.dumps(config, sort_keys=True), "seed": seed,
             "n": len(lines), "pixels": length}  # fmt: skip
    return Dataset(
        force_nN=force,
        x_nm=np.arange(length) * spec.pixel_nm,
        params=params,
        attrs=attrs,
    )


def split_by_group(
    groups: np.ndarray, val_fraction: float = 0.2, seed: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """Rows split into (train, validation) so that no group is on both sides.

    The groups (e.g. ``params["trajectory"]`` of :func:`randomised_window_set`) are
    split with :func:`stickslip.estimators.window.training.split_by_trajectory` (seeded, the
    given fraction of groups to validation); each row follows its group.

    Parameters
    ----------
    groups : ndarray (N,)
        Group id of every row.
    val_fraction : float
        Fraction of the groups held out for validation.
    seed : int
        Seed of the split.

    Returns
    -------
    train_idx, val_idx : ndarray
        Sorted row indices, for ``train_model(..., train_idx=, val_idx=)``.
    """
    groups = np.asarray(groups)
    ids, inverse = np.unique(groups, return_inverse=True)
    g_train, _ = split_by_trajectory(ids.size, val_fraction, seed)
    in_train = np.isin(inverse, g_train)
    return np.flatnonzero(in_train), np.flatnonzero(~in_train)
