"""Interval arithmetic shared by the estimators that give intervals, and the classes of
lines whose spread the line model calibrates separately.

- :func:`gaussian_z`, :data:`Z68`, :data:`Z95`: a Gaussian's central half-widths;
  :func:`lognormal_std`: the std of a log-normal interval;
- :data:`SHAPE_LEVELS`: the levels at which a calibration stores its standardised
  errors' quantiles;
- :class:`SpreadClasses`: classes of lines read off the line itself (quiet or noisy,
  resampled or not), each with its own scale factors.

The line model's calibration itself (per class and target, the calibrated std ``scale *
sd ** exponent`` of the ensemble's raw std ``sd``, and the error shape) lives on the
ensemble (:class:`stickslip.estimators.line.ensemble.LineEnsemble`) and is fitted by
:func:`stickslip.estimators.line.training.calibrate`; the <F> interval's offset and
compression terms are in :mod:`stickslip.estimators.offsets`.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from statistics import NormalDist

import numpy as np

from stickslip.estimators.noise import log_noise_level

#: Levels at which a calibration stores its standardised errors' quantiles.
SHAPE_LEVELS = np.arange(1, 100) / 100.0


def gaussian_z(level: float) -> float:
    """Half-width, in standard deviations, of a Gaussian's central interval at ``level``."""
    return NormalDist().inv_cdf(0.5 + level / 2)


#: Two-sided 68 % and 95 % Gaussian quantiles: the half-widths of those intervals in stds.
Z68, Z95 = gaussian_z(0.68), gaussian_z(0.95)


def lognormal_std(median, sigma_ln):
    """Standard deviation of a log-normal with median ``median`` and std ``sigma_ln`` of
    its logarithm (arrays broadcast): how a ``*_std`` column states an interval that is
    symmetric in log space (U0, K, eta)."""
    s2 = np.square(sigma_ln)
    return median * np.sqrt(np.expm1(s2) * np.exp(s2))


@dataclass(frozen=True)
class SpreadClasses:
    """Classes of lines whose predictive spread is calibrated separately.

    The networks' spread is right on average but not in every kind of line: on a quiet
    line (no detector noise, as in a simulation) it is several times too wide, and
    how much depends on whether the line was resampled onto the reference lattice.
    Both can be read off the line itself, so each class gets its own scale factors:

    - 0: quiet, recorded on the reference lattice (not resampled);
    - 1: quiet, resampled from another lattice;
    - 2, 3, ...: noisy, by noise level, between ``noise_edges``.

    The noise level is ln of the median absolute second difference of the mapped line
    (nN): a slip moves few pixels, so in a quiet line it stays tiny, while white
    detector noise raises it directly. A line is quiet below ``quiet_below``.
    """

    quiet_below: float = -3.0
    noise_edges: tuple[float, ...] = (-2.2, -1.7)

    @property
    def n(self) -> int:
        """Number of classes."""
        return 3 + len(self.noise_edges)

    def classify(self, force_nN: np.ndarray, lattice_ratio: np.ndarray) -> np.ndarray:
        """Class of each of B mapped lines of equal length.

        Parameters
        ----------
        force_nN : ndarray (B, L)
            Mapped lines (on the reference lattice and pixel).
        lattice_ratio : ndarray (B,)
            ``a / a0`` of each line (1: recorded on the reference lattice).
        """
        return self.from_level(log_noise_level(force_nN), lattice_ratio)

    def classify_lines(self, lines: list[np.ndarray], lattice_ratio: np.ndarray) -> np.ndarray:
        """:meth:`classify` for mapped lines of any lengths."""
        return self.from_level(np.array([log_noise_level(f) for f in lines]), lattice_ratio)

    def from_level(self, level: np.ndarray, lattice_ratio: np.ndarray) -> np.ndarray:
        """Class of lines with noise level ``level`` (:func:`log_noise_level`)."""
        on_ref = np.abs(np.asarray(lattice_ratio, float) - 1.0) < 1e-6
        noisy = 2 + np.searchsorted(np.asarray(self.noise_edges), level)
        return np.where(level < self.quiet_below, np.where(on_ref, 0, 1), noisy).astype(int)

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> SpreadClasses:
        return cls(float(d["quiet_below"]), tuple(float(e) for e in d["noise_edges"]))
