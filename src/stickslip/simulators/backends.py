"""Backend interface: a backend integrates :class:`Lanes` with a common step layout.

A backend is a function ``(lanes, record_fine) -> (force_nN, fine_x_nm, fine_force_nN)``.
Names:

- ``cpu`` (alias ``numba``, the default): the production CPU kernel; its results never
  depend on the machine, the thread count or the batch split.
- ``cuda``: the GPU kernel (:mod:`.cuda`), float64; ``cuda-float32``: the same in float32.
  Same random streams as ``cpu``; traces agree with it to rounding, and at finite T
  statistically once rounding sends a thermally activated slip the other way (:mod:`.cuda`).
- ``auto``: ``cuda`` when a CUDA device is present, else ``cpu``.
- ``numpy``: the slow reference used by tests.
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


def _cuda64(lanes: Lanes, record_fine: bool):
    from stickslip.simulators.cuda import integrate_cuda

    return integrate_cuda(lanes, record_fine, precision="float64")


def _cuda32(lanes: Lanes, record_fine: bool):
    from stickslip.simulators.cuda import integrate_cuda

    return integrate_cuda(lanes, record_fine, precision="float32")


BACKENDS: dict[str, Backend] = {
    "cpu": _numba,
    "cuda": _cuda64,
    "cuda-float32": _cuda32,
    "numpy": _numpy,
}
ALIASES = {"numba": "cpu"}
#: Names accepted by :func:`resolve_backend` (``auto`` resolves to ``cuda`` or ``cpu``).
BACKEND_NAMES = ("cpu", "cuda", "cuda-float32", "auto", "numba", "numpy")


def resolve_backend(name: str) -> str:
    """The concrete backend a name stands for: aliases mapped, ``auto`` decided here.

    Raises
    ------
    ValueError
        For an unknown name.
    CudaUnavailableError
        (a :class:`~stickslip.simulators.config.SettingsError`) for ``cuda`` or
        ``cuda-float32`` without a CUDA device.
    """
    name = ALIASES.get(name, name)
    if name not in BACKENDS and name != "auto":
        raise ValueError(f"unknown backend '{name}' (have: {', '.join(BACKEND_NAMES)})")
    if name == "auto" or name.startswith("cuda"):
        from stickslip.simulators.cuda import CudaUnavailableError, cuda_available

        if name == "auto":
            return "cuda" if cuda_available() else "cpu"
        if not cuda_available():
            raise CudaUnavailableError(
                f"backend '{name}': no CUDA device found (needs an NVIDIA GPU, its driver "
                "and pip install 'stickslip[gpu]'; --backend auto falls back to cpu)"
            )
    return name


def get_backend(name: str) -> Backend:
    """Look up a backend by name (see :func:`resolve_backend`)."""
    return BACKENDS[resolve_backend(name)]
