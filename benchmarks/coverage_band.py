"""The 0.90-0.98 band of the 95 % intervals over several evaluation pools, against chance.

`benchmarks/families.py` writes one ``summary_<eval seed>.json`` per evaluation pool
(each pool made independently of training, of calibration and of the other pools). A
set of about 384 lines measures a coverage with a binomial standard error of about
0.011 at 0.95, so a set whose true coverage is 0.97 lands above 0.98 on one pool in
eight. This script reads the pools' summaries and prints, for <F>, U0 and K of every
"with f" and "all families" set calibrated on every family and of every set left out of
the calibration (leave-one-family-out):

- the coverage on each pool, and pooled over the pools (the lines of every pool
  together: three pools hold about 1,150 lines, standard error about 0.006);
- the cells (one set, one quantity, one pool) outside 0.90-0.98, and how many would
  fall outside by chance alone if each set's true coverage were its pooled coverage
  (the sum over cells of the binomial probability of landing outside the band);
- the sets whose pooled coverage itself lies outside the band, with the pooled coverage
  of their rows in domain (out of domain, the verdict widens the intervals on purpose;
  summaries written since 2026-11-26 hold it).

    python benchmarks/families.py --threads 2                      # pool 601
    python benchmarks/families.py --threads 2 --eval-seed 602 --n-bench 0 --no-pairs
    python benchmarks/families.py --threads 2 --eval-seed 603 --n-bench 0 --no-pairs
    python benchmarks/coverage_band.py [--work build/families] [--seeds 601 602 603]
"""

from __future__ import annotations

import argparse
import json
import platform
from pathlib import Path

import numpy as np
from scipy.stats import binom

ROOT = Path(__file__).resolve().parents[1]
LOW, HIGH = 0.90, 0.98
QUANTITIES = {"F_mean_nN": "<F>", "U0_eV": "U0", "K_N_m": "K"}


def outside_probability(n: int, p: float, low: float = LOW, high: float = HIGH) -> float:
    """Probability that a binomial coverage of ``n`` lines with true rate ``p`` lands
    outside ``[low, high]``."""
    # k / n > high  <=>  k >= floor(high n) + 1;  k / n < low  <=>  k <= ceil(low n) - 1
    above = binom.sf(np.floor(high * n + 1e-9), n, p)
    below = binom.cdf(np.ceil(low * n - 1e-9) - 1, n, p)
    return float(above + below)


Cell = tuple[int, float, int | None, float | None]


def cells(summaries: dict[int, dict]) -> dict[tuple[str, str, str], dict[int, Cell]]:
    """``(calibration, set, quantity) -> {pool: (lines, coverage, lines in domain, their
    coverage)}`` for the family sets calibrated on every family and the
    leave-one-family-out sets (the last two None in summaries written without them)."""
    out: dict[tuple[str, str, str], dict[int, Cell]] = {}
    for seed, s in summaries.items():
        rows = [("families", name, r) for name, r in s["families"].items()
                if name == "all families" or name.startswith("with ")]  # fmt: skip
        rows += [("left out", f"with {f}", r) for f, r in s.get("lofo", {}).items()]
        for cal, name, r in rows:
            for key, q in QUANTITIES.items():
                cov = float(r["coverage95"][key])
                inside = r.get("coverage95_in_domain", {}).get(key)
                n_in = r.get("n_in_domain")
                out.setdefault((cal, name, q), {})[seed] = (
                    int(r["n"]), cov, None if n_in is None else int(n_in),
                    None if inside is None else float(inside))  # fmt: skip
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", type=Path, default=ROOT / "build" / "families")
    ap.add_argument("--seeds", type=int, nargs="+", default=[601, 602, 603])
    args = ap.parse_args()
    summaries = {}
    for seed in args.seeds:
        path = args.work / f"summary_{seed}.json"
        if not path.is_file():
            raise SystemExit(f"{path}: missing; run benchmarks/families.py --eval-seed {seed}")
        summaries[seed] = json.loads(path.read_text())
    table = cells(summaries)
    seeds = " ".join(f"{s:>6d}" for s in args.seeds)
    print(f"95 % coverage per pool and pooled; band {LOW:.2f}-{HIGH:.2f}; * outside the band")
    print(f"  {'calibration':12s} {'set':26s} {'':4s} {seeds}  pooled  P(outside)")
    n_cells = n_out = 0
    per_pool = dict.fromkeys(args.seeds, 0)
    expected = 0.0
    pooled_out = []
    pooled: dict[str, float] = {}
    for (cal, name, q), per in table.items():
        n = np.array([per[s][0] for s in args.seeds if s in per])
        c = np.array([per[s][1] for s in args.seeds if s in per])
        p = float(np.sum(np.round(c * n)) / n.sum())
        probs = [outside_probability(int(ni), p) for ni in n]
        flags = [ci < LOW or ci > HIGH for ci in c]
        for s, f in zip((s for s in args.seeds if s in per), flags, strict=True):
            per_pool[s] += f
        n_cells += c.size
        n_out += sum(flags)
        expected += sum(probs)
        pooled[f"{cal} {name} {q}"] = p
        if not LOW <= p <= HIGH:
            text = f"{cal} {name} {q} {p:.3f}"
            m = [per[s][2:] for s in args.seeds if s in per]
            if all(ni is not None and ci is not None for ni, ci in m):
                n_in = sum(ni for ni, _ in m)
                c_in = sum(round(ni * ci) for ni, ci in m) / n_in
                text += f" ({c_in:.3f} on the {n_in} of {n.sum()} lines in domain)"
            pooled_out.append(text)
        cols = " ".join(f"{ci:.3f}{'*' if f else ' '}" for ci, f in zip(c, flags, strict=True))
        print(f"  {cal:12s} {name:26s} {q:4s} {cols}  {p:.3f}   {np.mean(probs):.3f}")
    print(f"\ncells (set, quantity, pool): {n_cells}; outside the band: {n_out}; "
          f"expected outside by chance at each set's pooled coverage: {expected:.1f}")  # fmt: skip
    print("cells outside the band per pool: "
          + ", ".join(f"{s} {k}" for s, k in per_pool.items()))  # fmt: skip
    print(f"pooled coverages outside the band: {len(pooled_out)} of {len(table)}"
          + "".join(f"\n  {s}" for s in pooled_out))  # fmt: skip
    ranked = sorted(pooled, key=pooled.__getitem__)
    for label, keys in (("highest", ranked[:-4:-1]), ("lowest", ranked[:3])):
        print(f"{label} pooled: " + "; ".join(f"{k} {pooled[k]:.4f}" for k in keys))
    print(f"machine: {platform.processor() or platform.machine()}, {platform.system()}, "
          f"python {platform.python_version()}")  # fmt: skip


if __name__ == "__main__":
    main()
