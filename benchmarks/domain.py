"""The in/out-of-domain verdict: its rates on PT and non-PT traces, and what it costs.

Sets (each drawn from a seed; the verdict's thresholds were tuned on seed 1 and its lab
bench on seed ``BENCH_SEED + 1``, the figures are reported on other seeds):

- non-PT traces (must come out of domain), stated lattice 0.246 nm, 11 nm as 512 px:
  white noise, a random walk, flat lines, square waves, a reversed sawtooth (PT traces
  reversed in x or sign-flipped: slow fall, sudden rise), smooth sliding (simulated
  with 0.2 <= eta <= 0.95), and single-slip stick-slip simulated on a lattice 0.6x
  the stated one (0.1476 nm, stated 0.246). The simulated ones carry the lab bench's
  instrument effects on half of their lines;
- PT traces (must stay in domain): clean paper-preset simulations (the training range,
  1.2 <= eta <= 40), the lab bench (:mod:`stickslip.simulators.bench`: three
  lattices, 30 nm/s, modulation, defects, detector effects), and the clean set with one
  draw of the nuisance prior's effect families (:mod:`stickslip.simulators.effects`,
  ``"eval"`` implementation, every family at its documented probability).

Prints, per set, the fraction of rows in domain with the line model (the default) and
the classical estimator, the reasons given, and the smooth-sliding rows in domain per
band of their true eta (clean and lab-effect lines apart); on the sets with truths, the
factor by which the line model's out-of-domain rows' 95 % intervals had to be widened to
cover 95 % of the truths (the verdict's widening factors are chosen from it on seed 1);
and the line model's throughput (:meth:`LineEstimator.predict` on ``--n-speed`` traces)
with and without the verdict, timed alternately in the same sitting, and the machine.
Sets are cached under ``--work`` (default build/domain, git-ignored).

``--write-reference`` fits the line model's embedding reference and its contact probe
(:func:`write_reference`) and writes them to ``src/stickslip/resources/line_domain.npz``.

Usage: python benchmarks/domain.py [--seed 2] [--bench-seed 20261121] [--n 200]
       [--n-speed 5000] [--repeats 3] [--threads 2] [--work build/domain] [--skip-speed]
       [--speed-only] [--eta-confirm X]
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from collections import Counter
from pathlib import Path

import numpy as np
import torch

from stickslip.estimators.table import domain_verdict
from stickslip.simulators import PhysicalSettings, simulate
from stickslip.simulators import effects as fx
from stickslip.simulators.bench import BENCH_SEED, BenchConfig, bench_if_missing
from stickslip.simulators.config import ParameterRange
from stickslip.simulators.instrument import LAB, apply_instrument
from stickslip.simulators.sampling import sample_parameters
from stickslip.traces.dataset import dataset_traces, load_dataset
from stickslip.traces.trace import Trace
from stickslip.units import eta_from

ROOT = Path(__file__).resolve().parents[1]
LATTICE_NM = 0.246
NON_PT = ("white_noise", "random_walk", "flat", "square_wave", "reversed_sawtooth",
          "smooth_sliding", "lattice_0.6")  # fmt: skip
PT = ("clean", "lab_bench", "families")
#: Sets whose traces carry truths (the widening of out-of-domain rows is measured on them).
TRUTH_SETS = ("smooth_sliding", "lattice_0.6", *PT)
X_NM = np.arange(512) * (11.0 / 512)


def _loguniform(rng: np.random.Generator, lo: float, hi: float, n: int) -> np.ndarray:
    return np.exp(rng.uniform(np.log(lo), np.log(hi), n))


def _lab_half(force: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """The lab bench's instrument effects on every other line (the rest stay clean)."""
    out = force.copy()
    out[1::2] = apply_instrument(force[1::2], LAB, rng)[0]
    return out


def _simulated(U0: np.ndarray, K: np.ndarray, seed: int, lattice_nm: float
               ) -> dict[str, np.ndarray]:  # fmt: skip
    """Clean paper-preset lines on ``lattice_nm`` with their truths."""
    n = U0.size
    f = simulate(U0, K, PhysicalSettings(), seed=seed, lattice_nm=np.full(n, lattice_nm)).force_nN
    return {"force_nN": f, "U0_eV": U0, "K_N_m": K, "eta": eta_from(U0, K, lattice_nm),
            "F_mean_nN": f.mean(axis=1)}  # fmt: skip


def _pt_lines(n: int, seed: int, eta: tuple[float, float], lattice_nm: float
              ) -> dict[str, np.ndarray]:  # fmt: skip
    U0, K = sample_parameters(ParameterRange(eta=eta), n, seed, lattice_nm)
    return _simulated(U0, K, seed, lattice_nm)


def non_pt_set(kind: str, n: int, seed: int) -> dict[str, np.ndarray]:
    """``n`` lines (n, 512) of one non-PT kind, read at the stated lattice 0.246 nm
    (``force_nN``), with the truths of the simulated kinds (``U0_eV``, ``K_N_m``, ``eta``
    and ``F_mean_nN``, the clean line's mean; NaN for the others)."""
    rng = np.random.default_rng([seed, NON_PT.index(kind)])
    p = X_NM.size
    mean = rng.uniform(-1.0, 3.0, (n, 1))
    f = None
    if kind == "white_noise":
        f = mean + _loguniform(rng, 0.01, 2.0, n)[:, None] * rng.standard_normal((n, p))
    elif kind == "random_walk":
        step = _loguniform(rng, 0.003, 0.3, n)[:, None]
        f = mean + np.cumsum(step * rng.standard_normal((n, p)), axis=1)
    elif kind == "flat":
        slope = rng.uniform(-0.02, 0.02, (n, 1)) * X_NM[None, :]
        f = mean + slope + _loguniform(rng, 1e-5, 3e-3, n)[:, None] * rng.standard_normal((n, p))
    elif kind == "square_wave":
        period = _loguniform(rng, 0.2, 4.0, n)[:, None]
        duty = rng.uniform(0.3, 0.7, (n, 1))
        phase = rng.random((n, 1))
        amp = _loguniform(rng, 0.1, 3.0, n)[:, None]
        wave = amp * (((X_NM[None, :] / period + phase) % 1.0) < duty)
        f = mean + wave + 0.05 * amp * rng.random((n, 1)) * rng.standard_normal((n, p))
    if f is not None:
        return {"force_nN": f, **{k: np.full(n, np.nan) for k in TRUTHS}}
    if kind == "reversed_sawtooth":
        out = _pt_lines(n, seed, (1.5, 40.0), LATTICE_NM)
        f = _lab_half(out["force_nN"], rng)
        f[::2] = f[::2, ::-1]  # reversed in x: slow fall, sudden rise
        f[1::2] = -f[1::2]  # sign-flipped: the same shape, negative friction
        return {"force_nN": f, **{k: np.full(n, np.nan) for k in TRUTHS}}
    if kind == "smooth_sliding":
        K = rng.uniform(5.0, 80.0, n)
        U0 = rng.uniform(0.2, 0.95, n) * K / eta_from(1.0, 1.0, LATTICE_NM)
        out = _simulated(U0, K, seed, LATTICE_NM)
    elif kind == "lattice_0.6":
        out = _pt_lines(n, seed, (1.5, 4.6), 0.6 * LATTICE_NM)
    else:
        raise ValueError(kind)
    out["force_nN"] = _lab_half(out["force_nN"], rng)
    return out


TRUTHS = ("U0_eV", "K_N_m", "eta", "F_mean_nN")


def _cached(path: Path, make) -> dict[str, np.ndarray]:
    if not path.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(path.with_name(path.name + ".partial"), "wb") as fh:
            np.savez(fh, **make())
        os.replace(path.with_name(path.name + ".partial"), path)
    with np.load(path) as z:
        return dict(z)


def _traces(data: dict[str, np.ndarray], name: str) -> list[Trace]:
    """Traces at the stated lattice 0.246 nm and 60 nm/s, truths in ``meta``."""
    out = []
    for i, row in enumerate(data["force_nN"]):
        meta = {"lattice_nm": LATTICE_NM, "velocity_nm_per_s": 60.0}
        meta.update({k: float(data[k][i]) for k in TRUTHS if k in data})
        out.append(Trace(X_NM.copy(), row.astype(float), f"{name}:{i:04d}", name, meta))
    return out


def non_pt_traces(kind: str, n: int, seed: int, work: Path) -> list[Trace]:
    """Traces of one non-PT kind (cached under ``work``)."""
    return _traces(_cached(work / f"{kind}_{n}_{seed}.npz", lambda: non_pt_set(kind, n, seed)),
                   kind)  # fmt: skip


def clean_traces(n: int, seed: int, work: Path) -> list[Trace]:
    """Clean paper-preset simulations over the training range (cached under ``work``)."""
    data = _cached(work / f"clean_{n}_{seed}.npz",
                   lambda: _pt_lines(n, seed, ParameterRange().eta, LATTICE_NM))  # fmt: skip
    return _traces(data, "clean")


def bench_traces(n_per_material: int, seed: int, work: Path) -> list[Trace]:
    """The lab bench of ``seed`` (cached under ``work``), with its lattices and velocity."""
    path = bench_if_missing(BenchConfig(n_per_material=n_per_material, seed=seed),
                            work / f"bench_{n_per_material}_{seed}.h5")  # fmt: skip
    return dataset_traces(load_dataset(path), name="bench")


# -- the line model's embedding reference (--write-reference) --------------------------
#: Training-like simulations behind the reference: the line model's randomised training
#: distribution, its typical laboratory substrate, and paper-preset lines, each on
#: seeds of their own (training used 101, 104 and 0).
REFERENCE_SEEDS = {"randomised": 7001, "lab": 7002, "paper": 7003, "effects": 7004}
REFERENCE_SIZES = {"randomised": 600, "lab": 300, "paper": 240}
EFFECT_DRAWS = 3  # draws of the detector effects per trajectory
FAMILY_DRAWS = 2  # draws of the nuisance prior's effect families per trajectory
CLEAN_FRACTION = 0.2  # of each draw, left without detector effects (as in training)
HOLD_OUT = 0.2  # of the reference trajectories: set the limit, not the moments


def reference_traces(work: Path) -> tuple[list[Trace], np.ndarray]:
    """Training-like lines (simulations cached under ``work``) and the trajectory each
    comes from. Every trajectory gives :data:`EFFECT_DRAWS` lines with the training
    prior's detector effects (:func:`~stickslip.estimators.line.training.training_effects`,
    a :data:`CLEAN_FRACTION` left clean), and those on a flat substrate one pristine line
    more, as training's pristine lines."""
    from stickslip.jobs.train import BundledRecipe
    from stickslip.simulators.randomised import RandomisedConfig, cached_randomised_set, lab_config

    n, seed = REFERENCE_SIZES, REFERENCE_SEEDS
    configs = [RandomisedConfig(n=n["randomised"], seed=seed["randomised"]),
               lab_config(n["lab"], seed["lab"])]  # fmt: skip
    # the training prior's dynamics and acquisition
    configs = [BundledRecipe().prior(c) for c in configs]
    parts = []
    for config in configs:
        data = cached_randomised_set(config, work, progress=False)
        p = data.params
        flat = (np.asarray(p["mod_amplitude"]) == 0) & (np.asarray(p["defect_count"]) == 0)
        parts.append((np.asarray(data.x_nm, float), np.asarray(data.force_nN, float),
                      np.asarray(p["lattice_nm"], float),
                      np.asarray(p["velocity_nm_per_s"], float), flat,
                      np.asarray(p["temperature_K"], float)))  # fmt: skip
    n_p, seed_p = REFERENCE_SIZES["paper"], REFERENCE_SEEDS["paper"]
    paper = _cached(work / f"paper_{n_p}_{seed_p}.npz",
                    lambda: _pt_lines(n_p, seed_p, ParameterRange().eta, LATTICE_NM))  # fmt: skip
    parts.append((X_NM, paper["force_nN"], np.full(n_p, LATTICE_NM), np.full(n_p, 60.0),
                  np.ones(n_p, bool), np.full(n_p, 296.0)))  # fmt: skip
    return with_effects(parts, np.random.default_rng(REFERENCE_SEEDS["effects"]), "reference")


def with_effects(parts: list[tuple], rng: np.random.Generator, source: str
                 ) -> tuple[list[Trace], np.ndarray]:  # fmt: skip
    """Every line of ``parts`` (each ``(x, F, lattice, velocity, flat, temperature)``,
    per-line arrays but ``x``) as training recorded it: :data:`EFFECT_DRAWS` lines with
    the training prior's detector effects (a :data:`CLEAN_FRACTION` left clean), the
    line itself where ``flat`` (a pristine line), and :data:`FAMILY_DRAWS` lines with the
    nuisance prior's effect families; with the index of the line each comes from."""
    from stickslip.estimators.line.training import TYPICAL_FRACTION, training_effects

    effects = training_effects(TYPICAL_FRACTION)
    traces, owner = [], []
    first = 0
    for x, F, a, v, flat, T in parts:
        draws = []
        for _ in range(EFFECT_DRAWS):
            noisy = apply_instrument(F, effects, rng)[0]
            keep = rng.random(F.shape[0]) < CLEAN_FRACTION
            noisy[keep] = F[keep]
            draws.append((np.arange(F.shape[0]), noisy, v, T))
        draws.append((np.flatnonzero(flat), F[flat], v, T))
        # and the broad nuisance prior (effect families, "train" implementation): lines a
        # lab records carry them, and the calibration is fitted on them
        for _ in range(FAMILY_DRAWS):
            d = fx.draw(fx.NuisancePrior(), F.shape[0], rng, "train")
            noisy, said = fx.apply(d, x, F, v, rng, temperature_K=T)
            draws.append((np.arange(F.shape[0]), noisy, said.velocity_nm_per_s,
                          said.temperature_K))  # fmt: skip
        for rows, forces, vel, temp in draws:
            for i, f in zip(rows, forces, strict=True):
                traces.append(Trace(x, f, f"{source}:{first + i}", source,
                                    {"lattice_nm": float(a[i]),
                                     "velocity_nm_per_s": float(vel[i]),
                                     "temperature_K": float(temp[i])}))  # fmt: skip
                owner.append(first + i)
        first += F.shape[0]
    return traces, np.array(owner)


#: Multi-asperity contact lines behind the contact probe: sets of
#: :data:`PROBE_SET_SIZE` lines (:func:`~stickslip.simulators.contacts.contact_set`), each
#: at recording and dynamics drawn from the training prior's ranges, on seeds
#: ``PROBE_SEED + j`` used by nothing else (the calibration's contact lines: 5111 on, the
#: contact benchmark's: 4401 on).
PROBE_SEED = 7101
PROBE_SETS = 24
PROBE_SET_SIZE = 100
#: (pixels, length in nm) of the probe's sets, in turn (cost grows with the length).
PROBE_SCANS = ((512, 11.0), (256, 5.5), (1024, 11.0), (512, 5.5), (256, 11.0), (1024, 22.0))


def probe_settings(j: int) -> PhysicalSettings:
    """The recording and dynamics of the probe's contact set ``j``: temperature 250-350 K,
    velocity 30-200 nm/s (log-uniform), damping 0.3-3x and mass 0.5-2x the preset's
    (log-uniform), graphite or MoS2, and a scan of :data:`PROBE_SCANS`."""
    rng = np.random.default_rng([PROBE_SEED, j])
    px, length = PROBE_SCANS[j % len(PROBE_SCANS)]
    return PhysicalSettings(
        temperature_K=float(rng.uniform(250.0, 350.0)),
        velocity_nm_per_s=float(_loguniform(rng, 30.0, 200.0, 1)[0]),
        damping_per_s=1e7 * float(_loguniform(rng, 0.3, 3.0, 1)[0]),
        mass_kg=1e-12 * float(_loguniform(rng, 0.5, 2.0, 1)[0]),
        lattice_nm=(0.246, 0.316)[j % 2], pixels=px, length_nm=length,
    )  # fmt: skip


def probe_contacts(work: Path) -> list[dict[str, np.ndarray]]:
    """The probe's multi-asperity sets (simulated once, cached under ``work``): per set
    ``x_nm``, ``force_nN`` (Langevin, at the set's temperature), ``misfit``, ``U0_eV`` and
    ``K_N_m`` (of the effective PT fit to the T = 0 waveform) and the set's lattice,
    velocity and temperature."""
    from stickslip.simulators.contacts import contact_set

    def make(j: int) -> dict[str, np.ndarray]:
        s = probe_settings(j)
        c = contact_set(PROBE_SET_SIZE, "multi", PROBE_SEED + j, s)
        return {"x_nm": c.x_nm, "force_nN": c.force_nN,
                "misfit": np.asarray(c.truth["misfit_fraction"], float),
                "U0_eV": np.asarray(c.truth["U0_eV"], float),
                "K_N_m": np.asarray(c.truth["K_N_m"], float),
                "lattice_nm": np.float64(s.lattice_nm),
                "velocity_nm_per_s": np.float64(s.velocity_nm_per_s),
                "temperature_K": np.float64(s.temperature_K)}  # fmt: skip

    return [_cached(work / f"probe_multi_{PROBE_SET_SIZE}_{PROBE_SEED + j}.npz",
                    lambda j=j: make(j)) for j in range(PROBE_SETS)]  # fmt: skip


def probe_points(work: Path) -> list[dict[str, np.ndarray]]:
    """Single-point PT lines beside each of the probe's contact sets (cached under
    ``work``): :data:`PROBE_SET_SIZE` lines at the set's recording and dynamics
    (:func:`probe_settings`), (U0, K) uniform in the contact sets' box, so that the
    conditions tell the probe nothing; ``x_nm``, ``force_nN``, ``U0_eV``, ``K_N_m``."""
    from stickslip.simulators import contacts as ct

    def make(j: int) -> dict[str, np.ndarray]:
        s = probe_settings(j)
        rng = np.random.default_rng([PROBE_SEED, j, 1])
        U0, K = [], []
        while len(U0) < PROBE_SET_SIZE:
            u, k = rng.uniform(*ct.SET_U0_EV), rng.uniform(*ct.SET_K_N_M)
            if ct.SET_ETA[0] <= float(eta_from(u, k, s.lattice_nm)) <= ct.SET_ETA[1]:
                U0.append(u)
                K.append(k)
        res = simulate(np.array(U0), np.array(K), s, seed=PROBE_SEED * 100 + j)
        return {"x_nm": np.asarray(res.x_nm, float), "force_nN": res.force_nN,
                "U0_eV": np.array(U0), "K_N_m": np.array(K)}

    return [_cached(work / f"probe_points_{PROBE_SET_SIZE}_{PROBE_SEED + j}.npz",
                    lambda j=j: make(j)) for j in range(PROBE_SETS)]  # fmt: skip


#: Share of held-out single-point lines the contact probe may flag (its limit's level).
PROBE_LEVEL = 0.99
#: Misfits (of the effective PT to the T = 0 waveform) of the probe's two classes: no
#: single PT describes a line above the first (several contacts); one describes it well
#: below the second (a described contact, with the single-point lines). Lines between
#: are left out of the fit.
PROBE_MISFIT = (0.05, 0.01)


def probe_traces(work: Path) -> tuple[list[Trace], np.ndarray, np.ndarray]:
    """The probe's lines with the reference lines' effects (:func:`with_effects`): its
    contact lines that no single PT describes (group 1) or that one describes well (2)
    and its single-point lines (3), between them every kind at every setting; each
    line's group and the clean line it comes from."""
    parts, group = [], []
    for d, pts in zip(probe_contacts(work), probe_points(work), strict=True):
        several = d["misfit"] > PROBE_MISFIT[0]
        described = d["misfit"] <= PROBE_MISFIT[1]
        F = np.vstack([d["force_nN"][several | described], pts["force_nN"]])
        n = F.shape[0]
        parts.append((d["x_nm"], F, np.full(n, float(d["lattice_nm"])),
                      np.full(n, float(d["velocity_nm_per_s"])), np.ones(n, bool),
                      np.full(n, float(d["temperature_K"]))))  # fmt: skip
        group.append(np.concatenate([np.where(several[several | described], 1, 2),
                                     np.full(pts["force_nN"].shape[0], 3)]))  # fmt: skip
    traces, owner = with_effects(parts, np.random.default_rng(PROBE_SEED), "probe")
    return traces, np.concatenate(group)[owner], owner


def _features(line, traces: list[Trace]) -> np.ndarray:
    from stickslip.estimators.line.estimator import pooled_features

    meta = [[t.meta[k] for t in traces] for k in ("lattice_nm", "velocity_nm_per_s",
                                                  "temperature_K")]  # fmt: skip
    return pooled_features(line.ensemble, [t.x_nm for t in traces],
                           [t.force_nN for t in traces], *map(np.array, meta))[1]  # fmt: skip


def write_reference(work: Path, out: Path, level: float = 0.995) -> None:
    """Fit the bundled line model's :class:`EmbeddingReference` and its contact probe and
    write them to ``out``.

    The moments come from the lines of 80 % of the reference trajectories, the limit
    (the ``level`` quantile of the distance) from the other 20 %. The probe
    (:class:`~stickslip.estimators.domain.ContactProbe`) is fitted on the same 80 % and
    on 80 % of the probe's contact lines (:func:`probe_traces`; classes weighing
    equally, and within the single-point class the reference lines and the described
    contact lines), its penalty chosen on the other 20 %, its limit the
    :data:`PROBE_LEVEL` quantile of the held-out reference lines.
    """
    from stickslip.estimators.domain import ContactProbe, EmbeddingReference
    from stickslip.estimators.line.estimator import fingerprint
    from stickslip.estimators.load import load_estimator

    line = load_estimator(None)
    traces, owner = reference_traces(work)
    feats = _features(line, traces)
    held = np.random.default_rng(REFERENCE_SEEDS["effects"]).random(owner.max() + 1) < HOLD_OUT
    test = held[owner]
    ref = EmbeddingReference.fit(feats[:, ~test], fingerprint(line.ensemble), level=level)
    in_sample = ref.limit
    ref.set_limit(feats[:, test], level)
    ptraces, group, powner = probe_traces(work)
    pfeats = _features(line, ptraces)
    pheld = np.random.default_rng(PROBE_SEED).random(powner.max() + 1) < HOLD_OUT
    ptest = pheld[powner]
    y = np.concatenate([np.zeros(test.size), (group == 1).astype(float)])
    # the classes weigh equally; within the single-point class the reference lines, the
    # described contact lines and the single-point lines at the contacts' settings
    share = {1: 1.0, 2: 1.0 / 3.0, 3: 1.0 / 3.0}
    w = np.concatenate([np.full(test.size, 1.0 / 3.0 / test.size),
                        [share[g] / np.sum(group == g) for g in group]])  # fmt: skip
    val = np.concatenate([test, ptest])
    allf = np.concatenate([feats, pfeats], axis=1)
    probe = ContactProbe.fit(allf, y, w, val)
    probe.set_limit(feats[:, test], PROBE_LEVEL)
    ref.probe = probe
    ref.save(out)
    print(f"embedding reference: {int((~test).sum())} lines fit the moments, {int(test.sum())} "
          f"held-out lines set the {level:.1%} limit {ref.limit:.3f} (in-sample "
          f"{in_sample:.3f}); written to {out} ({out.stat().st_size / 1024:.0f} KiB)")
    flagged = probe.log_odds(pfeats[:, ptest]) > probe.limit
    g = group[ptest]
    print(f"contact probe: {len(ptraces)} probe lines ({int(np.sum(group == 1))} of contacts no "
          f"single PT describes), penalty {probe.penalty:g}; held out, it flags "
          + ", ".join(f"{flagged[g == k].mean():.3f} of {int(np.sum(g == k))} {name}"
                      for k, name in ((1, "several-contact lines"),
                                      (2, "described contact lines"),
                                      (3, "single-point lines at their settings")))
          + f" and {1 - PROBE_LEVEL:.3f} of the reference lines (its limit)")  # fmt: skip


def family_traces(n: int, seed: int, work: Path) -> list[Trace]:
    """The clean set with one draw of the nuisance prior's effect families, ``"eval"``
    implementation (the estimator is told the stated velocity)."""
    data = _cached(work / f"clean_{n}_{seed}.npz",
                   lambda: _pt_lines(n, seed, ParameterRange().eta, LATTICE_NM))  # fmt: skip
    rng = np.random.default_rng([seed, 31])
    d = fx.draw(fx.NuisancePrior(), n, rng, "eval")
    force, said = fx.apply(d, X_NM, data["force_nN"], 60.0, rng)
    truth_F = fx.contact_force(d, data["force_nN"]).mean(axis=1)
    out = _traces({**data, "force_nN": force, "F_mean_nN": truth_F}, "families")
    for t, v in zip(out, said.velocity_nm_per_s, strict=True):
        t.meta["velocity_nm_per_s"] = float(v)
    return out


def all_sets(n: int, seed: int, bench_seed: int, work: Path) -> dict[str, list[Trace]]:
    """Every set of the module docstring, by name."""
    sets = {k: non_pt_traces(k, n, seed, work) for k in NON_PT}
    sets["clean"] = clean_traces(n, seed, work)
    sets["lab_bench"] = bench_traces(max(n // 3, 1), bench_seed, work)
    sets["families"] = family_traces(n, seed, work)
    return sets


def rates(estimator, sets: dict[str, list[Trace]]) -> dict[str, tuple[float, Counter]]:
    """Per set: the fraction of rows in domain and the count of each reason given."""
    out = {}
    for name, traces in sets.items():
        table = estimator.predict(traces)
        flags = np.array([domain_verdict(r) is True for r in table.rows])
        reasons = Counter(str(r.get("domain_reason"))
                          for r, inside in zip(table.rows, flags, strict=True) if not inside)
        out[name] = (float(flags.mean()), reasons)
    return out


def print_rates(label: str, res: dict[str, tuple[float, Counter]]) -> None:
    print(f"\n{label}: fraction of rows in domain (target: non-PT <= 0.25 each and <= 0.10 "
          "overall, clean >= 0.95, lab bench and families >= 0.85)")  # fmt: skip
    for name, (frac, reasons) in res.items():
        top = "; ".join(f"{r} ({c})" for r, c in reasons.most_common(3))
        print(f"  {name:<18}{frac:>7.3f}   {top}")
    non = np.mean([res[k][0] for k in NON_PT if k in res])
    print(f"  {'non-PT overall':<18}{non:>7.3f}   (out of domain: {1 - non:.3f})")


def smooth_by_eta(estimator, traces: list[Trace], label: str,
                  bands: tuple[float, ...] = (0.2, 0.5, 0.7, 0.8, 0.9, 0.95)) -> None:  # fmt: skip
    """The smooth-sliding set's rows in domain per band of their true eta, the clean
    lines (even rows) and those with the lab bench's effects (odd rows) apart: where
    smooth sliding passes for stick-slip."""
    rows = estimator.predict(traces).rows
    inside = np.array([domain_verdict(r) is True for r in rows])
    eta = np.array([t.meta["eta"] for t in traces])
    lab = np.arange(len(traces)) % 2 == 1
    cells = []
    for lo, hi in zip(bands[:-1], bands[1:], strict=False):
        m = (eta >= lo) & (eta < hi)
        parts = [f"{inside[m & sel].mean():.2f} of {int((m & sel).sum())}" if (m & sel).any()
                 else "none" for sel in (~lab, lab)]  # fmt: skip
        cells.append(f"eta {lo:g}-{hi:g}: clean {parts[0]}, lab {parts[1]}")
    print(f"  smooth sliding in domain by true eta ({label}): " + "; ".join(cells))


def widening_needed(estimator, sets: dict[str, list[Trace]]) -> None:
    """Per set with truths: how far the 95 % intervals of its out-of-domain rows had to
    be widened to cover 95 % of the truths, as a factor on the calibrated half-width
    (in log space for U0 and K, as :func:`~stickslip.estimators.domain.widen_rows`
    widens), and the coverage of the intervals as the verdict widens them."""
    from stickslip.jobs.evaluate import truth_from_traces

    keys = (("F_mean_nN", False), ("U0_eV", True), ("K_N_m", True))
    print("\nout-of-domain rows (line model): the factor on the 95 % half-width that covers "
          "95 % of the truths; in brackets the coverage as widened")  # fmt: skip
    for name, traces in sets.items():
        tables = {}
        for widen in (False, True):
            estimator.widen_out_of_domain = widen
            tables[widen] = estimator.predict(traces)
        estimator.widen_out_of_domain = True
        truth = truth_from_traces(tables[True], traces)
        pairs = [(r, w) for r, w in zip(tables[False].rows, tables[True].rows, strict=True)
                 if domain_verdict(r) is not True and r.get("quality") == "ok"
                 and r["trace"] in truth]  # fmt: skip
        if not pairs:
            continue
        cells = []
        for k, log in keys:
            need, covered = [], []
            for r, w in pairs:
                m, t, lo, hi = r[k], truth[r["trace"]][k], r[f"{k}_lo95"], r[f"{k}_hi95"]
                if not np.all(np.isfinite([m, t, lo, hi])) or (log and min(m, t, lo) <= 0):
                    continue
                side = hi if t > m else lo
                gap, half = (np.log(t / m), np.log(side / m)) if log else (t - m, side - m)
                need.append(gap / half if half != 0 else np.inf)
                covered.append(w[f"{k}_lo95"] <= t <= w[f"{k}_hi95"])
            cells.append(f"{k.split('_')[0]} {np.quantile(need, 0.95):.2f} "
                         f"({np.mean(covered):.3f})")  # fmt: skip
        print(f"  {name:<18}{len(pairs):>5d} rows   " + "   ".join(cells))


def speed(estimator, n: int, repeats: int, work: Path) -> None:
    """Time ``estimator.predict`` with and without the verdict, alternately."""
    base = clean_traces(200, 1, work) + bench_traces(67, BENCH_SEED + 1, work)
    traces = [base[i % len(base)] for i in range(n)]
    estimator.predict(traces[:300])
    best = {True: np.inf, False: np.inf}
    for _ in range(repeats):
        for verdict in (False, True):
            estimator.domain_verdict = verdict
            t = time.perf_counter()
            estimator.predict(traces)
            best[verdict] = min(best[verdict], time.perf_counter() - t)
    estimator.domain_verdict = True
    cpu = platform.processor() or platform.machine()
    print(f"\nLineEstimator.predict, {n} traces of 512 px (clean and lab-bench lines), "
          f"{torch.get_num_threads()} torch threads, {os.cpu_count()} CPUs ({cpu}), "
          f"load average {os.getloadavg()[0]:.1f}: best of {repeats}")
    for verdict in (False, True):
        print(f"  verdict {'on ' if verdict else 'off'}: {best[verdict]:.2f} s = "
              f"{n / best[verdict]:,.0f} traces/s")
    print(f"  throughput with / without the verdict: {best[False] / best[True]:.3f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=2, help="seed of the sets (tuned on 1)")
    parser.add_argument("--bench-seed", type=int, default=BENCH_SEED)
    parser.add_argument("--n", type=int, default=200, help="traces per set")
    parser.add_argument("--n-speed", type=int, default=5000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--work", type=Path, default=ROOT / "build" / "domain")
    parser.add_argument("--skip-speed", action="store_true")
    parser.add_argument("--speed-only", action="store_true", help="skip the rates")
    parser.add_argument("--eta-confirm", type=float, default=None,
                        help="the line model's ETA_CONFIRM for this run (0: no stick-slip "
                             "check; default: the library's)")  # fmt: skip
    parser.add_argument("--write-reference", action="store_true",
                        help="Fit the line model's embedding reference and contact probe and "
                             "write them to src/stickslip/resources/line_domain.npz, then "
                             "stop.")  # fmt: skip
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    if args.write_reference:
        write_reference(args.work, ROOT / "src" / "stickslip" / "resources" / "line_domain.npz")
        return
    import stickslip.estimators.domain as domain
    from stickslip.estimators.classical.estimator import ClassicalEstimator
    from stickslip.estimators.load import load_estimator

    if args.eta_confirm is not None:
        domain.ETA_CONFIRM = args.eta_confirm  # the line model's check and the verdict read it
    line = load_estimator(None)
    if args.speed_only:
        speed(line, args.n_speed, args.repeats, args.work)
        return
    sets = all_sets(args.n, args.seed, args.bench_seed, args.work)
    print(f"sets of seed {args.seed} ({args.n} traces each), lab bench of seed "
          f"{args.bench_seed} ({len(sets['lab_bench'])} traces)")
    print_rates("line model (bundled)", rates(line, sets))
    smooth_by_eta(line, sets["smooth_sliding"], "line model")
    classical = ClassicalEstimator()
    print_rates("classical estimator", rates(classical, sets))
    smooth_by_eta(classical, sets["smooth_sliding"], "classical estimator")
    widening_needed(line, {k: v for k, v in sets.items() if k in TRUTH_SETS})
    if not args.skip_speed:
        speed(line, args.n_speed, args.repeats, args.work)


if __name__ == "__main__":
    main()
