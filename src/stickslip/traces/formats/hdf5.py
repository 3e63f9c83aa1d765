"""The project's own HDF5 trace datasets (``.h5``, ``.hdf5``).

Layout read here (any group, the root included, may hold one set):

- ``force_nN``: float array ``(n_traces, n_samples)`` or ``(n_samples,)``;
- ``x_nm``: ``(n_samples,)`` shared by all traces, or the same shape as ``force_nN``;
- optional ``names``: ``(n_traces,)`` strings;
- optional further 1-D datasets of length ``n_traces``, beside ``force_nN`` or in a
  ``params`` subgroup (labels such as ``U0_eV``, ``K_N_m``, ``lattice_nm``): copied
  into each trace's ``meta`` under their own names;
- optional ``done`` ``(n_traces,)`` bool: rows not yet simulated are skipped;
- scalar attributes of the file and of the group (except the long ``config``) are
  copied into ``meta``.

This is the layout of the simulated sweeps (:mod:`stickslip.traces.dataset`,
``/force_nN``, ``/x_nm``, ``/params/<name>``, ``/done``), so they read as traces too.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from stickslip.traces.formats.common import read_bytes
from stickslip.traces.trace import Trace, TraceReadError, validate_trace

H5_MAGIC = b"\x89HDF\r\n\x1a\n"
_RESERVED = ("force_nN", "x_nm", "names", "done", "support_nm")
LAYOUT = "needs a force_nN dataset (with x_nm) in the project's HDF5 layout"


def _scalars(attrs: Any) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in attrs.items():
        if k == "config":
            continue
        v = v.decode() if isinstance(v, bytes) else v
        if isinstance(v, np.generic):
            v = v.item()
        if isinstance(v, (int, float, str, bool)):
            out[str(k)] = v
    return out


def _group_traces(path: Path, group: Any, file_meta: dict[str, Any]) -> list[Trace]:
    force = np.asarray(group["force_nN"][()], dtype=float)
    if "x_nm" not in group:
        raise TraceReadError(path, f"group {group.name}: force_nN without x_nm")
    x = np.asarray(group["x_nm"][()], dtype=float)
    force = force[None, :] if force.ndim == 1 else force
    if force.ndim != 2:
        raise TraceReadError(path, f"group {group.name}: force_nN must be 1-D or 2-D")
    n = force.shape[0]
    xs = np.broadcast_to(x, force.shape) if x.ndim == 1 else x
    if xs.shape != force.shape:
        raise TraceReadError(path, f"group {group.name}: x_nm and force_nN differ in shape")
    names = [f"{path.stem}:{group.name.strip('/') or 'root'}:{i:05d}" for i in range(n)]
    if "names" in group:
        raw = list(group["names"][()])
        if len(raw) == n:
            names = [r.decode() if isinstance(r, bytes) else str(r) for r in raw]
    items = list(group.items())
    if "params" in group and hasattr(group["params"], "items"):
        items += list(group["params"].items())
    extra = {
        k: np.asarray(ds[()]) for k, ds in items
        if k not in _RESERVED and hasattr(ds, "shape") and ds.shape == (n,)
        and ds.dtype.kind in "fiub"
    }
    done = np.asarray(group["done"][()], dtype=bool) if "done" in group else np.ones(n, bool)
    if done.shape != (n,):
        raise TraceReadError(path, f"group {group.name}: done does not match force_nN")
    meta0 = dict(file_meta, **_scalars(group.attrs), file=str(path), unit="nN", calibrated=True)
    out = []
    for i in np.flatnonzero(done).tolist():
        xi, fi = np.array(xs[i], dtype=float), np.array(force[i], dtype=float)
        validate_trace(xi, fi, str(path))
        # the row index, unless the file's own per-trace table states one
        meta = {**meta0, "index": i, **{k: v[i].item() for k, v in extra.items()}}
        out.append(Trace(x_nm=xi, force_nN=fi, name=names[i], source=str(path), meta=meta))
    return out


def read_h5(path: Path, **_: Any) -> list[Trace]:
    """Read every trace set of a project HDF5 file."""
    if read_bytes(path, 8) != H5_MAGIC:
        raise TraceReadError(path, "not an HDF5 file (bad signature)")
    import h5py

    try:
        fh = h5py.File(path, "r")
    except OSError as e:
        raise TraceReadError(path, f"damaged HDF5 file ({e})") from None
    with fh:
        groups: list[Any] = [fh] if "force_nN" in fh else []
        fh.visititems(
            lambda _, obj: groups.append(obj)
            if isinstance(obj, h5py.Group) and "force_nN" in obj else None
        )
        if not groups:
            raise TraceReadError(path, LAYOUT)
        file_meta = _scalars(fh.attrs)
        return [t for g in groups for t in _group_traces(path, g, file_meta)]
