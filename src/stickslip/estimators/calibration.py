"""Interval arithmetic shared by the estimators that give intervals."""

from __future__ import annotations

from statistics import NormalDist


def gaussian_z(level: float) -> float:
    """Half-width, in standard deviations, of a Gaussian's central interval at ``level``."""
    return NormalDist().inv_cdf(0.5 + level / 2)
