"""What the map's defect flags could see: the shipped local filter against a detector told
where the defect is and what it looks like, at the same share of normal lines flagged.

The per-map pooling flags a line crossing a surface defect by its local anomaly
(``stickslip.estimators.evidence.local_evidence``: the largest response along the line
of a filter a few lattice periods wide, scored against the map's other lines, the two
scan directions summed). It does not know where the defect is, so it pays for looking
everywhere: the largest of some fifteen independent responses per line. This benchmark
measures that price on the maps of ``benchmarks/map_pooling.py`` (its line simulation,
shared per-map effects and per-line detector effects, imported from it):

- per parameter point, clean lines and lines crossing two Gaussian defects of barrier
  ``--barrier`` U0 (0.6 nm wide) at the *same* two positions, trace and retrace;
- four maps of ``--lines``/4 clean and as many defect lines each, every map with its own
  shared effects;
- the *told* detector: the mean defect response of maps 0-1 (defect lines' level less
  the clean lines', the level being the line's mean over one lattice period, an offset,
  slope and curvature taken off), correlated with the lines of maps 2-3 at the known
  positions: an upper bound that no detector blind to the position can reach;
- the *shipped* filter on the same lines of maps 2-3;
- a *blind likelihood*: the shipped filter's response along the line, in units of the
  map's own noise scale of it (the median over the map's clean lines of each line's
  1.4826 median |response|), turned into the likelihood ratio of a bump at each position
  with an unknown amplitude, ``exp(r^2 / 2)``, averaged over the positions (a uniform
  prior on where the defect is): what a detector can do that knows the shape of the
  filter but not the position, without the shipped filter's per-line scale;
- a *shape-told likelihood*: the same position-averaged likelihood ratio, one-sided
  (a barrier pushes one way), with the filter replaced by the point's own response to one
  defect (learned from ``--lines`` further lines of the point, trace and retrace, each
  crossing one defect at the window's middle, 7 nm, without map effects: the defect
  lines' mean level less the clean lines', cut to 6 lattice periods either side of its
  middle, made blind to an offset, a slope and a curvature): the best a detector
  blind to the position can do when it knows everything else about the defect. Where it
  stays short of the told detector, what is missing is the position;
- all scored as the pooling scores (robust z against the map's clean lines, trace and
  retrace summed over sqrt 2), flagged above the threshold that flags ``--fpr`` of the
  clean lines of all points together.

Seeds: ``--seed`` (default 777001, used by nothing else; it is a diagnostic, not a
scoring set of any method). The defects are those of the map benchmark's scoring sets,
but one pair of positions per point.

    python benchmarks/defect_bound.py [--seed 777001] [--points 12] [--lines 128]
        [--barrier 1.0] [--fpr 0.01]
"""

from __future__ import annotations

import argparse
import math
import time

import map_pooling as mp
import numpy as np
from _machine import machine_line
from scipy.signal import fftconvolve
from tqdm import tqdm

from stickslip.estimators.evidence import LOCAL_SCALE, local_evidence, local_kernel
from stickslip.estimators.periodic import sliding_period_mean
from stickslip.simulators import PhysicalSettings, simulate

MAPS = 4  # maps per point: the first two learn the told detector's template
#: Half-length of the shape-told detector's response, in lattice periods.
SHAPE_HALF = 6.0


def _robust_z(x: np.ndarray, ref: np.ndarray) -> np.ndarray:
    med = np.median(x[ref])
    return (x - med) / (1.4826 * np.median(np.abs(x[ref] - med)))


def _level(F: np.ndarray, period_px: float) -> np.ndarray:
    """Each line's mean over one lattice period, less its offset, slope and curvature."""
    L = sliding_period_mean(F, period_px)
    t = np.linspace(-1.0, 1.0, L.shape[1])
    Q, _ = np.linalg.qr(np.column_stack([np.ones_like(t), t, t * t]))
    return L - (L @ Q) @ Q.T


def blind_likelihood(F: np.ndarray, period_px: float, reference: np.ndarray) -> np.ndarray:
    """ln of the position-averaged likelihood ratio of a bump of the shipped filter's
    shape, each line's response in units of the map's noise scale (from ``reference``)."""
    k = local_kernel(LOCAL_SCALE * period_px)
    r = np.abs(fftconvolve(sliding_period_mean(F, period_px), k[None, ::-1], mode="valid",
                           axes=1))  # fmt: skip
    q = r / np.median(1.4826 * np.median(r[reference], axis=1))
    return np.log(np.mean(np.exp(0.5 * np.minimum(q, 30.0) ** 2), axis=1))


def one_defect_shapes(U0: float, K: float, n: int, seed: int, barrier: float) -> list[np.ndarray]:
    """The point's response to one defect at 7 nm (trace, retrace as the readers store
    them): the mean level of ``n`` lines crossing it less that of ``n`` clean lines, cut
    to :data:`SHAPE_HALF` periods either side of its middle (where the shipped filter
    answers most), blind to an offset, a slope and a curvature, of unit norm, signed so
    that its pairing with the mean response is positive."""
    s = PhysicalSettings()
    period = s.lattice_nm / s.pixel_nm
    U, Kv = np.full(n, U0), np.full(n, K)
    # the second defect far outside the window: one defect per line
    xs = np.tile([7.0, -1e3], (n, 1))
    bad = mp._defect_lines(U, Kv, xs, seed, barrier)
    clean = (simulate(U, Kv, s, seed=seed + 11).force_nN,
             simulate(U, Kv, s, seed=seed + 12).force_nN)  # fmt: skip
    out = []
    for d, key in enumerate(("defect", "defect_retrace")):
        r = _level(bad[key], period).mean(axis=0) - _level(clean[d], period).mean(axis=0)
        h = int(round(SHAPE_HALF * period))
        # centred where the shipped filter answers most: the dipole's middle
        k = local_kernel(LOCAL_SCALE * period)
        a = np.abs(np.correlate(r, k, mode="same"))
        c = int(np.clip(np.argmax(a), h, r.size - h - 1))
        w = r[c - h : c + h + 1]
        t = np.linspace(-1.0, 1.0, w.size)
        Q, _ = np.linalg.qr(np.column_stack([np.ones_like(t), t, t * t]))
        w = w - Q @ (Q.T @ w)
        out.append(w / np.linalg.norm(w))
    return out


def shape_likelihood(F: np.ndarray, period_px: float, shape: np.ndarray,
                     reference: np.ndarray) -> np.ndarray:  # fmt: skip
    """ln of the position-averaged one-sided likelihood ratio of one defect of the
    response ``shape``, the response in units of the map's noise scale of it (from the
    ``reference`` lines)."""
    r = fftconvolve(_level(F, period_px), shape[None, ::-1], mode="valid", axes=1)
    q = r / np.median(1.4826 * np.median(np.abs(r[reference]), axis=1))
    return np.log(np.mean(np.exp(0.5 * np.clip(q, 0.0, 30.0) ** 2), axis=1))


def point_scores(U0: float, K: float, xs: np.ndarray, n: int, seed: int, barrier: float,
                 rng: np.random.Generator) -> dict[str, np.ndarray]:  # fmt: skip
    """Each detector's paired scores of the test maps' lines of one parameter point
    (``told``, ``shape``, ``blind``, ``shipped``), and which of them cross the defects
    (``defect``)."""
    s = PhysicalSettings()
    period = s.lattice_nm / s.pixel_nm
    U, Kv = np.full(n, U0), np.full(n, K)
    clean = (simulate(U, Kv, s, seed=seed + 1).force_nN, simulate(U, Kv, s, seed=seed + 2).force_nN)
    bad = mp._defect_lines(U, Kv, np.tile(xs, (n, 1)), seed + 3, barrier)
    bad = (bad["defect"], bad["defect_retrace"])
    per = n // MAPS
    defect = np.r_[np.zeros(per, bool), np.ones(per, bool)]
    maps = []
    for m in range(MAPS):
        part = slice(m * per, (m + 1) * per)
        lines = np.stack([np.concatenate([clean[d][part], bad[d][part]]) for d in range(2)])
        traces, _ = mp.make_map(lines, rng, f"p{m}", mp.shared_effects(rng))
        maps.append(np.array([t.force_nN for t in traces]).reshape(2, 2 * per, -1))
    templates = []
    for d in range(2):
        L = np.concatenate([_level(maps[m][d], period) for m in range(2)])
        lab = np.tile(defect, 2)
        templates.append(L[lab].mean(axis=0) - L[~lab].mean(axis=0))
    shapes = one_defect_shapes(U0, K, n, seed + 1_000_000, barrier)  # seeds apart
    stats = {"told": lambda F, d: _level(F, period) @ templates[d],
             "shape": lambda F, d: shape_likelihood(F, period, shapes[d], ~defect),
             "shipped": lambda F, d: local_evidence(F, period),
             "blind": lambda F, d: blind_likelihood(F, period, ~defect)}  # fmt: skip
    out: dict[str, list] = {name: [] for name in stats}
    for m in range(2, MAPS):
        for name, stat in stats.items():
            z = [_robust_z(stat(maps[m][d], d), ~defect) for d in range(2)]
            out[name].append((z[0] + z[1]) / math.sqrt(2.0))
    return {**{k: np.concatenate(v) for k, v in out.items()},
            "defect": np.tile(defect, MAPS - 2)}  # fmt: skip


def flagged(score: np.ndarray, defect: np.ndarray, fpr: float) -> tuple[float, float]:
    """Share of defect lines above the threshold that flags ``fpr`` of the clean ones."""
    thr = float(np.quantile(score[~defect], 1.0 - fpr))
    return float(np.mean(score[defect] > thr)), thr


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--seed", type=int, default=777001)
    ap.add_argument("--points", type=int, default=12)
    ap.add_argument("--lines", type=int, default=128, help="clean (and defect) lines per point")
    ap.add_argument("--barrier", type=float, default=1.0, help="defect barrier, in units of U0")
    ap.add_argument("--fpr", type=float, default=0.01, help="share of clean lines flagged")
    args = ap.parse_args()
    print(machine_line())
    t0 = time.time()
    pts = mp._points(args.seed, args.points)
    rng = np.random.default_rng([args.seed, 7])
    names = ("told", "shape", "blind", "shipped")
    scores = []
    for p, (U0, K) in enumerate(tqdm(pts, desc="parameter points", unit="point")):
        xs = rng.uniform(3.0, 9.0, 2) + 2.0  # as map_pooling.defect_pools draws them
        scores.append(point_scores(U0, K, xs, args.lines, args.seed + 10 * p, args.barrier, rng))
    lab = np.concatenate([sc["defect"] for sc in scores])
    pooled = {k: flagged(np.concatenate([sc[k] for sc in scores]), lab, args.fpr) for k in names}
    print(f"\ndefect barrier {args.barrier:g} U0, {args.points} points, {lab.sum()} defect "
          f"and {(~lab).sum()} clean test lines; threshold at {args.fpr:.1%} of the clean "
          "lines")  # fmt: skip
    print(f"{'U0 eV':>6} {'K N/m':>6} {'eta':>5} | " + " ".join(f"{k:>7s}" for k in names)
          + "  (defect lines flagged at the pooled thresholds)")  # fmt: skip
    for (U0, K), sc in zip(pts, scores, strict=True):
        eta = float(mp.eta_from(U0, K, mp.A))
        d = sc["defect"]
        print(f"{U0:6.2f} {K:6.1f} {eta:5.1f} | "
              + " ".join(f"{np.mean(sc[k][d] > pooled[k][1]):7.2f}" for k in names))  # fmt: skip
    print(f"{'all':>20} | " + " ".join(f"{pooled[k][0]:7.3f}" for k in names))
    print(f"\n{time.time() - t0:.0f} s")


if __name__ == "__main__":
    main()
