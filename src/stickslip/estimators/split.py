"""The one train/validation split of trajectories."""

from __future__ import annotations

import numpy as np


def split_indices(n: int, val_fraction: float, rng: np.random.Generator
                  ) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """(train, validation) indices of ``n`` trajectories, in the order of one permutation.

    The validation set is the permutation's first ``round(val_fraction n)`` (at least 1,
    at most ``n - 1``); whole trajectories go to one side only.
    """
    if n < 2:
        raise ValueError(f"need at least 2 trajectories to split (got {n})")
    perm = rng.permutation(n)
    n_val = min(max(1, int(round(val_fraction * n))), n - 1)
    return perm[n_val:], perm[:n_val]
