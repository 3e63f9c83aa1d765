"""Held-out acquisition-factor sets (issue 41) and their scoring of the line estimator.

How the sets are made
---------------------
Every line is a clean finite-temperature Prandtl-Tomlinson trace of the project's
simulator (:func:`stickslip.simulators.simulate.simulate`, BAOAB, dt = 10 ns, CPU
backend) plus white Gaussian detector noise. The parameters are drawn here, by this
file's own code (not ``stickslip.simulators.sampling`` or ``randomised``):

- lattice spacing a uniform in [0.24, 0.33] nm, per line;
- U0 log-uniform in [0.3, 5] eV and K log-uniform in [2, 50] N/m, redrawn (per line)
  until eta = 2 pi^2 U0 / (K a^2) (:func:`stickslip.units.eta_from`) lies in [2, 35];
- noise std uniform in [0, 0.05] nN, per line, from its own random stream;
- the acquisition factor of the set at its level; every other factor at the paper
  preset (m = 1e-12 kg, Gamma = 1e7 1/s, v = 60 nm/s, T = 296 K, 11 nm as 512 px).

Sets (seed; lines per level; level sizes are multiples of 32 because the simulator
integrates 32 lines at a time and a partial block costs as much as a full one):

- ``damping``: Gamma = 0.1x, 0.3x (96 lines each), 1x, 3x, 10x (64 each) of 1e7 1/s;
  also scored pooled over the "low-damping third" 0.1-0.3x (seed 41001; 384 lines);
- ``mass``: m = 0.3x, 1x, 3x of 1e-12 kg, 128 each (seed 41002; 384 lines);
- ``velocity``: v = 15, 30, 60, 150 nm/s (96 each), 10 and 200 nm/s (64 each)
  (seed 41003; 512 lines; the simulation's cost goes as 1/v);
- ``temperature``: T = 260, 296, 330 K, 128 each (seed 41004; 384 lines);
- ``pixels``: (256 px, 5.5 nm), (1024 px, 22 nm), (256 px, 11 nm), (1024 px, 11 nm),
  (512 px, 25 nm), 64 each (seed 41005; 320 lines);
- ``all``: every factor drawn at random at once, 416 lines (seed 41006): per line
  Gamma log-uniform 0.1-10x, m log-uniform 0.3-3x, T uniform 260-330 K (and a, U0, K,
  noise as above); per group of 8 consecutive lines (52 groups, so that the simulator
  can batch them: a step layout is shared by a batch) v log-uniform 15-150 nm/s,
  pixels from {256, 512, 1024}, length uniform 5-25 nm. Also scored on its lines with
  Gamma < 0.3x and those with v < 30 nm/s.

Set of seed ``S``: parameters from ``numpy.random.default_rng([S, 1])``, noise levels
from ``default_rng([S, 2])``, noise samples from ``default_rng([S, 3])``, thermal noise
from the simulator's streams of ``(S, line index)`` (independent of how lines are
batched). The seeds 41001-41099 are reserved for issue 41 and used nowhere else in the
repository (41001-41006 used here). These sets are HELD OUT: never use them (or their
seeds) for training, calibration, early stopping, model selection or tuning of any
estimator; they exist only to measure.

Every stated condition is right: each trace carries its true lattice, velocity and
temperature as metadata (source ``file``); mass, damping, pixels and length are what a
user would not state. Truths: the drawn U0 and K, and <F> = the mean of the noiseless
simulated force line. Sets are cached in ``--cache`` (default build/acquisition/) as
``<set>.h5`` (h5py, chunked, gzip), with the draw configuration as a JSON attribute; a
set is regenerated only when its configuration changes (or with ``--regenerate``).

Scoring
-------
The estimator is called as a user calls it: ``stickslip.predict(traces, model=...)``
(the default line estimator, or ``--model PATH``), with the in/out-of-domain verdict
on. Per set, per level and per target, over the rows answered and over the rows in
domain only: n; RMSE (<F>, nN) or relative RMSE sqrt(mean((est/true - 1)^2)) (U0, K)
and the log RMSE sqrt(mean(ln(est/true)^2)); the median bias (<F>: nN; U0, K:
median(est/true) - 1); 68 % and 95 % coverage; the median 95 % half-width (<F>: nN;
U0, K: (ln hi - ln lo) / 2, a relative half-width); the median absolute error (<F>:
nN; U0, K: |ln(est/true)|); the sharpness ratio = median half-width / (median abs error
x 1.96 / 0.674), 1 where the half-width matches the errors of a Gaussian; and the mean
interval score at alpha = 0.05 (Gneiting & Raftery 2007, Winkler 1972) in nN for <F>
and in log space for U0, K. Refused rows (no estimate) and out-of-domain verdicts are
counted per level.

Usage: NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 python benchmarks/acquisition.py
       [--model PATH] [--cache build/acquisition] [--json FILE] [--scale 1.0]
       [--sets damping,mass,...] [--regenerate] [--code-note TEXT] [--contact ideal]
       [--zero-offset] [--seed-shift N]

The library is whatever ``import stickslip`` finds: to score the committed code while the
working tree holds uncommitted edits, export it and put it first on the path, e.g.
``git archive HEAD src | tar -x -C /tmp/head && PYTHONPATH=/tmp/head/src python ...``;
the JSON records the package's path (and ``--code-note``, e.g. the export's commit), the
repository HEAD where the package is this checkout's, and the model file's sha256.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import platform
import sys
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import h5py
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
BUNDLED_MODEL = ROOT / "src" / "stickslip" / "resources" / "line_model.pt"
FORMAT_VERSION = 1

# the paper preset (PhysicalSettings' defaults, ../shared/PHYSICS.md)
MASS_KG, DAMPING_PER_S, VELOCITY, TEMPERATURE_K = 1e-12, 1e7, 60.0, 296.0
PIXELS, LENGTH_NM, DT_S = 512, 11.0, 1e-8
FACTORS = ("damping_per_s", "mass_kg", "velocity_nm_per_s", "temperature_K", "pixels",
           "length_nm")  # fmt: skip
PRESET: dict[str, float] = {"damping_per_s": DAMPING_PER_S, "mass_kg": MASS_KG,
                            "velocity_nm_per_s": VELOCITY, "temperature_K": TEMPERATURE_K,
                            "pixels": PIXELS, "length_nm": LENGTH_NM}  # fmt: skip

TARGETS = ("F_mean_nN", "U0_eV", "K_N_m")
LOG_TARGETS = ("U0_eV", "K_N_m")
ALPHA = 0.05
Z95_OVER_MAD = 1.96 / 0.674  # ideal 95 % half-width over the median |error| (Gaussian)


@dataclass(frozen=True)
class Draw:
    """The parameter prior shared by every set (ranges; log-uniform where so named)."""

    U0_eV: tuple[float, float] = (0.3, 5.0)  # log-uniform
    K_N_m: tuple[float, float] = (2.0, 50.0)  # log-uniform
    eta: tuple[float, float] = (2.0, 35.0)  # rejection window
    lattice_nm: tuple[float, float] = (0.24, 0.33)  # uniform
    noise_nN: tuple[float, float] = (0.0, 0.05)  # uniform white-noise std
    dt_s: float = DT_S


@dataclass(frozen=True)
class Level:
    """One level of a factor set: a label, its number of lines, the factors it sets."""

    label: str
    n: int
    factors: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class SetSpec:
    """A held-out set: its seed, its levels, or ``random`` for every factor at once."""

    name: str
    seed: int
    levels: tuple[Level, ...]
    random: bool = False
    #: with ``random``: lines per group sharing one draw of velocity, pixels and length
    #: (the simulator integrates 32 lines at a time at one step layout: one line alone
    #: costs as much as a full block)
    shared_group: int = 8

    @property
    def n(self) -> int:
        """Number of lines in the set."""
        return sum(lv.n for lv in self.levels)

    def config(self, draw: Draw) -> dict[str, Any]:
        """The draw configuration stored with the cached set (JSON-able)."""
        return {"format_version": FORMAT_VERSION, "name": self.name, "seed": self.seed,
                "random_factors": self.random,
                "shared_group": self.shared_group if self.random else None,
                "levels": [asdict(lv) for lv in self.levels],
                "draw": asdict(draw), "preset": PRESET, "simulator_backend": "cpu"}  # fmt: skip


def _levels(key: str, values: list[tuple[str, int, float]]) -> tuple[Level, ...]:
    return tuple(Level(label, n, {key: v}) for label, n, v in values)


def set_specs(scale: float = 1.0) -> dict[str, SetSpec]:
    """The six sets of issue 41 (``scale`` multiplies every level's line count)."""

    def n(k: int) -> int:
        return max(2, round(k * scale))

    g, m = DAMPING_PER_S, MASS_KG
    specs = [
        SetSpec("damping", 41001, _levels("damping_per_s", [
            ("0.1x", n(96), 0.1 * g), ("0.3x", n(96), 0.3 * g), ("1x", n(64), g),
            ("3x", n(64), 3 * g), ("10x", n(64), 10 * g)])),
        SetSpec("mass", 41002, _levels("mass_kg", [
            ("0.3x", n(128), 0.3 * m), ("1x", n(128), m), ("3x", n(128), 3 * m)])),
        SetSpec("velocity", 41003, _levels("velocity_nm_per_s", [
            ("10 nm/s", n(64), 10.0), ("15 nm/s", n(96), 15.0), ("30 nm/s", n(96), 30.0),
            ("60 nm/s", n(96), 60.0), ("150 nm/s", n(96), 150.0),
            ("200 nm/s", n(64), 200.0)])),
        SetSpec("temperature", 41004, _levels("temperature_K", [
            ("260 K", n(128), 260.0), ("296 K", n(128), 296.0), ("330 K", n(128), 330.0)])),
        SetSpec("pixels", 41005, tuple(
            Level(f"{p} px {length:g} nm", n(64), {"pixels": p, "length_nm": length})
            for p, length in ((256, 5.5), (1024, 22.0), (256, 11.0), (1024, 11.0),
                              (512, 25.0)))),
        SetSpec("all", 41006, (Level("all random", n(416)),), random=True),
    ]  # fmt: skip
    return {s.name: s for s in specs}


def _log_uniform(rng: np.random.Generator, lo: float, hi: float, size: int) -> np.ndarray:
    return np.exp(rng.uniform(np.log(lo), np.log(hi), size))


def draw_parameters(spec: SetSpec, draw: Draw) -> dict[str, np.ndarray]:
    """Per-line parameters, conditions and noise level of a set (no simulation)."""
    from stickslip.units import eta_from

    rng = np.random.default_rng([spec.seed, 1])
    n = spec.n
    level = np.repeat(np.arange(len(spec.levels)), [lv.n for lv in spec.levels])
    p: dict[str, np.ndarray] = {"level": level}
    for f in FACTORS:
        p[f] = np.array([lv.factors.get(f, PRESET[f]) for lv in spec.levels], float)[level]
    if spec.random:
        p["damping_per_s"] = _log_uniform(rng, 0.1 * DAMPING_PER_S, 10 * DAMPING_PER_S, n)
        p["mass_kg"] = _log_uniform(rng, 0.3 * MASS_KG, 3 * MASS_KG, n)
        p["temperature_K"] = rng.uniform(260.0, 330.0, n)
        group = np.arange(n) // spec.shared_group
        n_groups = int(group.max()) + 1
        p["group"] = group
        p["velocity_nm_per_s"] = _log_uniform(rng, 15.0, 150.0, n_groups)[group]
        p["pixels"] = rng.choice([256.0, 512.0, 1024.0], n_groups)[group]
        p["length_nm"] = rng.uniform(5.0, 25.0, n_groups)[group]
    a = rng.uniform(*draw.lattice_nm, n)
    U0, K = np.empty(n), np.empty(n)
    todo = np.arange(n)
    while todo.size:  # rejection, per line, until eta is in the window
        u = _log_uniform(rng, *draw.U0_eV, todo.size)
        k = _log_uniform(rng, *draw.K_N_m, todo.size)
        eta = eta_from(u, k, a[todo])
        ok = (eta >= draw.eta[0]) & (eta <= draw.eta[1])
        U0[todo[ok]], K[todo[ok]] = u[ok], k[ok]
        todo = todo[~ok]
    p.update(U0_eV=U0, K_N_m=K, lattice_nm=a, eta=eta_from(U0, K, a))
    p["noise_nN"] = np.random.default_rng([spec.seed, 2]).uniform(*draw.noise_nN, n)
    return p


@dataclass
class LineSet:
    """A generated set: per-line parameters and truths, clean and noisy lines."""

    spec: SetSpec
    params: dict[str, np.ndarray]
    clean_nN: list[np.ndarray]
    noisy_nN: list[np.ndarray]

    def x_nm(self, i: int) -> np.ndarray:
        """Support positions of line ``i`` (0 at the first pixel, as the simulator's)."""
        pix = int(self.params["pixels"][i])
        return np.arange(pix) * (float(self.params["length_nm"][i]) / pix)


def simulate_set(spec: SetSpec, draw: Draw, log: Callable[[str], None] = print) -> LineSet:
    """Draw and simulate a set (the clean lines, their <F> truths, and the noisy lines)."""
    from stickslip.simulators.config import PhysicalSettings
    from stickslip.simulators.simulate import simulate

    p = draw_parameters(spec, draw)
    n = spec.n
    clean: list[np.ndarray] = [np.empty(0)] * n
    # one call per step layout (pixels, length, velocity): the kernel integrates 32
    # lines at a time and sorts each call's lines by warm-up
    groups: dict[tuple[float, float, float], list[int]] = {}
    for i in range(n):
        key = (p["pixels"][i], p["length_nm"][i], p["velocity_nm_per_s"][i])
        groups.setdefault(key, []).append(i)
    t0, done = time.perf_counter(), 0
    for (pix, length, _), members in groups.items():
        settings = PhysicalSettings(pixels=int(pix), length_nm=float(length), dt_s=draw.dt_s)
        sel = np.array(members)
        res = simulate(p["U0_eV"][sel], p["K_N_m"][sel], settings, seed=spec.seed,
                       indices=sel, lattice_nm=p["lattice_nm"][sel],
                       velocity_nm_per_s=p["velocity_nm_per_s"][sel],
                       temperature_K=p["temperature_K"][sel],
                       damping_per_s=p["damping_per_s"][sel], mass_kg=p["mass_kg"][sel],
                       backend="cpu")  # fmt: skip
        for j, i in enumerate(sel.tolist()):
            clean[i] = res.force_nN[j].copy()
        before, done = done, done + sel.size
        if done // 100 > before // 100 or done == n:
            log(f"  {spec.name}: {done}/{n} lines simulated ({time.perf_counter() - t0:.0f} s)")
    p["F_mean_nN"] = np.array([c.mean() for c in clean])
    rng = np.random.default_rng([spec.seed, 3])
    noisy = [c + s * rng.standard_normal(c.size) for c, s in zip(clean, p["noise_nN"],
                                                                  strict=True)]  # fmt: skip
    return LineSet(spec, p, clean, noisy)


def _padded(lines: list[np.ndarray]) -> np.ndarray:
    out = np.full((len(lines), max(c.size for c in lines)), np.nan, np.float32)
    for i, c in enumerate(lines):
        out[i, : c.size] = c
    return out


def save_set(ls: LineSet, path: Path, config: dict[str, Any]) -> None:
    """Write a set to HDF5 (chunked, gzip; lines NaN-padded to the longest), atomically."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".h5.part")
    with h5py.File(tmp, "w") as h:
        h.attrs["config"] = json.dumps(config, sort_keys=True)
        h.attrs["levels"] = json.dumps([lv.label for lv in ls.spec.levels])
        h.attrs["description"] = ("issue 41 held-out acquisition set (benchmarks/acquisition.py); "
                                  "never use for training or calibration")  # fmt: skip
        for name, lines in (("force_nN", ls.noisy_nN), ("clean_force_nN", ls.clean_nN)):
            arr = _padded(lines)
            h.create_dataset(name, data=arr, chunks=(min(64, arr.shape[0]), arr.shape[1]),
                             compression="gzip", shuffle=True)  # fmt: skip
        grp = h.create_group("params")
        for k, v in ls.params.items():
            grp.create_dataset(k, data=v)
    os.replace(tmp, path)


def load_set(spec: SetSpec, path: Path, config: dict[str, Any]) -> LineSet | None:
    """The cached set at ``path`` if it was made with ``config``, else None."""
    if not path.exists():
        return None
    with h5py.File(path, "r") as h:
        if h.attrs.get("config") != json.dumps(config, sort_keys=True):
            return None
        p = {k: h["params"][k][()] for k in h["params"]}
        pix = p["pixels"].astype(int)
        noisy = [h["force_nN"][i, : pix[i]].astype(float) for i in range(spec.n)]
        clean = [h["clean_force_nN"][i, : pix[i]].astype(float) for i in range(spec.n)]
    return LineSet(spec, p, clean, noisy)


def cached_set(spec: SetSpec, draw: Draw, cache: Path, regenerate: bool = False) -> LineSet:
    """A set from the cache, regenerated (and cached) when missing or its config changed."""
    config = spec.config(draw)
    path = cache / f"{spec.name}.h5"
    ls = None if regenerate else load_set(spec, path, config)
    if ls is None:
        print(f"generating set '{spec.name}' ({spec.n} lines, seed {spec.seed}) -> {path}",
              flush=True)  # fmt: skip
        ls = simulate_set(spec, draw, lambda s: print(s, flush=True))
        save_set(ls, path, config)
    return ls


def traces_of(ls: LineSet) -> list[Any]:
    """The noisy lines as ``Trace`` objects stating their true lattice, velocity and T."""
    from stickslip.traces.trace import Trace

    p = ls.params
    return [Trace(x_nm=ls.x_nm(i), force_nN=ls.noisy_nN[i], name=f"{ls.spec.name}:{i:04d}",
                  source=f"acquisition/{ls.spec.name}",
                  meta={"lattice_nm": float(p["lattice_nm"][i]),
                        "velocity_nm_per_s": float(p["velocity_nm_per_s"][i]),
                        "temperature_K": float(p["temperature_K"][i])})
            for i in range(ls.spec.n)]  # fmt: skip


def _col(rows: list[dict[str, Any]], key: str) -> np.ndarray:
    out = np.full(len(rows), np.nan)
    for i, r in enumerate(rows):
        v = r.get(key)
        if isinstance(v, (int, float, np.number)) and not isinstance(v, bool):
            out[i] = float(v)
    return out


def target_metrics(key: str, y: np.ndarray, est: np.ndarray, lo95: np.ndarray,
                   hi95: np.ndarray, lo68: np.ndarray, hi68: np.ndarray
                   ) -> dict[str, float]:  # fmt: skip
    """The metrics of one target over rows that all have an estimate (see module doc)."""
    nan = float("nan")
    n = int(y.size)
    out: dict[str, float] = {"n": n}
    if n == 0:
        return out
    # an estimator without intervals (the classical one) has no coverage, not 0
    intervals = bool(np.any(np.isfinite(lo95) & np.isfinite(hi95)))
    cov95 = float(np.mean((y >= lo95) & (y <= hi95))) if intervals else nan
    cov68 = float(np.mean((y >= lo68) & (y <= hi68))) if intervals else nan
    with np.errstate(divide="ignore", invalid="ignore"):
        if key in LOG_TARGETS:
            rel = est / y - 1.0
            out["rel_rmse"] = float(np.sqrt(np.mean(rel**2)))
            tr: Callable[[np.ndarray], np.ndarray] = np.log
            out["bias_median"] = float(np.median(rel))
            out["nonpositive_lo95"] = int(np.sum(~(lo95 > 0)))
        else:
            out["rmse_nN"] = float(np.sqrt(np.mean((est - y) ** 2)))
            out["bias_median"] = float(np.median(est - y))

            def tr(v: np.ndarray) -> np.ndarray:
                return v

        e, lo, hi, ty = tr(est), tr(lo95), tr(hi95), tr(y)
        err = e - ty
        if key in LOG_TARGETS:
            out["log_rmse"] = float(np.sqrt(np.mean(err**2)))
        hw = np.median((hi - lo) / 2.0)
        mae = np.median(np.abs(err))
        below = np.where(ty < lo, lo - ty, 0.0)
        above = np.where(ty > hi, ty - hi, 0.0)
        score = (hi - lo) + 2.0 / ALPHA * (below + above)
    out.update({
        "coverage95": cov95, "coverage68": cov68,
        "se95": float(np.sqrt(cov95 * (1 - cov95) / n)),
        "se68": float(np.sqrt(cov68 * (1 - cov68) / n)),
        "halfwidth95_median": float(hw), "abs_error_median": float(mae),
        "sharpness_ratio": float(hw / (mae * Z95_OVER_MAD)) if mae > 0 else nan,
        "interval_score95_mean": float(np.mean(score)),
    })  # fmt: skip
    return out


def group_metrics(rows: list[dict[str, Any]], truth: dict[str, np.ndarray],
                  mask: np.ndarray) -> dict[str, Any]:  # fmt: skip
    """Counts, and per target the metrics over rows answered and over rows in domain."""
    from stickslip.estimators.table import domain_verdict

    sub = [r for r, m in zip(rows, mask, strict=True) if m]
    answered = np.array([r.get("quality") == "ok" and np.isfinite(_col([r], "U0_eV")[0])
                         for r in sub], bool)  # fmt: skip
    in_domain = np.array([domain_verdict(r) is True for r in sub], bool) & answered
    out: dict[str, Any] = {"lines": len(sub), "refused": int((~answered).sum()),
                           "out_of_domain": int((answered & ~in_domain).sum())}  # fmt: skip
    reasons: dict[str, int] = {}
    for r in sub:
        if r.get("quality") != "ok":
            key = f"refused: {r.get('quality')}"
        elif domain_verdict(r) is not True:
            key = str(r.get("domain_reason"))
        else:
            continue
        key = key.split(" (")[0][:80]
        reasons[key] = reasons.get(key, 0) + 1
    out["reasons"] = dict(sorted(reasons.items(), key=lambda kv: -kv[1]))
    for scope, keep in (("answered", answered), ("in_domain", in_domain)):
        rs = [r for r, k in zip(sub, keep, strict=True) if k]
        y_all = {k: truth[k][mask] for k in TARGETS}
        out[scope] = {}
        for k in TARGETS:
            est = _col(rs, k)
            ok = np.isfinite(est)
            cols = [_col(rs, f"{k}_{b}")[ok] for b in ("lo95", "hi95", "lo68", "hi68")]
            out[scope][k] = target_metrics(k, y_all[k][keep][ok], est[ok], *cols)
    return out


def groups_of(ls: LineSet) -> dict[str, np.ndarray]:
    """Masks scored for a set: each level, pooled groups, and the whole set."""
    p, spec = ls.params, ls.spec
    out: dict[str, np.ndarray] = {}
    if len(spec.levels) > 1:
        for j, lv in enumerate(spec.levels):
            out[lv.label] = p["level"] == j
    if spec.name == "damping":
        out["0.1-0.3x pooled"] = p["damping_per_s"] <= 0.3 * DAMPING_PER_S * 1.0001
    if spec.name == "all":
        out["damping < 0.3x"] = p["damping_per_s"] < 0.3 * DAMPING_PER_S
        out["v < 30 nm/s"] = p["velocity_nm_per_s"] < 30.0
    out["whole set"] = np.ones(spec.n, bool)
    return out


def predict_set(ls: LineSet, estimator: Any
                ) -> tuple[list[dict[str, Any]], dict[str, np.ndarray], float]:  # fmt: skip
    """Predict every line of a set through ``stickslip.predict`` as a user calls it: the
    rows in the set's order, the truths of ``TARGETS`` and the seconds it took."""
    import stickslip

    traces = traces_of(ls)
    t0 = time.perf_counter()
    table = stickslip.predict(traces, model=estimator)
    seconds = time.perf_counter() - t0
    by_name = {r["trace"]: r for r in table.rows}
    truth = {k: np.asarray(ls.params[k], float) for k in TARGETS}
    return [by_name[t.name] for t in traces], truth, seconds


def score_set(ls: LineSet, estimator: Any) -> tuple[dict[str, Any], float]:
    """:func:`predict_set`, then the metrics per group (:func:`groups_of`)."""
    rows, truth, seconds = predict_set(ls, estimator)
    return {g: group_metrics(rows, truth, m) for g, m in groups_of(ls).items()}, seconds


HEADER = (f"    {'target':7s} {'scope':6s} {'n':>4s} {'(r)RMSE':>8s} {'logRMSE':>7s} "
          f"{'bias':>7s} {'cov95':>6s} {'cov68':>6s} {'hw95':>7s} {'med|e|':>7s} "
          f"{'sharp':>6s} {'IS95':>7s}")  # fmt: skip


def _fmt(v: Any, spec: str) -> str:
    return "nan" if v is None or not np.isfinite(v) else format(v, spec)


def print_group(name: str, g: dict[str, Any]) -> None:
    """One group's counts and its rows per target and scope."""
    print(f"  {name}: {g['lines']} lines, refused {g['refused']}, "
          f"out of domain {g['out_of_domain']}")  # fmt: skip
    for k in TARGETS:
        short = {"F_mean_nN": "F nN", "U0_eV": "U0 rel", "K_N_m": "K rel"}[k]
        for scope, tag in (("answered", "answ"), ("in_domain", "in-dom")):
            m = g[scope][k]
            if m["n"] == 0:
                print(f"    {short:7s} {tag:6s} {0:4d}")
                continue
            rm = m["rmse_nN"] if k == "F_mean_nN" else m["rel_rmse"]
            pct = k != "F_mean_nN"
            print(f"    {short:7s} {tag:6s} {m['n']:4d} {_fmt(rm, '8.3f')} "
                  f"{_fmt(m.get('log_rmse', float('nan')), '7.3f') if pct else '      -'} "
                  f"{_fmt(m['bias_median'], '+7.3f')} {m['coverage95']:6.3f} "
                  f"{m['coverage68']:6.3f} {_fmt(m['halfwidth95_median'], '7.3f')} "
                  f"{_fmt(m['abs_error_median'], '7.3f')} {_fmt(m['sharpness_ratio'], '6.2f')} "
                  f"{_fmt(m['interval_score95_mean'], '7.3f')}")  # fmt: skip


def provenance(note: str | None = None) -> dict[str, Any]:
    """Which stickslip code ran: the imported package's path and version, and, where it
    is this checkout's, the repository HEAD and whether the package has uncommitted
    edits (an exported copy is described by ``note`` instead)."""
    import subprocess

    import stickslip

    lib = Path(stickslip.__file__).resolve().parent
    out: dict[str, Any] = {"stickslip_path": str(lib), "stickslip_version": stickslip.__version__,
                           "note": note}  # fmt: skip
    if lib != (ROOT / "src" / "stickslip").resolve():
        out["package"] = "outside this checkout"
        return out
    git = ["git", "-C", str(ROOT)]
    try:
        out["repo_head"] = subprocess.run([*git, "rev-parse", "HEAD"], capture_output=True,
                                          text=True, check=True).stdout.strip()  # fmt: skip
        dirty = subprocess.run([*git, "status", "--porcelain", "--", str(lib)],
                               capture_output=True, text=True, check=True).stdout  # fmt: skip
        out["package"] = "this checkout" + (", with uncommitted edits" if dirty.strip() else "")
    except (OSError, subprocess.CalledProcessError):
        out["package"] = "this checkout"
    return out


def machine() -> dict[str, Any]:
    """Platform, CPU count and thread settings of this run."""
    import torch

    return {"platform": platform.platform(), "processor": platform.processor() or
            platform.machine(), "cpu_count": os.cpu_count(), "python": platform.python_version(),
            "torch": torch.__version__, "torch_threads": torch.get_num_threads(),
            "NUMBA_NUM_THREADS": os.environ.get("NUMBA_NUM_THREADS")}  # fmt: skip


def main() -> None:
    """Generate (or load) the sets, score the model, print the table, write the JSON."""
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument(
        "--model",
        type=Path,
        default=None,
        help=f"line-model file to score (default: the bundled {BUNDLED_MODEL.name})",
    )
    ap.add_argument("--cache", type=Path, default=ROOT / "build" / "acquisition")
    ap.add_argument("--json", type=Path, default=None, help="write the results here")
    ap.add_argument(
        "--sets", default=",".join(set_specs()), help="comma-separated subset of the sets"
    )
    ap.add_argument(
        "--scale",
        type=float,
        default=1.0,
        help="multiply every level's line count (smoke tests; changes the sets)",
    )
    ap.add_argument("--regenerate", action="store_true", help="ignore the cache")
    ap.add_argument("--contact", default="any",
                    help="the contact stated to the line model (any, ideal: --contact)")
    ap.add_argument("--zero-offset", action="store_true",
                    help="state that the lines' zero carries no offset (--zero-offset): "
                         "<F>'s interval is the model's own")  # fmt: skip
    ap.add_argument("--seed-shift", type=int, default=0,
                    help="move every set's seed by this (fresh sets within 41001-41099, "
                         "cached under --cache/shiftN)")  # fmt: skip
    ap.add_argument(
        "--code-note",
        default=None,
        help="what the imported stickslip is (recorded; e.g. an export's commit)",
    )
    args = ap.parse_args()
    t_start = time.perf_counter()
    from stickslip.estimators.load import load_estimator, state_contact, state_zero_offset

    specs = {name: replace(spec, seed=spec.seed + args.seed_shift)
             for name, spec in set_specs(args.scale).items()}
    cache = args.cache / f"shift{args.seed_shift}" if args.seed_shift else args.cache
    names = [s.strip() for s in args.sets.split(",") if s.strip()]
    unknown = [s for s in names if s not in specs]
    if unknown:
        ap.error(f"unknown set(s) {', '.join(unknown)}; choose from {', '.join(specs)}")
    mach = machine()
    print(f"machine: {mach['platform']}, {mach['processor']}, {mach['cpu_count']} CPUs, "
          f"python {mach['python']}, torch {mach['torch']} ({mach['torch_threads']} threads), "
          f"NUMBA_NUM_THREADS={mach['NUMBA_NUM_THREADS']}")  # fmt: skip
    prov = provenance(args.code_note)
    bundled = Path(prov["stickslip_path"]) / "resources" / BUNDLED_MODEL.name
    model = str(args.model) if args.model else f"bundled ({bundled})"
    model_sha256 = hashlib.sha256((args.model or bundled).read_bytes()).hexdigest()
    print(f"model: {model}, sha256 {model_sha256[:16]}")
    print(f"stickslip {prov['stickslip_version']} from {prov['stickslip_path']} "
          f"({prov['package']}" + (f", HEAD {prov['repo_head'][:10]}" if "repo_head" in prov
                                   else "") + ")" + (f"; {args.code_note}" if args.code_note
                                                      else ""))  # fmt: skip
    estimator = state_zero_offset(state_contact(load_estimator(args.model), args.contact),
                                  args.zero_offset)  # fmt: skip
    print(f"estimator: {estimator.describe()}")
    draw = Draw()
    results: dict[str, Any] = {}
    timing: dict[str, dict[str, float]] = {}
    for name in names:
        spec = specs[name]
        t0 = time.perf_counter()
        ls = cached_set(spec, draw, cache, args.regenerate)
        t_gen = time.perf_counter() - t0
        groups, t_pred = score_set(ls, estimator)
        timing[name] = {"load_or_generate_s": t_gen, "predict_s": t_pred}
        results[name] = {"seed": spec.seed, "lines": spec.n, "config": spec.config(draw),
                         "groups": groups}  # fmt: skip
        print(f"\n== set '{name}' (seed {spec.seed}, {spec.n} lines; data {t_gen:.0f} s, "
              f"predict {t_pred:.1f} s) ==")  # fmt: skip
        print(HEADER)
        for g, m in groups.items():
            print_group(g, m)
        whole = groups["whole set"]["reasons"]
        if whole:
            print("  not answered / out of domain, by reason: " +
                  "; ".join(f"{v} x {k}" for k, v in list(whole.items())[:4]))  # fmt: skip
    total = time.perf_counter() - t_start
    print(f"\nlegend: F in nN (RMSE, median bias, half-width, |e|, interval score); U0, K: "
          f"rRMSE = sqrt(mean((est/true-1)^2)), bias = median(est/true)-1, hw95 = (ln hi - "
          f"ln lo)/2, |e| = |ln(est/true)|, IS95 in log space; sharp = hw95 / (med|e| x "
          f"1.96/0.674); scope answ = rows answered, in-dom = rows the verdict keeps in "
          f"domain.\ntotal wall time {total:.0f} s")  # fmt: skip
    if args.json:
        doc = {"description": "issue 41 held-out acquisition sets, scored by "
               "benchmarks/acquisition.py", "command": " ".join(sys.argv), "model": model,
               "model_sha256": model_sha256, "code": prov,
               "date": time.strftime("%Y-%m-%d"),
               "machine": mach, "draw": asdict(draw), "alpha": ALPHA, "sets": results,
               "timing_s": timing, "total_wall_s": total}  # fmt: skip
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(_json_safe(doc), indent=1, allow_nan=False) + "\n")
        print(f"wrote {args.json}")


def _json_safe(obj: Any) -> Any:
    """Plain JSON values: numpy scalars as Python ones, non-finite floats as null."""
    if isinstance(obj, dict):
        return {str(k): _json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_json_safe(v) for v in obj]
    if isinstance(obj, (np.integer, np.bool_)):
        return obj.item()
    if isinstance(obj, (float, np.floating)):
        return float(obj) if np.isfinite(obj) else None
    return obj


if __name__ == "__main__":
    main()
