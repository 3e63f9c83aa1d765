"""Stress corpus for the classical stick-slip estimator: generation and scoring.

An independent evaluation corpus, made before the estimator's slip detector was
rewritten and never used to develop it. Run it once per estimator version and report;
do not tune against it.

Sets
----
A. Spring-block lines (:mod:`stickslip.simulators.spring_block`: a rigid slider on a
   spring driven at constant velocity, Coulomb, velocity-weakening or rate-and-state
   friction, no periodic potential), recorded with instrument effects of this file's
   own (:func:`instrument`): slow baseline wander up to 10 drops over the line, white
   and 1/f noise, sparse spikes, quantisation and sometimes a first-order detector
   low-pass.

   - ``broad`` (:data:`N_BROAD` lines): k 10-5000 N/m, M 5-100 g, v 10 um/s-10 mm/s,
     fs 0.5-20 kHz, 2,000-400,000 samples, log-uniform, drawn by rejection so that the
     *predicted* stuck fraction falls in a stratum ("sticks", "grey", "oscillation")
     and the samples per slip in a decade of 5-40,000, in turn (fs is drawn last, from
     a log-uniform samples per slip in the decade; the design is a Coulomb estimate,
     the truth is measured on the simulated motion);
   - ``paper`` (:data:`N_PAPER` lines): paper on paper as in Colas et al. (PRE 2019) and
     the real file ``k1002Nm_v42.mat``: M = 30.7 g, 2 kHz, springs 168/1002/2254 N/m,
     v = 42/1100/4300 um/s, drops of 20-50 mN with a 0.84 mN ADC step, ~1e-3 spikes
     per sample, slow wander.

   True regime of each line, from the noiseless slider motion, with thresholds fixed
   before anything was scored (``stuck`` = slider speed <= 1 % of the drive
   velocity, so that the recorded slope is within 1 % of k; ``stuck_fraction`` = stuck
   share of the recorded time; ``n_slips`` = slips starting inside the recording):

   - ``sticks``: stuck_fraction >= :data:`STICK_MIN` (0.5) and n_slips >= 3. Truth: k
     (the estimator's ``k_exp_N_m``, its stick slope, is compared with it);
   - ``oscillation`` (does not stick: inertia-dominated, near-sinusoidal, or steady
     sliding): stuck_fraction < :data:`OSC_MAX` (0.1). Should be refused;
   - ``grey``: everything else; scored only by the no-row-more-than-20 %-off rule.

   Given to the estimator as ``stickslip label --temperature 0 --velocity v`` does,
   less the AFM range check that refuses forces beyond 1e4 nN and scans beyond 0.1 mm
   before estimating (a macroscopic slider lies outside it):
   :class:`ClassicalEstimator` ``.estimate`` with ``x_nm = X_m * 1e9``,
   ``force_nN = F_N * 1e9`` (stick slope in nN/nm = N/m), temperature 0 K, velocity
   ``v * 1e9`` nm/s, the reference lattice.

B. AFM lab-like lines (the project's own simulators, new seeds), scored on U0 and K
   through ``ClassicalEstimator().predict`` at each line's stated conditions, lines with
   1.5 <= eta <= 40 as ``benchmarks/classical_lab.py``:

   - ``families``: a randomised pool (``RandomisedConfig(n, seed=3911)``) with one draw
     of every effect family (``draw_family_lines``, seed 3912, "eval" implementations);
   - ``families + tilt``: the same lines plus ``a x + b x^2`` (random signs, random
     mix) whose peak-to-peak over the line is 0.1-10 (log-uniform) times the clean
     line's force range (p99.5 - p0.5 of the pool's clean trace; seed 3913);
   - ``bench``: the lab bench (``BenchConfig(n_per_material, seed=3921)``;
     ``make_bench`` derives its per-material streams 3921, 4921, 5921);
   - ``bench + tilt``: the same plus the tilt/curvature, sized on the recorded line's
     range (p99.5 - p0.5; seed 3922);
   - ``... + tilt, zero-mean``: each tilted set with its tilt less the tilt's mean over
     the line: the tilt's shape without the offset of the force zero it also adds,
     which one line cannot tell from friction (a trace/retrace pair cancels it);
   - ``clean PT``: paper-preset lines at 296 K, eta in [1.5, 40] (as
     ``benchmarks/classical.py`` makes them; seed 3931);
   - ``clean PT + tilt``: the same plus a tilt/curvature sized on each line's range
     (seed 3933), one line at a time;
   - ``clean PT + tilt, trace/retrace pairs``: the same trace rows, each estimated beside
     its retrace (the same parameters simulated again, seed 3932, with the same tilt,
     stored as a map reader stores a retrace): the classical estimator reads a pair less
     the offset both directions share.

Seeds: 3901 (broad draws), 3902 (paper draws), 3903 (strength disorder, stream = line),
3904 (instrument effects, stream = line), 3911, 3912, 3913, 3921, 3922, 3931-3933 as
above.
Nothing else in the project uses 3901-3999.

Scoring: a row is answered iff ``quality == "ok"`` and the number is finite. Printed per
set and true regime, with targets: spring-block sticking >= 95 % answered, every
answered k within 10 %, median |error| <= 3 %; not sticking >= 90 % refused (quality not
ok, or a regime that says smooth / oscillation / not stick-slip); no answered row more
than 20 % off in any regime; breakdowns by samples per slip and by baseline amplitude
(in drops); AFM sets >= 90 % answered with K rel. RMSE <= 15 % (with and without
tilt), clean lines median |error| of U0 and K <= 1 %, 95th percentile <= 8 %; per AFM
set, the share an oracle refusal of the worst answered rows would leave answered at
K rel. RMSE 15 % (:func:`answered_at_target`: below 90 %, no refusal rule meets both).

Cached under ``build/stress/`` (HDF5; the spring-block file holds the corpus config and
every line's simulator config and effect draw as JSON, so it can be remade from the
file alone).

Runtime (2-core VM, NUMBA_NUM_THREADS=1): the first run simulates everything (~1 min
spring-block, ~7 min AFM sets) and caches it; scoring then takes ~70 s (432 spring-block
lines, 42.7 M samples; the AFM sets ~1 s) plus numba's first compilation.

Usage: python benchmarks/classical_stress.py [--quick] [--json out.json]
       [--work build/stress] [--regenerate] [--no-afm]
"""

from __future__ import annotations

import argparse
import collections
import dataclasses
import datetime
import json
import math
import os
import platform
import subprocess
import time
from pathlib import Path
from typing import Any

import h5py
import numpy as np
from scipy.signal import lfilter
from tqdm.auto import tqdm

import stickslip
from stickslip.estimators.classical.estimator import ClassicalEstimator
from stickslip.estimators.line.families import draw_family_lines
from stickslip.simulators import effects as fx
from stickslip.simulators.bench import BenchConfig, bench_if_missing, in_eta_window
from stickslip.simulators.config import PhysicalSettings
from stickslip.simulators.randomised import RandomisedConfig, cached_randomised_set
from stickslip.simulators.simulate import simulate
from stickslip.simulators.spring_block import (
    G_M_PER_S2,
    Coulomb,
    RateState,
    SpringBlockConfig,
    VelocityWeakening,
    law_name,
    simulate_spring_block,
)
from stickslip.traces.dataset import Dataset, dataset_traces, load_dataset
from stickslip.traces.trace import Trace
from stickslip.units import eta_from

ROOT = Path(__file__).resolve().parents[1]

SEED_BROAD, SEED_PAPER, SEED_STRENGTH, SEED_INSTRUMENT = 3901, 3902, 3903, 3904
SEED_POOL, SEED_FAMILIES, SEED_FAMILY_TILT = 3911, 3912, 3913
SEED_BENCH, SEED_BENCH_TILT = 3921, 3922
SEED_CLEAN, SEED_CLEAN_RETRACE, SEED_CLEAN_TILT = 3931, 3932, 3933
#: Every seed this corpus uses (all in 3901-3999).
SEEDS = {"broad": SEED_BROAD, "paper": SEED_PAPER, "strength": SEED_STRENGTH,
         "instrument": SEED_INSTRUMENT, "pool": SEED_POOL, "families": SEED_FAMILIES,
         "families_tilt": SEED_FAMILY_TILT, "bench": SEED_BENCH,
         "bench_tilt": SEED_BENCH_TILT, "clean": SEED_CLEAN}  # fmt: skip

N_BROAD, N_PAPER = 360, 72
N_AFM = 300  # lines of each AFM set (the bench: 100 per material)
QUICK_EVERY = 6  # --quick: every 6th spring-block line
N_AFM_QUICK = 60

# true-regime thresholds (fixed before scoring; module docstring)
STUCK_TOLERANCE = 0.01  # slider speed / drive velocity counted as stuck
STICK_MIN = 0.5
OSC_MAX = 0.1
MIN_SLIPS = 3
REGIMES = ("sticks", "oscillation", "grey")

# targets printed beside the figures
T_ANSWERED, T_WITHIN, T_MEDIAN, T_REFUSED, T_OFF = 0.95, 0.10, 0.03, 0.90, 0.20
T_AFM_ANSWERED, T_AFM_K_RMSE, T_CLEAN_MEDIAN, T_CLEAN_P95 = 0.90, 0.15, 0.01, 0.08

GENERATOR_VERSION = 1
SPS_DECADES = ((5.0, 10.0), (10.0, 100.0), (100.0, 1e3), (1e3, 1e4), (1e4, 4e4))
PAPER_SPRINGS_N_PER_M = (168.0, 1002.0, 2254.0)
PAPER_VELOCITIES_M_PER_S = (42e-6, 1100e-6, 4300e-6)
PAPER_MASS_KG = 0.0307
PAPER_ADC_STEP_N = 0.00279 * PAPER_MASS_KG * G_M_PER_S2  # the real file's Fnorm step


# ------------------------------------------------------------------ spring-block draws


def _logu(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(np.exp(rng.uniform(np.log(lo), np.log(hi))))


def _predict(k: float, M: float, v: float, law: Any) -> tuple[float, float]:
    """Design estimate (Coulomb-like) of one stick-slip cycle's duration (s) and of the
    stuck fraction; ``(inf, 0)`` where the law predicts steady sliding."""
    w = math.sqrt(k / M)
    if isinstance(law, RateState):
        vc = law.length_m / law.state_cutoff_s
        k_crit = (law.b - law.a) * law.normal_force_N / law.length_m
        if v >= vc or k >= k_crit:
            return math.inf, 0.0
        delta = (law.b - law.a) * law.normal_force_N * math.log(vc / v)
    else:
        delta = (law.mu_static - law.mu_dynamic) * law.normal_force_N
    v_star = delta * w / k
    t_stick = 2 * delta / (k * v)
    t_slip = (2 * math.pi - 2 * math.atan(v_star / v)) / w
    return t_stick + t_slip, t_stick / (t_stick + t_slip)


def _law(rng: np.random.Generator, kind: str, k: float, M: float, v: float, N: float,
         paper: bool) -> Any:  # fmt: skip
    w = math.sqrt(k / M)
    if kind in ("coulomb", "weakening"):
        if paper:
            mu_s = rng.uniform(0.30, 0.36)
            mu_d = mu_s - _logu(rng, 0.03, 0.08)
        else:
            mu_s = rng.uniform(0.15, 0.8)
            mu_d = mu_s * (1 - _logu(rng, 0.03, 0.5))
        if kind == "coulomb":
            return Coulomb(mu_s, mu_d, N)
        v_star = (mu_s - mu_d) * N * w / k
        uc = v_star * (_logu(rng, 0.1, 1.0) if paper else _logu(rng, 0.03, 3.0))
        return VelocityWeakening(mu_s, mu_d, uc, N)
    if paper:
        mu0, b = rng.uniform(0.22, 0.28), _logu(rng, 0.006, 0.016)
        a = b * rng.uniform(0.3, 0.6)
        dc = _logu(rng, 0.5e-6, 5e-6)
        vc = _logu(rng, 1e-3, 3e-2)
        v1 = _logu(rng, 1e-7, 1e-5)
    else:
        mu0, b = rng.uniform(0.2, 0.5), _logu(rng, 0.005, 0.05)
        a = b * rng.uniform(0.2, 0.8)
        dc = _logu(rng, 0.3e-6, 30e-6)
        vc = v * _logu(rng, 0.5, 300.0)
        v1 = v * _logu(rng, 1e-3, 0.1)
    # cost guards (documented): the direct effect's rate a N / (M V1) at most 300 per
    # slip time pi / w, and a slip of ~ 2 b N / k at least 1/300 of Dc
    v1 = max(v1, a * N * math.pi / (300 * M * w))
    dc = max(dc, 2 * b * N / k / 300)
    # the contact's age at the start: near the steady state at the drive velocity
    theta0 = dc / v * rng.uniform(1.0, 3.0)
    return RateState(mu0, a, b, v1, dc / vc, dc, N, initial_state_s=theta0)


def draw_broad(i: int, rng: np.random.Generator) -> SpringBlockConfig:
    """Line ``i`` of the broad set: its design targets (a samples-per-slip decade and a
    predicted-regime stratum), then log-uniform draws kept when they meet them. Where
    the ranges cannot give the decade for the stratum (inertia-dominated lines have
    slips of ``2 pi / w`` at most, a few thousand samples at 20 kHz), the next lower
    decade is the target."""
    stratum = ("sticks", "oscillation", "sticks", "grey", "sticks", "oscillation",
               "sticks", "grey")[(i // len(SPS_DECADES)) % 8]  # fmt: skip
    # steady sliding (rate-and-state above its cut-off speed) is the easy way not to
    # stick: every other block of "oscillation" lines is inertia-dominated (Coulomb,
    # weakening) only
    inertial = stratum == "oscillation" and (i // 40) % 2 == 0
    top = i % len(SPS_DECADES) if stratum == "sticks" else min(i % len(SPS_DECADES), 3)
    for d in range(top, -1, -1):
        cfg = _draw_broad(i, rng, SPS_DECADES[d], stratum, inertial)
        if cfg is not None:
            return cfg
    raise RuntimeError(f"no draw for broad line {i}")


def _draw_broad(i: int, rng: np.random.Generator, decade: tuple[float, float],
                stratum: str, inertial: bool) -> SpringBlockConfig | None:  # fmt: skip
    for _ in range(40_000):
        k, M, v = _logu(rng, 10.0, 5000.0), _logu(rng, 0.005, 0.1), _logu(rng, 1e-5, 1e-2)
        p = [0.5, 0.5, 0.0] if inertial else [0.4, 0.3, 0.3]
        kind = str(rng.choice(["coulomb", "weakening", "rate_state"], p=p))
        N = M * G_M_PER_S2 * _logu(rng, 1.0, 10.0)
        law = _law(rng, kind, k, M, v, N, paper=False)
        cycle, sf = _predict(k, M, v, law)
        if stratum == "sticks" and sf < 0.6 or stratum == "grey" and not 0.15 < sf < 0.45:
            continue
        if stratum == "oscillation" and sf > 0.03:
            continue
        # the sampling rate last, log-uniform samples per slip inside the decade (a steady
        # slider: per free period)
        sps = _logu(rng, *decade)
        fs = sps / (cycle if math.isfinite(cycle) else 2 * math.pi / math.sqrt(k / M))
        if not 500.0 <= fs <= 20000.0 or 3.5 * sps > 400_000:
            continue
        n = int(_logu(rng, max(2000.0, 3.5 * sps), 400_000.0))
        dur = n / fs
        if kind != "coulomb" and dur * math.sqrt(k / M) / (2 * math.pi) * 32 > 3e7:
            continue  # RK4 cost
        zeta = 0.0 if rng.random() < 0.5 else _logu(rng, 0.005, 0.3)
        spread = 0.0 if rng.random() < 0.4 else rng.uniform(0.02, 0.3)
        over = int(rng.choice([1, 1, 1, 1, 2, 4, 8, 16]))
        lead = (cycle if math.isfinite(cycle) else 0.2 * dur) * rng.uniform(1.0, 3.0)
        return SpringBlockConfig(
            k_N_per_m=k, mass_kg=M, velocity_m_per_s=v, sample_rate_Hz=fs, n_samples=n,
            law=law, damping_N_s_per_m=2 * zeta * math.sqrt(k * M), oversample=over,
            lead_s=lead, strength_spread=spread, seed=SEED_STRENGTH, stream=i,
            stuck_tolerance=STUCK_TOLERANCE,
        )  # fmt: skip
    return None


def draw_paper(j: int, rng: np.random.Generator) -> SpringBlockConfig:
    """Paper-like line ``j``: spring and velocity of the experiments (in turn), 30.7 g,
    2 kHz, rate-and-state half of the time."""
    k = PAPER_SPRINGS_N_PER_M[j % 3]
    v = PAPER_VELOCITIES_M_PER_S[(j // 3) % 3]
    M, N = PAPER_MASS_KG, PAPER_MASS_KG * G_M_PER_S2
    kind = str(rng.choice(["coulomb", "weakening", "rate_state"], p=[0.25, 0.25, 0.5]))
    law = _law(rng, kind, k, M, v, N, paper=True)
    cycle, _ = _predict(k, M, v, law)
    n = int(_logu(rng, 20_000.0, 400_000.0))
    if math.isfinite(cycle):
        n = min(400_000, max(n, int(4 * cycle * 2000.0)))
    lead = (cycle if math.isfinite(cycle) else 1.0) * rng.uniform(1.0, 3.0)
    return SpringBlockConfig(
        k_N_per_m=k, mass_kg=M, velocity_m_per_s=v, sample_rate_Hz=2000.0, n_samples=n,
        law=law, damping_N_s_per_m=2 * _logu(rng, 0.01, 0.1) * math.sqrt(k * M),
        oversample=int(rng.choice([1, 4])), lead_s=lead, strength_spread=rng.uniform(0.1, 0.4),
        seed=SEED_STRENGTH, stream=10_000 + j, stuck_tolerance=STUCK_TOLERANCE,
    )  # fmt: skip


# -------------------------------------------------------------------- instrument effects


def _pink(n: int, rng: np.random.Generator) -> np.ndarray:
    spec = rng.standard_normal(n // 2 + 1) + 1j * rng.standard_normal(n // 2 + 1)
    f = np.fft.rfftfreq(n)
    f[0] = f[1] if n > 1 else 1.0
    spec /= np.sqrt(f)
    spec[0] = 0.0
    x = np.fft.irfft(spec, n=n)
    return x / (x.std() + 1e-300)


def _wander(n: int, rng: np.random.Generator) -> np.ndarray:
    """A smooth random curve over the line with peak-to-peak 1: a few long sine modes
    (1/j amplitudes) and a trend."""
    u = np.linspace(0.0, 1.0, n)
    b = rng.normal() * u
    for j in range(1, 5):
        b += rng.normal() / j * np.sin(np.pi * j * u + rng.uniform(0, 2 * np.pi))
    span = b.max() - b.min()
    return (b - b.min()) / span if span > 0 else np.zeros(n)


def instrument(F: np.ndarray, fs: float, unit: float, rng: np.random.Generator,
               paper: bool) -> tuple[np.ndarray, dict[str, float]]:  # fmt: skip
    """Recorded force: ``F`` (N) with wander, detector low-pass, noise, spikes and ADC.

    ``unit`` (N) is the line's force scale (:func:`force_unit`); sizes are drawn
    relative to it (``paper``: the real file's absolute noise, ADC step and spikes).
    Returns the force and the drawn sizes (0 where an effect is absent).
    """
    n = F.size
    d: dict[str, float] = {}
    on = rng.random(6)
    d["wander_drops"] = (_logu(rng, 0.1, 3.0) if paper else _logu(rng, 0.05, 10.0)) \
        if on[0] < (0.8 if paper else 0.7) else 0.0
    out = F + d["wander_drops"] * unit * _wander(n, rng)
    d["lowpass_samples"] = _logu(rng, 0.3, 5.0) if on[1] < 0.3 else 0.0
    if d["lowpass_samples"] > 0:
        alpha = 1.0 - math.exp(-1.0 / d["lowpass_samples"])
        out = lfilter([alpha], [1.0, alpha - 1.0], out - out[0]) + out[0]
    white = _logu(rng, 2e-4, 1e-3) if paper else _logu(rng, 3e-4, 0.05) * unit
    d["white_N"] = white if (paper or on[2] < 0.8) else 0.0
    d["pink_N"] = _logu(rng, 3e-4, 0.05) * unit if on[3] < (0.3 if paper else 0.5) else 0.0
    out = out + d["white_N"] * rng.standard_normal(n) + d["pink_N"] * _pink(n, rng)
    d["spike_rate"] = _logu(rng, 3e-4, 2e-3) if paper else (
        _logu(rng, 1e-4, 3e-3) if on[4] < 0.35 else 0.0)  # fmt: skip
    d["spike_drops"] = _logu(rng, 0.1, 1.0) if paper else _logu(rng, 0.05, 1.0)
    if d["spike_rate"] > 0:
        m = rng.random(n) < d["spike_rate"]
        where = np.flatnonzero(m)
        sign = np.where(rng.random(where.size) < (0.8 if paper else 0.7), -1.0, 1.0)
        amp = sign * d["spike_drops"] * unit * rng.uniform(0.2, 1.0, where.size)
        out[where] += amp
        two = where[(rng.random(where.size) < 0.3) & (where + 1 < n)]
        out[two + 1] += 0.5 * amp[np.isin(where, two)]
    else:
        d["spike_drops"] = 0.0
    d["adc_step_N"] = PAPER_ADC_STEP_N if paper else (
        _logu(rng, 0.003, 0.05) * unit if on[5] < 0.5 else 0.0)  # fmt: skip
    if d["adc_step_N"] > 0:
        out = np.round(out / d["adc_step_N"]) * d["adc_step_N"]
    return out, d


def force_unit(F: np.ndarray, median_drop: float) -> float:
    """The line's force scale for the instrument sizes: the larger of the median slip
    drop and half the clean force's p99 - p1 range, and at least 2 % of the mean force
    (a steady slider has neither)."""
    half = 0.5 * float(np.percentile(F, 99) - np.percentile(F, 1))
    drop = median_drop if np.isfinite(median_drop) else 0.0
    return max(drop, half, 0.02 * abs(float(F.mean())), 1e-12)


def regime(stuck_fraction: float, n_slips: int) -> str:
    """The true regime of a line (thresholds in the module docstring)."""
    if stuck_fraction >= STICK_MIN and n_slips >= MIN_SLIPS:
        return "sticks"
    if stuck_fraction < OSC_MAX:
        return "oscillation"
    return "grey"


# -------------------------------------------------------------------- spring-block corpus


def corpus_config(quick: bool) -> dict[str, Any]:
    """Everything that defines the spring-block corpus (stored in its file)."""
    return {"generator_version": GENERATOR_VERSION, "seeds": SEEDS, "n_broad": N_BROAD,
            "n_paper": N_PAPER, "quick_every": QUICK_EVERY if quick else 1,
            "stuck_tolerance": STUCK_TOLERANCE, "stick_min": STICK_MIN, "osc_max": OSC_MAX,
            "min_slips": MIN_SLIPS, "sps_decades": SPS_DECADES,
            "paper_adc_step_N": PAPER_ADC_STEP_N}  # fmt: skip


def line_configs(quick: bool) -> list[tuple[str, int, SpringBlockConfig]]:
    """(set, stream, config) of every line of the corpus (or of the --quick subset)."""
    rng = np.random.default_rng(SEED_BROAD)
    broad = [("broad", i, draw_broad(i, rng)) for i in range(N_BROAD)]
    rng = np.random.default_rng(SEED_PAPER)
    paper = [("paper", 10_000 + j, draw_paper(j, rng)) for j in range(N_PAPER)]
    lines = broad + paper
    return lines[::QUICK_EVERY] if quick else lines


COLUMNS = ("set", "k_N_per_m", "mass_kg", "velocity_m_per_s", "sample_rate_Hz", "n_samples",
           "t0_s", "law", "stuck_fraction", "rest_fraction", "n_slips", "median_drop_N",
           "samples_per_slip", "unit_N", "regime", "wander_drops", "lowpass_samples",
           "white_N", "pink_N", "spike_rate", "spike_drops", "adc_step_N", "offset")  # fmt: skip
LAWS = ("coulomb", "velocity_weakening", "rate_state")
SETS = ("broad", "paper")


def make_corpus(path: Path, quick: bool) -> Path:
    """Simulate the spring-block corpus into ``path`` (see the module docstring)."""
    lines = line_configs(quick)
    part = path.with_name(path.name + ".partial")
    path.parent.mkdir(parents=True, exist_ok=True)
    table: dict[str, list] = {c: [] for c in COLUMNS}
    with h5py.File(part, "w") as h:
        h.attrs["corpus_config"] = json.dumps(corpus_config(quick), sort_keys=True)
        h.attrs["kind"] = "spring-block stress corpus"
        h.attrs["columns_doc"] = ("set: 0 broad, 1 paper; law: 0 coulomb, 1 velocity "
                                  "weakening, 2 rate-state; regime: 0 sticks, 1 oscillation, "
                                  "2 grey; force of line i: force_N[offset[i]:offset[i+1]], "
                                  "X_m = v (t0_s + (j + 0.5)/fs)")  # fmt: skip
        ds = h.create_dataset("force_N", shape=(0,), maxshape=(None,), dtype="f8",
                              chunks=(1 << 16,), compression="gzip", compression_opts=1,
                              shuffle=True)  # fmt: skip
        cfgs = []
        total = 0
        for name, stream, cfg in tqdm(lines, desc="spring-block lines", unit="line"):
            line = simulate_spring_block(cfg)
            unit = force_unit(line.force_N, line.median_drop_N)
            rng = np.random.default_rng([SEED_INSTRUMENT, stream])
            F, drawn = instrument(line.force_N, cfg.sample_rate_Hz, unit, rng, name == "paper")
            ds.resize((total + F.size,))
            ds[total:] = F
            row = {"set": SETS.index(name), "k_N_per_m": cfg.k_N_per_m, "mass_kg": cfg.mass_kg,
                   "velocity_m_per_s": cfg.velocity_m_per_s,
                   "sample_rate_Hz": cfg.sample_rate_Hz, "n_samples": cfg.n_samples,
                   "t0_s": float(line.t_s[0] - 0.5 / cfg.sample_rate_Hz),
                   "law": LAWS.index(law_name(cfg.law)),
                   "stuck_fraction": line.stuck_fraction, "rest_fraction": line.rest_fraction,
                   "n_slips": line.n_slips, "median_drop_N": line.median_drop_N,
                   "samples_per_slip": line.samples_per_slip, "unit_N": unit,
                   "regime": REGIMES.index(regime(line.stuck_fraction, line.n_slips)),
                   **drawn, "offset": total}  # fmt: skip
            for c in COLUMNS:
                table[c].append(row[c])
            cfgs.append(json.dumps({"set": name, "stream": stream, "config": cfg.to_dict(),
                                    "effects": drawn}, sort_keys=True))  # fmt: skip
            total += F.size
        table["offset"].append(total)
        g = h.create_group("table")
        for c in COLUMNS:
            g.create_dataset(c, data=np.asarray(table[c]))
        h.create_dataset("line_json", data=np.array(cfgs, dtype=h5py.string_dtype()))
    os.replace(part, path)
    return path


def corpus_if_missing(work: Path, quick: bool, regenerate: bool = False) -> Path:
    """The corpus file, simulated first if missing or made with other settings."""
    path = work / ("spring_block_quick.h5" if quick else "spring_block.h5")
    want = json.dumps(corpus_config(quick), sort_keys=True)
    if path.exists() and not regenerate:
        with h5py.File(path, "r") as h:
            if h.attrs.get("corpus_config") == want:
                return path
    return make_corpus(path, quick)


def read_corpus(path: Path) -> tuple[dict[str, np.ndarray], list[np.ndarray], list[np.ndarray]]:
    """The table and each line's ``x_nm`` and ``force_nN`` as the estimator gets them."""
    with h5py.File(path, "r") as h:
        tab = {c: h["table"][c][()] for c in COLUMNS}
        F = h["force_N"][()]
    off = tab["offset"]
    xs, Fs = [], []
    for i in range(off.size - 1):
        fs, v = tab["sample_rate_Hz"][i], tab["velocity_m_per_s"][i]
        j = np.arange(off[i + 1] - off[i])
        xs.append(v * (tab["t0_s"][i] + (j + 0.5) / fs) * 1e9)
        Fs.append(F[off[i]:off[i + 1]] * 1e9)
    tab = {c: v[:-1] if c == "offset" else v for c, v in tab.items()}
    return tab, xs, Fs


# -------------------------------------------------------------------- AFM sets


def _tilt(force: np.ndarray, x_nm: np.ndarray, scale: np.ndarray,
          rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """``force`` plus ``a x + b x^2`` per line: random signs and mix, peak-to-peak
    ``r * scale`` with r log-uniform in [0.1, 10]; returns the force and r."""
    n = force.shape[0]
    u = (x_nm - x_nm[0]) / (x_nm[-1] - x_nm[0])
    r = np.exp(rng.uniform(np.log(0.1), np.log(10.0), n))
    mix = rng.uniform(0.0, 1.0, n)
    s1, s2 = rng.choice([-1.0, 1.0], n), rng.choice([-1.0, 1.0], n)
    base = s1[:, None] * mix[:, None] * u + s2[:, None] * (1 - mix[:, None]) * u**2
    span = base.max(axis=1) - base.min(axis=1)
    base = base / np.where(span > 0, span, 1.0)[:, None]
    return force + base * (r * scale)[:, None], r


def _range(F: np.ndarray) -> np.ndarray:
    return np.percentile(F, 99.5, axis=1) - np.percentile(F, 0.5, axis=1)


def clean_pt(work: Path, n: int, sim_seed: int | None = None) -> Dataset:
    """Paper-preset lines at 296 K with 1.5 <= eta <= 40 (cached); ``sim_seed``: the same
    parameters simulated again with another thermal noise (a retrace)."""
    sim_seed = SEED_CLEAN if sim_seed is None else sim_seed
    suffix = "" if sim_seed == SEED_CLEAN else f"_sim{sim_seed}"
    path = work / f"clean_pt_{n}_{SEED_CLEAN}{suffix}.h5"
    s = PhysicalSettings()
    if not path.exists():
        rng = np.random.default_rng(SEED_CLEAN)
        U, K = rng.uniform(0.3, 6.0, 30 * n), rng.uniform(1.0, 50.0, 30 * n)
        e = eta_from(U, K, s.lattice_nm)
        keep = in_eta_window(e)
        U, K = U[keep][:n], K[keep][:n]
        parts = []
        for a in tqdm(range(0, n, 25), desc="clean PT lines", unit="x25"):
            parts.append(simulate(U[a:a + 25], K[a:a + 25], s, seed=sim_seed,
                                  indices=np.arange(a, min(a + 25, n))).force_nN)  # fmt: skip
        part = path.with_name(path.name + ".partial")
        with h5py.File(part, "w") as h:
            h.attrs["config"] = json.dumps({"seed": SEED_CLEAN, "sim_seed": sim_seed, "n": n,
                                            "physics":
                                            dataclasses.asdict(s)}, sort_keys=True)  # fmt: skip
            h["force_nN"] = np.vstack(parts)
            h["U0_eV"], h["K_N_m"] = U, K
        os.replace(part, path)
    with h5py.File(path, "r") as h:
        F, U, K = h["force_nN"][()], h["U0_eV"][()], h["K_N_m"][()]
    x = np.arange(s.pixels) * s.pixel_nm
    params = {"U0_eV": U, "K_N_m": K, "eta": eta_from(U, K, s.lattice_nm),
              "lattice_nm": np.full(U.size, s.lattice_nm),
              "velocity_nm_per_s": np.full(U.size, s.velocity_nm_per_s),
              "temperature_K": np.full(U.size, s.temperature_K)}  # fmt: skip
    return Dataset(F, x, params, {"kind": "clean-pt"})


AfmSets = dict[str, tuple[Dataset, np.ndarray | None]]


def afm_sets(work: Path, quick: bool
             ) -> tuple[AfmSets, dict[str, Dataset], dict[str, np.ndarray]]:  # fmt: skip
    """The AFM sets with, for the tilted ones, each line's tilt in force ranges; the
    retrace rows of the sets scored as trace/retrace pairs (stored as a map reader
    stores them: reversed in x and sign-flipped, the tilt not reversing with the scan);
    and, for the families sets, which families each line got (n, len(FAMILIES))."""
    n = N_AFM_QUICK if quick else N_AFM
    clean = clean_pt(work, n)
    Fc = np.asarray(clean.force_nN, float)
    F, r_clean = _tilt(Fc, np.asarray(clean.x_nm, float), _range(Fc),
                       np.random.default_rng(SEED_CLEAN_TILT))  # fmt: skip
    clean_tilt = Dataset(F, clean.x_nm, clean.params, {**clean.attrs, "kind": "clean-pt-tilt"})
    base = F - Fc
    retrace = clean_pt(work, n, SEED_CLEAN_RETRACE)
    retrace_tilt = Dataset(np.asarray(retrace.force_nN, float) - base[:, ::-1], retrace.x_nm,
                           retrace.params, {**retrace.attrs, "kind": "clean-pt-tilt-retrace"})
    pool = cached_randomised_set(RandomisedConfig(n=n, seed=SEED_POOL, chunk=50), work)
    fam = draw_family_lines(pool, fx.NuisancePrior(), SEED_FAMILIES)
    d = fam.data
    clean_range = _range(np.asarray(pool.force_nN, float))[fam.rows]
    F, r_fam = _tilt(np.asarray(d.force_nN, float), np.asarray(d.x_nm, float), clean_range,
                     np.random.default_rng(SEED_FAMILY_TILT))  # fmt: skip
    fam_tilt = Dataset(F, d.x_nm, d.params, {**d.attrs, "kind": "families-tilt"})
    cfg = BenchConfig(n_per_material=n // 3, seed=SEED_BENCH)
    bench = load_dataset(bench_if_missing(cfg, work / f"bench_{n // 3}_{SEED_BENCH}.h5"))
    Fb = np.asarray(bench.force_nN, float)
    F, r_bench = _tilt(Fb, np.asarray(bench.x_nm, float), _range(Fb),
                       np.random.default_rng(SEED_BENCH_TILT))  # fmt: skip
    bench_tilt = Dataset(F, bench.x_nm, bench.params, {**bench.attrs, "kind": "bench-tilt"})
    return {"families": (d, None), "families + tilt": (fam_tilt, r_fam),
            "families + tilt, zero-mean": (_zero_mean_tilt(d, fam_tilt), r_fam),
            "bench": (bench, None), "bench + tilt": (bench_tilt, r_bench),
            "bench + tilt, zero-mean": (_zero_mean_tilt(bench, bench_tilt), r_bench),
            "clean PT": (clean, None), "clean PT + tilt": (clean_tilt, r_clean),
            "clean PT + tilt, trace/retrace pairs": (clean_tilt, r_clean)}, {
            "clean PT + tilt, trace/retrace pairs": retrace_tilt}, {
            name: fam.applied for name in ("families", "families + tilt",
                                           "families + tilt, zero-mean")}  # fmt: skip


def _zero_mean_tilt(clean: Dataset, tilted: Dataset) -> Dataset:
    """The tilted set with each line's tilt less its own mean: the tilt's shape without
    the offset it adds to the line (one line cannot tell an offset of its force zero
    from friction; a trace/retrace pair can), so the two tilted sets tell apart what
    the shape costs from what the offset costs."""
    F0 = np.asarray(clean.force_nN, float)
    base = np.asarray(tilted.force_nN, float) - F0
    F = F0 + base - base.mean(axis=1, keepdims=True)
    return Dataset(F, tilted.x_nm, tilted.params, {**tilted.attrs,
                                                    "kind": f"{tilted.attrs['kind']}-zero-mean"})


# -------------------------------------------------------------------- scoring


def _refusing_regime(regime_str: Any) -> bool:
    s = str(regime_str or "").lower()
    return any(w in s for w in ("smooth", "oscillat", "not stick", "no stick", "sliding"))


def score_spring_block(tab: dict[str, np.ndarray], xs: list[np.ndarray],
                       Fs: list[np.ndarray], chunk: int = 24) -> dict[str, np.ndarray]:  # fmt: skip
    """Run the estimator on every line (as ``label --temperature 0 --velocity v``)."""
    est = ClassicalEstimator()
    out: dict[str, list] = {"quality": [], "regime": [], "k_exp": []}
    n = len(xs)
    for a in tqdm(range(0, n, chunk), desc="estimate spring-block", unit="chunk"):
        traces = [Trace(x_nm=xs[i], force_nN=Fs[i], name=f"sb:{i:04d}", source="stress",
                        meta={"velocity_nm_per_s": float(tab["velocity_m_per_s"][i] * 1e9),
                              "temperature_K": 0.0})
                  for i in range(a, min(a + chunk, n))]  # fmt: skip
        # estimate(), not predict(): a macroscopic slider's forces (up to 1e9 nN) and
        # scans (mm) lie outside the AFM range that predict() refuses before estimating
        rows, _ = est.estimate(traces, est.conditions(traces))
        for r in rows:
            r = {"quality": r} if isinstance(r, str) else r
            out["quality"].append(str(r.get("quality", "")))
            out["regime"].append(str(r.get("regime", "") or ""))
            out["k_exp"].append(float(r.get("k_exp_N_m", np.nan)))
    return {k: np.asarray(v) for k, v in out.items()}


def _frac(m: np.ndarray) -> float:
    return float(m.mean()) if m.size else float("nan")


def sb_group(err: np.ndarray, answered: np.ndarray, refused: np.ndarray,
             reg: np.ndarray) -> dict[str, Any]:  # fmt: skip
    """Figures of one group of spring-block lines (err: k_exp/k - 1)."""
    out: dict[str, Any] = {"n": int(reg.size)}
    for name in REGIMES:
        m = reg == name
        a = answered & m
        e = np.abs(err[a])
        g: dict[str, Any] = {"n": int(m.sum()), "answered": _frac(answered[m]),
                             "off20": int(np.sum(e > T_OFF))}  # fmt: skip
        if name == "sticks":
            g.update({"within10_of_all": _frac((np.abs(err) <= T_WITHIN)[m] & answered[m]),
                      "within10_of_answered": _frac(e <= T_WITHIN),
                      "median_err": float(np.median(e)) if e.size else float("nan"),
                      "max_err": float(e.max()) if e.size else float("nan")})  # fmt: skip
        if name == "oscillation":
            g["refused"] = _frac(refused[m])
        out[name] = g
    return out


def bins_of(values: np.ndarray, edges: tuple[float, ...], labels: tuple[str, ...]
            ) -> np.ndarray:  # fmt: skip
    idx = np.searchsorted(np.asarray(edges), values, side="right")
    return np.asarray(labels, dtype=object)[idx]


def spring_block_report(tab: dict[str, np.ndarray], est: dict[str, np.ndarray]) -> dict:
    k = tab["k_N_per_m"]
    err = est["k_exp"] / k - 1.0
    answered = (est["quality"] == "ok") & np.isfinite(est["k_exp"])
    refused = ~answered | np.array([_refusing_regime(r) for r in est["regime"]])
    reg = np.asarray(REGIMES, dtype=object)[tab["regime"]]
    res: dict[str, Any] = {"groups": {}, "by_samples_per_slip": {}, "by_baseline": {},
                           "by_law": {}}  # fmt: skip
    sets = {"all": np.ones(k.size, bool), "broad": tab["set"] == 0, "paper": tab["set"] == 1}
    for name, m in sets.items():
        res["groups"][name] = sb_group(err[m], answered[m], refused[m], reg[m])
    sps = tab["samples_per_slip"]
    sps_bin = bins_of(np.where(np.isfinite(sps), sps, np.inf), (10.0, 100.0, 1e3, 1e4, math.inf),
                      ("<10", "10-100", "100-1k", "1k-10k", ">=10k", "no slip"))  # fmt: skip
    base_bin = bins_of(tab["wander_drops"], (0.0, 0.3, 1.0, 3.0),
                       ("none", "<0.3", "0.3-1", "1-3", "3-10"))  # fmt: skip
    for key, labels, b in (("by_samples_per_slip", ("<10", "10-100", "100-1k", "1k-10k",
                                                    ">=10k", "no slip"), sps_bin),
                           ("by_baseline", ("none", "<0.3", "0.3-1", "1-3", "3-10"), base_bin),
                           ("by_law", LAWS,
                            np.asarray(LAWS, dtype=object)[tab["law"]])):  # fmt: skip
        for lab in labels:
            m = b == lab
            if m.any():
                res[key][lab] = sb_group(err[m], answered[m], refused[m], reg[m])
    # refusals: quality and regime counts, per true regime
    res["refusals"] = {name: {"quality": dict(collections.Counter(est["quality"][reg == name])),
                              "regime": dict(collections.Counter(est["regime"][reg == name]))}
                       for name in REGIMES}  # fmt: skip
    worst = np.argsort(-np.where(answered, np.abs(err), -1))[:10]
    res["worst_answered"] = [{"line": int(i), "regime": str(reg[i]), "err": float(err[i]),
                              "samples_per_slip": float(sps[i]),
                              "wander_drops": float(tab["wander_drops"][i])}
                             for i in worst if answered[i]]  # fmt: skip
    return res


def _as_map_line(traces: list[Trace], direction: str) -> list[Trace]:
    for t in traces:
        t.meta.update(direction=direction, line=t.meta["index"])
        t.source = "pairs"
    return traces


def score_afm(data: Dataset, est: ClassicalEstimator, retrace: Dataset | None = None,
              applied: np.ndarray | None = None) -> dict[str, Any]:  # fmt: skip
    """Answered fraction, rel. RMSE, median and 95th percentile of U0 and K (of the
    trace rows, estimated beside their ``retrace`` rows where given); with ``applied``
    (which effect families each line got), per family the K rel. RMSE of the answered
    lines with it and without it (``K_by_family``), and the share of them answered."""
    ok = in_eta_window(data.params["eta"])
    traces = dataset_traces(data, rows=np.flatnonzero(ok))
    if retrace is not None:
        traces = (_as_map_line(traces, "trace")
                  + _as_map_line(dataset_traces(retrace, rows=np.flatnonzero(ok)), "retrace"))
    rows = est.predict(traces).rows[:int(ok.sum())]
    answered = np.array([r["quality"] == "ok" and np.isfinite(r["K_N_m"])
                         and np.isfinite(r["U0_eV"]) for r in rows], dtype=bool)  # fmt: skip
    out: dict[str, Any] = {"n": len(rows), "answered": _frac(answered)}
    rel_K = np.full(len(rows), np.nan)  # each row's K rel. error (NaN where not answered)
    for key, name in (("K_N_m", "K"), ("U0_eV", "U0")):
        got = np.array([r.get(key, np.nan) for r in rows], dtype=float)[answered]
        rel = got / np.asarray(data.params[key], float)[ok][answered] - 1.0
        if key == "K_N_m":
            rel_K[answered] = rel
        a = np.abs(rel)
        out[f"{name}_rel_rmse"] = float(np.sqrt(np.mean(rel**2))) if rel.size else np.nan
        out[f"{name}_median"] = float(np.median(a)) if a.size else np.nan
        out[f"{name}_p95"] = float(np.percentile(a, 95)) if a.size else np.nan
    out["refusals"] = dict(collections.Counter(r["quality"] for r in rows if r["quality"] != "ok"))
    out["answered_at_K_target"] = answered_at_target(rel_K[answered], len(rows))
    if applied is not None:
        A = np.asarray(applied, bool)[ok]

        def rmse(m: np.ndarray) -> float:
            v = rel_K[m & answered]
            return float(np.sqrt(np.mean(v**2))) if v.size else np.nan

        out["K_by_family"] = {f: {"n": int(A[:, j].sum()), "answered": _frac(answered[A[:, j]]),
                                  "with": rmse(A[:, j]), "without": rmse(~A[:, j])}
                              for j, f in enumerate(fx.FAMILIES) if A[:, j].any()}  # fmt: skip
    return out


def answered_at_target(rel: np.ndarray, n: int, target: float = T_AFM_K_RMSE) -> float:
    """The share of ``n`` lines left answered if the answered rows of relative errors
    ``rel`` were refused worst first until their RMSE reaches ``target``: what an
    oracle refusal, which knows every truth, would attain. Below the answered target
    no refusal rule meets both targets; only better estimates can."""
    sq = np.sort(np.asarray(rel, float) ** 2)[::-1]
    left = sq.size
    while left > 0 and np.sqrt(np.mean(sq[sq.size - left:])) > target:
        left -= 1
    return left / n if n else np.nan


# -------------------------------------------------------------------- printing


def _pct(x: float) -> str:
    return "   -  " if not np.isfinite(x) else f"{100 * x:5.1f}%"


def print_sb(res: dict) -> None:
    print("\nA. spring-block (k from the stick slope k_exp_N_m; temperature 0 K)")
    print(f"  targets: sticks answered >= {T_ANSWERED:.0%}, answered k within "
          f"{T_WITHIN:.0%} (all of them), median |err| <= {T_MEDIAN:.0%}; oscillation "
          f"refused >= {T_REFUSED:.0%}; answered rows > {T_OFF:.0%} off: 0 in every regime")
    hdr = (f"  {'group':22s} {'n':>4s} | {'sticks':>6s} {'answer':>6s} {'<=10%':>6s} "
           f"{'<=10%a':>6s} {'median':>6s} {'max':>7s} {'>20%':>4s} | {'osc':>4s} "
           f"{'refuse':>6s} {'>20%':>4s} | {'grey':>4s} {'>20%':>4s}")  # fmt: skip
    def row(name: str, g: dict) -> str:  # noqa: E306
        s, o, gr = g["sticks"], g["oscillation"], g["grey"]
        return (f"  {name:22s} {g['n']:4d} | {s['n']:6d} {_pct(s['answered'])} "
                f"{_pct(s['within10_of_all'])} {_pct(s['within10_of_answered'])} "
                f"{_pct(s['median_err'])} {_pct(s['max_err']):>7s} {s['off20']:4d} | "
                f"{o['n']:4d} {_pct(o['refused'])} {o['off20']:4d} | {gr['n']:4d} "
                f"{gr['off20']:4d}")  # fmt: skip
    print("  columns: sticks: n, answered, within 10 % of all / of answered, median and max "
          "|k_exp/k - 1| of answered, answered > 20 % off; oscillation: n, refused, "
          "answered > 20 % off; grey: n, answered > 20 % off")
    print(hdr)
    for name, g in res["groups"].items():
        print(row(f"set {name}", g))
    for key, title in (("by_samples_per_slip", "samples per slip"),
                       ("by_baseline", "wander (drops)"), ("by_law", "law")):  # fmt: skip
        print(f"  -- by {title}")
        for lab, g in res[key].items():
            print(row(f"{lab}", g))
    print("  refusals per true regime (quality; regime strings):")
    for name, d in res["refusals"].items():
        q = ", ".join(f"{k} {v}" for k, v in sorted(d["quality"].items()))
        r = ", ".join(f"{k or '-'} {v}" for k, v in sorted(d["regime"].items()))
        print(f"    {name:12s} quality: {q}\n    {'':12s} regime:  {r}")
    if res["worst_answered"]:
        print("  worst answered rows: " + "; ".join(
            f"#{w['line']} {w['regime']} {w['err']:+.2f} ({w['samples_per_slip']:.0f} sps, "
            f"wander {w['wander_drops']:.1f})" for w in res["worst_answered"][:6]))


def print_afm(res: dict) -> None:
    print("\nB. AFM lab-like lines (1.5 <= eta <= 40, ClassicalEstimator().predict)")
    print(f"  targets: answered >= {T_AFM_ANSWERED:.0%} and K rel. RMSE <= "
          f"{T_AFM_K_RMSE:.0%} (families, bench, with and without tilt); clean PT: U0 and K "
          f"median <= {T_CLEAN_MEDIAN:.0%}, p95 <= {T_CLEAN_P95:.0%}")
    print(f"  oracle: the share left answered if the worst answered rows were refused until "
          f"K's rel. RMSE reaches {T_AFM_K_RMSE:.0%} (a refusal that knows the truths)")
    print(f"  {'set':18s} {'n':>4s} {'answer':>6s} {'K rRMSE':>8s} {'K med':>6s} {'K p95':>6s}"
          f" {'U0 rRMSE':>8s} {'U0 med':>6s} {'U0 p95':>6s} {'oracle':>6s}  refusals")  # fmt: skip
    for name, r in res.items():
        reasons = ", ".join(f"{k} {v}" for k, v in sorted(r["refusals"].items()))
        print(f"  {name:18s} {r['n']:4d} {_pct(r['answered'])} {_pct(r['K_rel_rmse']):>8s} "
              f"{_pct(r['K_median'])} {_pct(r['K_p95'])} {_pct(r['U0_rel_rmse']):>8s} "
              f"{_pct(r['U0_median'])} {_pct(r['U0_p95'])} "
              f"{_pct(r.get('answered_at_K_target', np.nan))}  {reasons}")  # fmt: skip
    for name, r in res.items():
        if "K_by_family" in r:
            print(f"  {name}: K rel. RMSE of the answered lines with / without each family "
                  "(lines with it, share answered): " + "; ".join(
                      f"{f} {_pct(v['with']).strip()} / {_pct(v['without']).strip()} "
                      f"({v['n']}, {_pct(v['answered']).strip()})"
                      for f, v in r["K_by_family"].items()))  # fmt: skip


def machine() -> dict[str, Any]:
    try:
        head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"],
                              capture_output=True, text=True,
                              check=False).stdout.strip()  # fmt: skip
    except OSError:
        head = ""
    return {"platform": platform.platform(), "processor": platform.processor()
            or platform.machine(), "cpu_count": os.cpu_count(),
            "numba_threads": os.environ.get("NUMBA_NUM_THREADS", "default"),
            "python": platform.python_version(), "git_head": head,
            "stickslip": str(Path(stickslip.__file__).parent),
            "date": datetime.datetime.now().astimezone().isoformat(timespec="seconds")}  # fmt: skip


def shift_seeds(shift: int) -> None:
    """Move every seed of the corpus by ``shift`` (module state: the draws read it)."""
    g = globals()
    for name in ("SEED_BROAD", "SEED_PAPER", "SEED_STRENGTH", "SEED_INSTRUMENT", "SEED_POOL",
                 "SEED_FAMILIES", "SEED_FAMILY_TILT", "SEED_BENCH", "SEED_BENCH_TILT",
                 "SEED_CLEAN", "SEED_CLEAN_RETRACE", "SEED_CLEAN_TILT"):  # fmt: skip
        g[name] += shift
    for key in SEEDS:
        SEEDS[key] += shift


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", type=Path, default=ROOT / "build" / "stress")
    ap.add_argument("--quick", action="store_true",
                    help=f"every {QUICK_EVERY}th spring-block line, {N_AFM_QUICK} AFM lines a set")
    ap.add_argument("--json", type=Path, default=None, help="write the figures here")
    ap.add_argument("--regenerate", action="store_true", help="remake the spring-block corpus")
    ap.add_argument("--no-afm", action="store_true", help="score the spring-block set only")
    ap.add_argument("--seed-shift", type=int, default=0,
                    help="add this to every seed (another draw of the same corpus, cached "
                         "under WORK/shift<N>): 10000 is the estimator's tuning draw, 20000 "
                         "a second held-out draw")  # fmt: skip
    args = ap.parse_args()
    if args.seed_shift:
        shift_seeds(args.seed_shift)
        args.work = args.work / f"shift{args.seed_shift}"
    args.work.mkdir(parents=True, exist_ok=True)
    info = machine()
    print(f"machine: {info['platform']}, {info['processor']}, {info['cpu_count']} cores, "
          f"numba threads {info['numba_threads']}, python {info['python']}; "
          f"{info['date']}; repository HEAD {info['git_head']}; stickslip imported from "
          f"{info['stickslip']}")  # fmt: skip
    t0 = time.perf_counter()
    path = corpus_if_missing(args.work, args.quick, args.regenerate)
    tab, xs, Fs = read_corpus(path)
    t_gen = time.perf_counter() - t0
    counts = collections.Counter(np.asarray(REGIMES)[tab["regime"]])
    print(f"spring-block corpus {path} ({len(xs)} lines, {sum(f.size for f in Fs):,} samples; "
          f"true regimes: {dict(counts)}) ready in {t_gen:.1f} s")  # fmt: skip
    t1 = time.perf_counter()
    est = score_spring_block(tab, xs, Fs)
    sb = spring_block_report(tab, est)
    t_sb = time.perf_counter() - t1
    print_sb(sb)
    print(f"  (estimated in {t_sb:.1f} s)")
    afm: dict[str, Any] = {}
    if not args.no_afm:
        t2 = time.perf_counter()
        sets, retraces, applied = afm_sets(args.work, args.quick)
        print(f"\nAFM sets ready in {time.perf_counter() - t2:.1f} s")
        ce = ClassicalEstimator()
        t3 = time.perf_counter()
        for name, (data, _) in sets.items():
            afm[name] = score_afm(data, ce, retraces.get(name), applied.get(name))
        print_afm(afm)
        print(f"  (estimated in {time.perf_counter() - t3:.1f} s)")
    total = time.perf_counter() - t0
    print(f"\ntotal {total:.1f} s")
    if args.json:
        doc = {"machine": info, "quick": args.quick, "corpus": str(path), "seeds": SEEDS,
               "thresholds": {"stuck_tolerance": STUCK_TOLERANCE, "stick_min": STICK_MIN,
                              "osc_max": OSC_MAX, "min_slips": MIN_SLIPS},
               "spring_block": sb, "afm": afm, "seconds": total}  # fmt: skip
        args.json.write_text(json.dumps(doc, indent=2, default=float) + "\n")
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
