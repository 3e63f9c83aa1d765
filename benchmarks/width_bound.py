"""How narrow a single line's U0 and K intervals could be: what the line tells of its error.

The bundled calibration sizes each line's 95 % interval from the ensemble's spread (a
power law per class of line). Issue 41 asks for a clean line's interval on clean lines
while every effect family stays covered. This benchmark measures how much of the error's
scale a line can tell at all, by fitting interval sizers of growing knowledge by the
mean interval score (Gneiting and Raftery 2007) of the 95 % interval of |error| of ln U0
and ln K, on the lines of even trajectories, and scoring them on the odd ones:

1. ``spread``: one power law of the ensemble's spread (the bundled calibration's form);
2. ``+ statistics``: a small network on the spread and three statistics of the mapped
   line (its force std, its mean, and the median |second difference|, the noise);
3. ``+ line``: the same with a 1D CNN that reads the whole mapped line;
4. ``+ substrate``: the statistics plus what no line states, given as truth: whether
   its substrate is modulated (and how much) or carries defects, whether it is a
   multi-asperity contact line and whether it is one of the members' training-effect
   lines;
5. ``+ oracle``: all that, and which effect families the line carries.

For each: the mean interval score, the coverage and the median 95 % half-width (log
units), on all test lines and on three groups: clean lines on a plain substrate (no
effect, no modulation, no defect, single point), clean lines on the augmented substrate
(modulation or defects) or contacts, and the rest. A CNN classifier trained to tell
precursor softening (the family behind most of the U0 and K tail, ``u0_width.py``) gives
its ROC AUC on the prior's test lines.

Lines: the calibration pool of ``benchmarks/families.py`` (600 trajectories of the
training prior, seed 501, which randomises the substrate on three quarters of them, and
the 640 multi-asperity contact lines the calibration keeps where one PT describes them),
with ``--draws`` draws of the nuisance prior and of the members' training effects drawn
on ``--seed`` (default 9601, used by nothing else). Nothing here is fitted into the
model; it is a diagnostic.

    python benchmarks/width_bound.py [--work build/families] [--seed 9601] [--draws 12]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import torch
from _machine import machine_line
from scipy.stats import rankdata
from torch import nn

from stickslip.diagnostics.metrics import interval_score
from stickslip.estimators.line.ensemble import predict_std_lines
from stickslip.estimators.line.families import (
    FamilyCalibration,
    contact_lines,
    family_calibration_lines,
)
from stickslip.estimators.line.modelfile import load_line_model
from stickslip.estimators.line.training import power_fit
from stickslip.jobs.train import BundledRecipe
from stickslip.simulators import effects as fx
from stickslip.simulators.randomised import RandomisedConfig, cached_randomised_set

ROOT = Path(__file__).resolve().parents[1]
CAL_N, CAL_SEED, CONTACTS = 600, 501, 640
TARGETS = {"U0": 1, "K": 2}  # columns of the mapped-frame targets (ln U0', ln K')
LENGTH = 480  # pixels the CNN reads (mapped lines are 374-535 long; shorter ones wrap)
ALPHA = 0.05


class Sizer(nn.Module):
    """ln half-width per target: the power law of the spread plus a learned correction
    from scalar features and, optionally, from a CNN over the line."""

    def __init__(self, n_scalars: int, read_line: bool) -> None:
        super().__init__()
        self.read_line = read_line
        self.conv = nn.Sequential(
            nn.Conv1d(2, 24, 9, padding=4), nn.GELU(),
            nn.Conv1d(24, 32, 9, stride=2, padding=4), nn.GELU(),
            nn.Conv1d(32, 48, 9, stride=2, padding=4), nn.GELU(),
            nn.Conv1d(48, 48, 9, stride=2, padding=4), nn.GELU(),
        )  # fmt: skip
        width = 96 if read_line else 0
        self.head = nn.Sequential(nn.Linear(width + n_scalars, 64), nn.GELU(), nn.Linear(64, 3))
        self.power = nn.Parameter(torch.ones(2))
        self.level = nn.Parameter(torch.ones(2))
        nn.init.zeros_(self.head[-1].weight)
        nn.init.zeros_(self.head[-1].bias)

    def forward(self, x: torch.Tensor, scalars: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        parts = [scalars]
        if self.read_line:
            h = self.conv(torch.stack([x, torch.diff(x, dim=1, prepend=x[:, :1])], 1))
            parts.insert(0, torch.cat([h.mean(2), h.amax(2)], 1))
        out = self.head(torch.cat(parts, 1))
        # the first two scalars are ln spread of U0 and K
        return self.level + self.power * scalars[:, :2] + out[:, :2], out[:, 2]


def train_sizer(x: np.ndarray, scalars: np.ndarray, err_abs: np.ndarray, label: np.ndarray,
                fit: np.ndarray, inner: np.ndarray, read_line: bool, epochs: int,
                width_weight: float = 1.0, label_weight: float = 0.05, seed: int = 0,
                ) -> Sizer:  # fmt: skip
    """Fit a :class:`Sizer` on the rows ``fit`` by the interval score (and, weighted by
    ``label_weight``, the cross-entropy of ``label``), keeping the epoch that scores best
    on the rows ``inner``."""
    torch.manual_seed(seed)
    net = Sizer(scalars.shape[1], read_line)
    opt = torch.optim.AdamW(net.parameters(), 2e-3, weight_decay=1e-4)
    tx, ts, ta, tl = (torch.from_numpy(np.ascontiguousarray(v, np.float32))
                      for v in (x, scalars, err_abs, label))  # fmt: skip

    def loss(rows: torch.Tensor) -> torch.Tensor:
        lw, logit = net(tx[rows], ts[rows])
        h = torch.exp(lw)
        score = (2 * h + (2 / ALPHA) * torch.relu(ta[rows] - h)).mean(0).sum()
        bce = nn.functional.binary_cross_entropy_with_logits(logit, tl[rows])
        return width_weight * score + label_weight * bce

    rng = np.random.default_rng(seed)
    best, state = np.inf, None
    val = torch.from_numpy(np.flatnonzero(inner))
    for _ in range(epochs):
        net.train()
        order = rng.permutation(np.flatnonzero(fit))
        for b in range(0, order.size, 128):
            opt.zero_grad()
            loss(torch.from_numpy(order[b:b + 128])).backward()
            opt.step()
        net.eval()
        with torch.no_grad():
            v = float(loss(val))
        if v < best:
            best, state = v, {k: t.clone() for k, t in net.state_dict().items()}
    net.load_state_dict(state)
    return net.eval()


def roc_auc(label: np.ndarray, score: np.ndarray) -> float:
    """Area under the ROC curve: the Mann-Whitney statistic (ties ranked half)."""
    ranks = rankdata(score)
    pos = label.astype(bool)
    n1, n0 = pos.sum(), (~pos).sum()
    return float((ranks[pos].sum() - n1 * (n1 + 1) / 2) / (n1 * n0))


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--work", type=Path, default=ROOT / "build" / "families")
    ap.add_argument("--seed", type=int, default=9601)
    ap.add_argument("--draws", type=int, default=12)
    ap.add_argument("--epochs", type=int, default=20)
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    print(machine_line())
    t0 = time.perf_counter()
    args.work.mkdir(parents=True, exist_ok=True)
    ens = load_line_model(None)
    settings = FamilyCalibration(contacts=CONTACTS, seed=args.seed, draws=args.draws,
                                 training_draws=args.draws)  # fmt: skip
    config = BundledRecipe().prior(RandomisedConfig(n=CAL_N, seed=CAL_SEED))
    pool = cached_randomised_set(config, args.work)
    parts = family_calibration_lines(ens, pool, settings,
                                     contact_lines(FamilyCalibration(contacts=CONTACTS), args.work))
    y_std, y_mean = np.asarray(ens.y_std, float), np.asarray(ens.y_mean, float)
    cols = list(TARGETS.values())
    err, spread, lines, applied, rows, clean, training = [], [], [], [], [], [], []
    for cs, Y, drawn, is_training in ((parts.prior_set, parts.prior_Y, parts.prior, False),
                                      (parts.training_set, parts.training_Y, parts.training,
                                       True)):  # fmt: skip
        mu, sd = predict_std_lines(ens, cs.lines, cs.C)
        err.append((mu * y_std + y_mean - Y)[:, cols])
        spread.append((sd * y_std)[:, cols])
        lines += [np.resize(np.asarray(f, np.float32), LENGTH) for f in cs.lines]
        applied.append(drawn.applied)
        rows.append(drawn.rows)
        forces = np.asarray(drawn.data.force_nN)
        untouched = np.all(forces == np.asarray(parts.clean.force_nN)[drawn.rows], axis=1)
        clean.append(untouched & ~drawn.applied.any(axis=1))
        training.append(np.full(drawn.rows.size, is_training))
    a = np.abs(np.concatenate(err))
    s = np.concatenate(spread)
    X = np.stack(lines)
    fam = np.vstack(applied)
    traj = np.concatenate(rows)
    clean_line = np.concatenate(clean)
    is_training = np.concatenate(training)
    contact = traj >= CAL_N
    p = pool.params
    own = np.flatnonzero(~contact)
    modulation, defects = np.zeros(traj.size), np.zeros(traj.size)
    modulation[own] = np.asarray(p["mod_amplitude"], float)[traj[own]]
    defects[own] = np.asarray(p["defect_count"], float)[traj[own]]
    plain = clean_line & (modulation == 0) & (defects == 0) & ~contact
    print(f"{a.shape[0]} lines ({(~is_training).sum()} of the nuisance prior, "
          f"{is_training.sum()} with the training effects; {contact.mean():.2f} contact lines; "
          f"clean: {clean_line.sum()} of which {plain.sum()} on a plain substrate), read in "
          f"{time.perf_counter() - t0:.0f} s")  # fmt: skip

    mean = X.mean(axis=1, keepdims=True)
    std = X.std(axis=1, keepdims=True) + 1e-6
    Xn = (X - mean) / std
    noise = np.median(np.abs(np.diff(X, 2, axis=1)), axis=1)
    stats = np.column_stack([np.log(s), np.log(std[:, 0]), np.log(noise + 1e-6),
                             np.log(np.abs(mean[:, 0]) + 1e-3)])  # fmt: skip
    substrate = np.column_stack([stats, modulation, defects > 0, contact, is_training])
    oracle = np.column_stack([substrate, fam])
    precursor = fam[:, fx.FAMILIES.index("precursor")].astype(float)
    fit, test = traj % 2 == 0, traj % 2 == 1
    inner = fit & ((traj // 2) % 10 == 0)
    train = fit & ~inner

    halves: dict[str, np.ndarray] = {}
    scale, power = power_fit(a[fit], s[fit], np.ones(int(fit.sum())))
    halves["spread"] = 1.959964 * scale * s ** power
    for name, scalars, read in (("+ statistics", stats, False), ("+ line", stats, True),
                                ("+ substrate", substrate, False),
                                ("+ oracle", oracle, False)):  # fmt: skip
        t1 = time.perf_counter()
        net = train_sizer(Xn, scalars, a, precursor, train, inner, read, args.epochs)
        with torch.no_grad():
            lw, _ = net(torch.from_numpy(Xn.astype(np.float32)),
                        torch.from_numpy(scalars.astype(np.float32)))  # fmt: skip
        halves[name] = np.exp(lw.numpy())
        print(f"  fitted '{name}' in {time.perf_counter() - t1:.0f} s")

    groups = {"all": test, "clean, plain substrate": test & plain,
              "clean, augmented substrate or contact": test & clean_line & ~plain,
              "the rest": test & ~clean_line}  # fmt: skip
    print(f"\n95 % interval of ln U0 and ln K, fitted on the lines of even trajectories, scored "
          f"on the {int(test.sum())} of odd ones: mean interval score, coverage, median "
          "half-width (log units)")  # fmt: skip
    for target, k in zip(TARGETS, range(len(TARGETS)), strict=True):
        print(f"\n{target}")
        for gname, m in groups.items():
            q95 = np.quantile(a[m, k], 0.95)
            print(f"  {gname} ({int(m.sum())} lines; 95 % quantile of |error| {q95:.3f})")
            for name, half in halves.items():
                h = half[m, k]
                score = np.mean(interval_score(a[m, k], -h, h, ALPHA))
                print(f"    {name:13s} score {score:.3f}, coverage "
                      f"{np.mean(a[m, k] <= h):.3f}, half-width {np.median(h):.3f}")  # fmt: skip

    t1 = time.perf_counter()
    net = train_sizer(Xn, stats, a, precursor, train & ~is_training, inner & ~is_training, True,
                      args.epochs, width_weight=0.0, label_weight=1.0)  # fmt: skip
    with torch.no_grad():
        _, logit = net(torch.from_numpy(Xn.astype(np.float32)),
                       torch.from_numpy(stats.astype(np.float32)))  # fmt: skip
    m = test & ~is_training
    auc = roc_auc(precursor[m], logit.numpy()[m])
    print(f"\nprecursor softening told from the line (a CNN classifier on the statistics and the "
          f"line, {time.perf_counter() - t1:.0f} s): ROC AUC {auc:.3f} on the prior's "
          f"{int(m.sum())} test lines ({precursor[m].mean():.2f} carry it)")
    print(f"\ntotal {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
