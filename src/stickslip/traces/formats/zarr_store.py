"""The project's Zarr sweep stores (``.zarr`` folders), read as traces.

A store holds the HDF5 sweep layout (:mod:`stickslip.traces.dataset`): ``force_nN``,
``x_nm``, ``params/<name>``, ``done`` and the sweep's attributes. Its traces are named,
labelled and filtered (rows not yet simulated are skipped) exactly as the HDF5 reader
does for the same sweep, by the same code.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from stickslip.traces.dataset import DatasetError, zarr_contents
from stickslip.traces.formats.hdf5 import _group_traces, _scalars
from stickslip.traces.trace import Trace, TraceReadError


class _RootGroup(dict):
    """A store's arrays in memory, shaped like the h5py root group the HDF5 reader reads."""

    name = "/"

    def __init__(self, arrays: dict[str, Any]):
        super().__init__(arrays)
        self.attrs: dict[str, Any] = {}  # the store's attributes come in as file meta


def read_zarr(path: Path, **_: Any) -> list[Trace]:
    """Read every trace of a stickslip Zarr store."""
    try:
        arrays, attrs = zarr_contents(path)
    except DatasetError as e:
        reason = str(e).removeprefix(f"{path}: ")
        raise TraceReadError(path, reason) from None
    if "force_nN" not in arrays:
        raise TraceReadError(path, "needs a force_nN array (with x_nm) in the project's layout")
    return _group_traces(path, _RootGroup(arrays), _scalars(attrs))
