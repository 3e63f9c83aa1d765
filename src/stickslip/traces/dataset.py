"""The project's simulated-dataset format: chunked HDF5 (``.h5``) or a Zarr store (``.zarr``).

Layout (one file or store = one sweep)::

    /force_nN        (N, pixels) float32, chunked by rows, compressed
    /x_nm            (pixels,)   recorded position, 0 at the first pixel
    /support_nm      (N, pixels) absolute support position at each pixel centre
    /params/<name>   (N,) per-trajectory table: U0_eV, K_N_m, eta, F_mean_nN, lattice_nm,
                     velocity_nm_per_s, temperature_K, damping_per_s, mass_kg, dt_s,
                     warmup_nm, index, and the substrate draw (mod_*, defect_* (N, D))
    /done            (N,) bool, rows already simulated (for --resume)
    attrs: format, config (JSON of SweepConfig), seed, stickslip_version, n, pixels

:func:`load_dataset` reads it back; the config in ``attrs`` regenerates it.

A Zarr store (a folder whose name ends in ``.zarr``; needs the ``dask`` extra) has the
same arrays and attributes, every per-row array chunked by shards of ``shard_rows``
rows (an extra attribute), so a sharded sweep writes whole chunks. Functions here take
either kind and tell them apart by the name (a ``.partial`` suffix is ignored).
"""

from __future__ import annotations

import os
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from stickslip.traces.trace import Trace

FORMAT = "stickslip-sweep-1"
ROW_CHUNK = 64
ZARR_SUFFIX = ".zarr"
PARTIAL_SUFFIX = ".partial"
ZARR_NEEDED = "Zarr stores need the zarr package: pip install 'stickslip[dask]'"


class DatasetError(Exception):
    """A dataset file that cannot be used; ``str()`` is one line."""


@dataclass
class Dataset:
    """An in-memory simulated dataset."""

    force_nN: np.ndarray
    x_nm: np.ndarray
    params: dict[str, np.ndarray]
    attrs: dict

    @property
    def n(self) -> int:
        return int(self.force_nN.shape[0])

    @property
    def config_json(self) -> str:
        return str(self.attrs.get("config", "{}"))

    def fingerprint(self) -> str:
        """Short content hash of forces and targets (identifies the training data)."""
        import hashlib

        h = hashlib.sha256()
        h.update(np.ascontiguousarray(self.force_nN, dtype=np.float32).tobytes())
        for k in ("U0_eV", "K_N_m"):
            h.update(np.ascontiguousarray(self.params[k], dtype=np.float64).tobytes())
        return h.hexdigest()[:16]


def is_zarr_path(path: str | os.PathLike) -> bool:
    """True if ``path`` names a Zarr store: ``*.zarr``, or ``*.zarr.partial`` while written."""
    name = Path(path).name.lower()
    if name.endswith(PARTIAL_SUFFIX):
        name = name[: -len(PARTIAL_SUFFIX)]
    return name.endswith(ZARR_SUFFIX)


def is_zarr_store(path: str | os.PathLike) -> bool:
    """True if ``path`` is a folder holding a Zarr group (format 3 or 2)."""
    p = Path(path)
    return p.is_dir() and ((p / "zarr.json").is_file() or (p / ".zgroup").is_file())


def _zarr(path: str | os.PathLike) -> Any:
    """The zarr module, imported only when a store is used (it is an optional extra)."""
    try:
        import zarr
    except ImportError:
        raise DatasetError(f"{path}: {ZARR_NEEDED}") from None
    return zarr


def check_output_path(path: str | os.PathLike) -> None:
    """Check, before any work, that an output file or store can be written at ``path``.

    A Zarr output may replace an existing Zarr store; any other existing folder is
    refused, and so are a missing or read-only parent folder.

    Raises
    ------
    DatasetError
        With a one-line reason.
    """
    p = Path(path)
    if not str(path).strip():
        raise DatasetError("'': empty output path")
    if p.is_dir() and not (is_zarr_path(p) and is_zarr_store(p)):
        what = "a folder that is not a Zarr store" if is_zarr_path(p) else "a directory"
        raise DatasetError(f"{p}: is {what}, cannot write the output there")
    if p.exists() and not p.is_dir() and is_zarr_path(p):
        raise DatasetError(f"{p}: is a file, not a Zarr store (folder)")
    parent = p.parent
    if not parent.exists():
        raise DatasetError(f"{p}: folder '{parent}' does not exist")
    if not parent.is_dir():
        raise DatasetError(f"{p}: '{parent}' is not a folder")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise DatasetError(f"{p}: folder '{parent}' is not writable")


def remove_dataset(path: str | os.PathLike) -> None:
    """Delete a dataset file or Zarr store if it exists."""
    p = Path(path)
    if p.is_dir() and not p.is_symlink():
        shutil.rmtree(p)
    elif p.exists() or p.is_symlink():
        p.unlink()


def finish_dataset(part: str | os.PathLike, out: str | os.PathLike) -> Path:
    """Rename a finished ``part`` onto ``out``, replacing an earlier dataset there."""
    part, out = Path(part), Path(out)
    if out.is_dir():  # os.replace cannot put a folder onto a non-empty one
        if not is_zarr_store(out):
            raise DatasetError(f"{out}: is a directory, not replaced")
        shutil.rmtree(out)
    os.replace(part, out)
    return out


def _json_value(v: Any) -> Any:
    """Attribute values as JSON types (Zarr attributes are JSON)."""
    return v.item() if isinstance(v, np.generic) else v


def create_dataset_file(
    path: str | os.PathLike,
    n: int,
    x_nm: np.ndarray,
    params: dict[str, np.ndarray],
    attrs: dict,
    shard_rows: int | None = None,
) -> None:
    """Create an empty sweep file with the parameter table filled and no rows done.

    ``shard_rows`` sets the rows per chunk of a Zarr store (default :data:`ROW_CHUNK`);
    HDF5 files are always chunked by :data:`ROW_CHUNK` rows.
    """
    if is_zarr_path(path):
        _create_zarr(path, n, x_nm, params, attrs, shard_rows or ROW_CHUNK)
        return
    pixels = int(np.size(x_nm))
    with h5py.File(path, "w") as f:
        chunks = (min(ROW_CHUNK, n), pixels)
        f.create_dataset("force_nN", (n, pixels), np.float32, chunks=chunks, compression="lzf")
        f.create_dataset("support_nm", (n, pixels), np.float64, chunks=chunks, compression="lzf")
        f.create_dataset("x_nm", data=np.asarray(x_nm, float))
        g = f.create_group("params")
        for k, v in params.items():
            g.create_dataset(k, data=np.asarray(v))
        f.create_dataset("done", data=np.zeros(n, bool))
        for k, v in attrs.items():
            f.attrs[k] = v
        f.attrs["format"] = FORMAT


def _create_zarr(
    path: str | os.PathLike,
    n: int,
    x_nm: np.ndarray,
    params: dict[str, np.ndarray],
    attrs: dict,
    shard_rows: int,
) -> None:
    zarr = _zarr(path)
    pixels = int(np.size(x_nm))
    rows = max(1, min(int(shard_rows), n))
    meta = {str(k): _json_value(v) for k, v in attrs.items()}
    meta.update(format=FORMAT, shard_rows=rows)
    g = zarr.open_group(str(path), mode="w", attributes=meta)
    g.create_array("force_nN", shape=(n, pixels), dtype="float32", chunks=(rows, pixels))
    g.create_array("support_nm", shape=(n, pixels), dtype="float64", chunks=(rows, pixels))
    g.create_array("x_nm", data=np.asarray(x_nm, float))
    p = g.create_group("params")
    for k, v in params.items():
        v = np.asarray(v)
        p.create_array(k, data=v, chunks=(rows, *v.shape[1:]))
    g.create_array("done", shape=(n,), dtype="bool", chunks=(rows,), fill_value=False)


def _row_order(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, slice | None]:
    """Sorted rows, the order that sorts them, and a slice if they are contiguous."""
    rows = np.asarray(rows, dtype=np.int64)
    order = np.argsort(rows, kind="stable")
    r = rows[order]
    if r.size and r[-1] - r[0] == r.size - 1:  # sorted and unique: contiguous
        return r, order, slice(int(r[0]), int(r[-1]) + 1)
    return r, order, None


def write_rows(
    path: str | os.PathLike,
    rows: np.ndarray,
    force_nN: np.ndarray,
    support_nm: np.ndarray,
    extra_params: dict[str, np.ndarray],
) -> None:
    """Write simulated rows (and per-row results such as F_mean_nN), then mark them done.

    ``rows`` (unique) may be in any order and need not be contiguous; the data follow it.
    """
    r, order, sl = _row_order(rows)
    force_nN, support_nm = np.asarray(force_nN)[order], np.asarray(support_nm)[order]
    extra = {k: np.asarray(v)[order] for k, v in extra_params.items()}
    if is_zarr_path(path):
        g = _zarr(path).open_group(str(path), mode="r+")

        def put(arr: Any, data: np.ndarray) -> None:
            if sl is not None:
                arr[sl] = data
            else:
                arr.oindex[r] = data

        put(g["force_nN"], force_nN.astype(np.float32))
        put(g["support_nm"], support_nm)
        for k, v in extra.items():
            put(g["params"][k], v)
        put(g["done"], np.ones(r.size, bool))  # last: a row counts once its data are in
        return
    sel = sl if sl is not None else r  # h5py takes increasing index lists
    with h5py.File(path, "r+") as f:
        f["force_nN"][sel] = force_nN
        f["support_nm"][sel] = support_nm
        for k, v in extra.items():
            f["params"][k][sel] = v
        f["done"][sel] = True
        f.flush()


def read_done(path: str | os.PathLike) -> np.ndarray:
    """Which rows of a (possibly partial) sweep file are complete."""
    if is_zarr_path(path):
        return np.asarray(_open_zarr(path)["done"][:], dtype=bool)
    with h5py.File(path, "r") as f:
        return f["done"][:]


def read_attrs(path: str | os.PathLike) -> dict:
    if is_zarr_path(path):
        return dict(_open_zarr(path).attrs)
    with h5py.File(path, "r") as f:
        return dict(f.attrs)


def _open_zarr(path: str | os.PathLike) -> Any:
    """Open a Zarr store for reading, or raise a one-line DatasetError."""
    p = Path(path)
    zarr = _zarr(p)
    if not p.exists():
        raise DatasetError(f"{p}: file not found")
    if not is_zarr_store(p):
        raise DatasetError(f"{p}: not a Zarr store (a folder holding zarr.json expected)")
    try:
        return zarr.open_group(str(p), mode="r")
    except Exception as e:  # zarr raises its own error types for damaged metadata
        raise DatasetError(f"{p}: unreadable Zarr store ({type(e).__name__}: {e})") from None


def zarr_contents(path: str | os.PathLike) -> tuple[dict[str, Any], dict[str, Any]]:
    """Every array of a sweep store in memory, and its attributes.

    Returns ``(arrays, attrs)``; ``arrays`` maps the top-level array names to numpy
    arrays and ``"params"`` to a dict of the parameter columns (the HDF5 layout).

    Raises
    ------
    DatasetError
        If the store is missing, unreadable or not a stickslip sweep.
    """
    g = _open_zarr(path)
    try:
        if g.attrs.get("format") != FORMAT:
            raise DatasetError(f"{path}: not a stickslip dataset (format {FORMAT} expected)")
        arrays: dict[str, Any] = {k: np.asarray(a[...]) for k, a in g.arrays()}
        if "params" in g:
            arrays["params"] = {k: np.asarray(a[...]) for k, a in g["params"].arrays()}
        return arrays, dict(g.attrs)
    except DatasetError:
        raise
    except Exception as e:
        raise DatasetError(f"{path}: unreadable Zarr store ({type(e).__name__}: {e})") from None


def _load_zarr(p: Path, rows: slice | np.ndarray | None) -> Dataset:
    g = _open_zarr(p)
    try:
        if g.attrs.get("format") != FORMAT:
            raise DatasetError(f"{p}: not a stickslip dataset (format {FORMAT} expected)")
        if not bool(np.all(g["done"][:])):
            raise DatasetError(f"{p}: incomplete dataset (finish it with --resume)")

        def take(a: Any) -> np.ndarray:
            if rows is None:
                return np.asarray(a[...])
            return np.asarray(a[rows] if isinstance(rows, slice) else a.oindex[np.asarray(rows)])

        params = {k: take(a) for k, a in g["params"].arrays()}
        return Dataset(force_nN=take(g["force_nN"]), x_nm=np.asarray(g["x_nm"][:]),
                       params=params, attrs=dict(g.attrs))  # fmt: skip
    except DatasetError:
        raise
    except Exception as e:
        raise DatasetError(f"{p}: unreadable Zarr store ({type(e).__name__}: {e})") from None


def load_dataset(path: str | os.PathLike, rows: slice | np.ndarray | None = None) -> Dataset:
    """Read a sweep file or Zarr store (all rows, or a selection).

    Raises
    ------
    DatasetError
        If the file is missing, not HDF5 or Zarr, not a stickslip sweep, or incomplete.
    """
    p = Path(path)
    if not p.exists():
        raise DatasetError(f"{p}: file not found")
    if is_zarr_path(p) or p.is_dir():
        return _load_zarr(p, rows)
    try:
        with h5py.File(p, "r") as f:
            if f.attrs.get("format") != FORMAT:
                raise DatasetError(f"{p}: not a stickslip dataset (format {FORMAT} expected)")
            if not bool(np.all(f["done"][:])):
                raise DatasetError(f"{p}: incomplete dataset (finish it with --resume)")
            sel = slice(None) if rows is None else rows
            force = f["force_nN"][sel]
            params = {k: v[sel] for k, v in f["params"].items()}
            return Dataset(force_nN=force, x_nm=f["x_nm"][:], params=params, attrs=dict(f.attrs))
    except DatasetError:
        raise
    except (OSError, KeyError) as e:
        raise DatasetError(f"{p}: unreadable dataset ({e})") from None


def concat_datasets(sets: list[Dataset], columns: list[str] | None = None) -> Dataset:
    """Rows of several datasets on one position grid, in order, as one dataset.

    ``attrs["config"]`` becomes the JSON list of the parts' configs. With ``columns``,
    only those parameter columns are kept (each part must have them), so sets written by
    different simulators (sweeps, randomised sets) can be joined.

    Raises
    ------
    DatasetError
        If the parts have different positions or parameter columns.
    """
    import json

    first = sets[0]
    keep = list(first.params) if columns is None else list(columns)
    for d in sets:
        names = set(d.params) if columns is None else set(d.params) & set(keep)
        if not np.array_equal(d.x_nm, first.x_nm) or names != set(keep):
            raise DatasetError("datasets to join differ in positions or parameter columns")
    return Dataset(
        force_nN=np.vstack([d.force_nN for d in sets]),
        x_nm=first.x_nm,
        params={k: np.concatenate([d.params[k] for d in sets]) for k in keep},
        attrs={**first.attrs, "n": sum(d.n for d in sets),
               "config": json.dumps([d.config_json for d in sets])},  # fmt: skip
    )


def dataset_traces(data: Dataset, rows: np.ndarray | None = None, name: str = "sweep"
                   ) -> list[Trace]:  # fmt: skip
    """Rows of a dataset as traces, each with its parameters (the truths) in ``meta``.

    Names are ``{name}:{row:05d}`` as the HDF5 reader names a sweep's traces.
    """
    rows = np.arange(data.n) if rows is None else np.asarray(rows)
    out = []
    for i in rows.tolist():
        meta = {k: np.asarray(v[i]).item() for k, v in data.params.items()
                if np.ndim(v) == 1}  # fmt: skip
        meta["index"] = i
        out.append(Trace(x_nm=np.asarray(data.x_nm, float), force_nN=np.asarray(data.force_nN[i],
                         float), name=f"{name}:{i:05d}", source=name, meta=meta))  # fmt: skip
    return out
