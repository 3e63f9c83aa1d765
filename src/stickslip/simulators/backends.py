"""Backend interface: a backend integrates :class:`Lanes` with a common step layout.

A backend is a function ``(lanes, record_fine) -> (force_nN, fine_x_nm, fine_force_nN)``.
``numba`` is the production CPU kernel; ``numpy`` is the slow reference used by tests.
A GPU backend can be registered here with the same signature.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from stickslip.simulators.lanes import Lanes

Backend = Callable[[Lanes, bool], tuple[np.ndarray, np.ndarray | None, np.ndarray | None]]


def _numba(lanes: Lanes, record_fine: bool):
    from stickslip.simulators.kernel import integrate_numba

    return integrate_numba(lanes, record_fine)


def _numpy(lanes: Lanes, record_fine: bool):
    from stickslip.simulators.reference import integrate_reference

    # the reference draws from one numpy stream seeded by the lanes' generator states
    return integrate_reference(lanes, seed=int(lanes.rng0[0] % (2**63)), record_fine=record_fine)


BACKENDS: dict[str, Backend] = {"numba": _numba, "numpy": _numpy}


def get_backend(name: str) -> Backend:
    """Look up a backend by name."""
    try:
        return BACKENDS[name]
    except KeyError:
        raise ValueError(f"unknown backend '{name}' (have: {', '.join(BACKENDS)})") from None
