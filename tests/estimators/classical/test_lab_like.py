"""The classical estimator on held-out lab-like lines (issue 19: answers >= 85 %, K <= 20 %).

Lines: a small randomised pool (the line model's training distribution) of a seed no
benchmark or tuning set uses, with one draw of every effect family of the nuisance
prior (``"eval"`` implementations), scored on 1.5 <= eta <= 40. The thresholds sit
below the benchmark's figures (``benchmarks/classical_lab.py``) by the binomial spread
of a set this size, so a regression of the detector or the fits fails them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from stickslip.estimators.classical import estimate_array
from stickslip.estimators.classical import estimator as E
from stickslip.estimators.line.families import draw_family_lines
from stickslip.simulators import effects as fx
from stickslip.simulators.bench import in_eta_window
from stickslip.simulators.randomised import RandomisedConfig, make_randomised_set
from stickslip.traces.dataset import Dataset, load_dataset

POOL_SEED, DRAW_SEED = 9091, 9191  # used by no benchmark and no tuning set


@pytest.fixture(scope="module")
def pool(tmp_path_factory: pytest.TempPathFactory) -> Dataset:
    path = Path(tmp_path_factory.mktemp("lab_like")) / "pool.h5"
    make_randomised_set(RandomisedConfig(n=120, seed=POOL_SEED, chunk=60), path, progress=False)
    return load_dataset(path)


def run(data: Dataset, eta_min: float = 1.5) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Answered mask and K, U0 relative errors of the lines with eta_min <= eta <= 40."""
    p = data.params
    ok = in_eta_window(p["eta"]) & (p["eta"] >= eta_min)
    est = estimate_array(data.x_nm, np.asarray(data.force_nN, float)[ok], p["lattice_nm"][ok],
                         p["temperature_K"][ok], p["velocity_nm_per_s"][ok])  # fmt: skip
    answered = est[:, E.STATUS] == 0
    k_rel = est[answered, E.K_] / p["K_N_m"][ok][answered] - 1.0
    u_rel = est[answered, E.U0] / p["U0_eV"][ok][answered] - 1.0
    return answered, k_rel, u_rel


def only(family: str) -> fx.NuisancePrior:
    """The nuisance prior with ``family`` on every line and no other family."""
    prior = fx.NuisancePrior()
    for f in fx.FAMILIES:
        prior = prior.replace(f, p=1.0 if f == family else 0.0)
    return prior


@pytest.mark.slow
def test_clean_lines_are_answered_accurately(pool: Dataset) -> None:
    answered, k_rel, _ = run(pool)
    assert answered.mean() >= 0.95
    assert np.sqrt(np.mean(k_rel**2)) <= 0.08


@pytest.mark.slow
def test_lab_like_lines_are_answered(pool: Dataset) -> None:
    lines = draw_family_lines(pool, fx.NuisancePrior(), DRAW_SEED).data
    answered, k_rel, u_rel = run(lines)
    # benchmark (seed 601/6101, 384 lines): answered 0.901, K relative RMSE 21 %. This
    # set (115 lines, seeds 9091/9191) gave answered 0.878, K RMSE 17.5 %, median |K
    # error| 8.8 %; the thresholds sit below by about 2.5 binomial spreads (0.03)
    assert answered.mean() >= 0.80
    assert np.sqrt(np.mean(k_rel**2)) <= 0.25
    assert np.median(np.abs(k_rel)) <= 0.13


@pytest.mark.slow
def test_detector_low_pass_does_not_hide_the_slips(pool: Dataset) -> None:
    # the detector's bandwidth smears each slip over a few pixels (time constant up to
    # 3 pixels at 11 pixels per slip): before the fix 72 % answered, most "smooth sliding";
    # with the cycles through a running mean 0.974 (K RMSE 9.0 %)
    lines = draw_family_lines(pool, only("detector"), DRAW_SEED + 1).data
    answered, k_rel, _ = run(lines)
    assert answered.mean() >= 0.90
    assert np.sqrt(np.mean(k_rel**2)) <= 0.20


@pytest.mark.slow
def test_precursor_softening_does_not_soften_k(pool: Dataset) -> None:
    # softening bends each stick from its bottom up (a drop of up to half the rise at the
    # top): straight-line slopes read a softer spring, the sticks' tangents at their
    # start do not. Before the tangents these lines gave K median -22 %, RMSE 26 %; with
    # them +5 %, 11 %.
    lines = draw_family_lines(pool, only("precursor"), DRAW_SEED + 2).data
    # eta >= 4: where the PT branch starts straight
    answered, k_rel, _ = run(lines, eta_min=4.0)
    print(f"precursor, eta >= 4: {answered.size} lines, answered {answered.mean():.3f}, "
          f"K median {np.median(k_rel):+.3f}, RMSE {np.sqrt(np.mean(k_rel**2)):.3f}")
    assert answered.mean() >= 0.85
    assert abs(np.median(k_rel)) <= 0.08
