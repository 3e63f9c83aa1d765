"""Shared test data of the line-model tests."""

from __future__ import annotations

import numpy as np
import pytest

from stickslip.estimators.line.ensemble import LineSpec


def make_sawtooth_lines(n: int, pixels: int, seed: int, velocities: tuple[float, ...] = (60.0,)
                   ) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:  # fmt: skip
    """Hand-made sawtooth lines (no simulation) with a parameter table: checks plumbing,
    not accuracy. Lattices 0.246 / 0.28 nm, half the lines on a modulated substrate."""
    rng = np.random.default_rng(seed)
    x = np.arange(pixels) * LineSpec().pixel_nm
    a = rng.choice([0.246, 0.28], n)
    K, U0 = rng.uniform(2, 20, n), rng.uniform(0.5, 3, n)
    force = np.array([k * a_ * ((x / a_) % 1.0) for k, a_ in zip(K, a, strict=True)])
    params = {"U0_eV": U0, "K_N_m": K, "F_mean_nN": force.mean(axis=1), "lattice_nm": a,
              "velocity_nm_per_s": rng.choice(np.asarray(velocities, float), n),
              "mod_amplitude": np.where(np.arange(n) % 2 == 0, 0.0, 0.2),
              "defect_count": np.zeros(n, int)}  # fmt: skip
    return force, x, params


@pytest.fixture(scope="session")
def sawtooth_lines():
    """:func:`make_sawtooth_lines`, for tests that build their own."""
    return make_sawtooth_lines
