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


class Rows:
    """The (N, pixels) force rows of a dataset, read a chunk of consecutive rows at a time.

    Training streams a set through this interface (never all of it in memory); an
    in-memory array is the same thing with chunks of :data:`ROW_CHUNK` rows
    (:class:`ArrayRows`). Indexing (``rows[i]``, ``rows[a:b]``, ``rows[index_array]``)
    reads only the rows asked for, one chunk at a time; ``np.asarray(rows)`` reads all.
    """

    shape: tuple[int, int]
    dtype: np.dtype
    chunk_rows: int

    def read(self, start: int, stop: int) -> np.ndarray:
        """Rows ``start`` to ``stop`` (within one chunk or across several)."""
        raise NotImplementedError

    def chunks(self) -> list[tuple[int, int]]:
        """``[start, stop)`` of every chunk, in row order."""
        n = self.shape[0]
        return [(s, min(s + self.chunk_rows, n)) for s in range(0, n, self.chunk_rows)]

    def take(self, rows: np.ndarray) -> np.ndarray:
        """Rows in the order given (repeats allowed), reading each chunk needed once."""
        rows = np.asarray(rows, dtype=np.int64).reshape(-1)
        out = np.empty((rows.size, self.shape[1]), self.dtype)
        if not rows.size:
            return out
        if rows.min() < 0 or rows.max() >= self.shape[0]:
            raise IndexError(f"row index out of range 0..{self.shape[0] - 1}")
        starts = np.array([s for s, _ in self.chunks()])
        which = np.searchsorted(starts, rows, side="right") - 1
        for c in np.unique(which):
            at = np.flatnonzero(which == c)
            lo, hi = int(rows[at].min()), int(rows[at].max()) + 1
            out[at] = self.read(lo, hi)[rows[at] - lo]
        return out

    def close(self) -> None:
        """Release an open file (it is opened again when next read)."""

    def __len__(self) -> int:
        return int(self.shape[0])

    def __getitem__(self, key: Any) -> np.ndarray:
        if isinstance(key, slice):
            start, stop, step = key.indices(self.shape[0])
            return self.read(start, max(start, stop))[::step]
        if np.ndim(key) == 0:
            return self.take(np.array([int(key)]))[0]
        key = np.asarray(key)
        return self.take(np.flatnonzero(key) if key.dtype == bool else key)

    def __array__(self, dtype: Any = None, copy: Any = None) -> np.ndarray:
        a = self.read(0, self.shape[0])
        return a if dtype is None else a.astype(dtype)


class ArrayRows(Rows):
    """An in-memory (N, pixels) array as :class:`Rows` (no copy)."""

    def __init__(self, array: np.ndarray, chunk_rows: int = ROW_CHUNK):
        self.array = np.asarray(array)
        self.shape = (int(self.array.shape[0]), int(self.array.shape[1]))
        self.dtype = self.array.dtype
        self.chunk_rows = max(1, int(chunk_rows))

    def read(self, start: int, stop: int) -> np.ndarray:
        return self.array[start:stop]

    def take(self, rows: np.ndarray) -> np.ndarray:
        return self.array[np.asarray(rows, dtype=np.int64).reshape(-1)]


class FileRows(Rows):
    """``force_nN`` of a sweep file or Zarr store, read by its own chunks (lazily).

    The file is opened on first read in each process, so loader workers that fork or
    unpickle a copy each read through a handle of their own.
    """

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)
        self._file: Any = None
        self._pid: int | None = None
        self._array: Any = None
        a = self._open()
        self.shape = (int(a.shape[0]), int(a.shape[1]))
        self.dtype = np.dtype(a.dtype)
        self.chunk_rows = int(a.chunks[0]) if a.chunks else ROW_CHUNK
        self.close()

    def _open(self) -> Any:
        if self._array is None or self._pid != os.getpid():
            if is_zarr_path(self.path) or self.path.is_dir():
                self._file = None
                self._array = _open_zarr(self.path)["force_nN"]
            else:
                self._file = h5py.File(self.path, "r")
                self._array = self._file["force_nN"]
            self._pid = os.getpid()
        return self._array

    def read(self, start: int, stop: int) -> np.ndarray:
        return np.asarray(self._open()[start:stop])

    def close(self) -> None:
        if self._pid == os.getpid() and getattr(self, "_file", None) is not None:
            self._file.close()
        self._file, self._array, self._pid = None, None, None

    def __getstate__(self) -> dict:
        return {**self.__dict__, "_file": None, "_array": None, "_pid": None}


class ConcatRows(Rows):
    """Several :class:`Rows` one after another (their chunks kept as they are)."""

    def __init__(self, parts: list[Rows]):
        self.parts = parts
        self.offsets = np.cumsum([0] + [p.shape[0] for p in parts])
        self.shape = (int(self.offsets[-1]), int(parts[0].shape[1]))
        self.dtype = np.result_type(*(p.dtype for p in parts))
        self.chunk_rows = max(p.chunk_rows for p in parts)

    def chunks(self) -> list[tuple[int, int]]:
        return [(int(o) + s, int(o) + e) for o, p in zip(self.offsets, self.parts, strict=False)
                for s, e in p.chunks()]  # fmt: skip

    def read(self, start: int, stop: int) -> np.ndarray:
        out = [np.asarray(p.read(max(start - o, 0), min(stop - o, p.shape[0])), self.dtype)
               for o, p in zip(self.offsets.tolist(), self.parts, strict=False)
               if start < o + p.shape[0] and stop > o]  # fmt: skip
        if not out:
            return np.empty((0, self.shape[1]), self.dtype)
        return out[0] if len(out) == 1 else np.concatenate(out)

    def close(self) -> None:
        for p in self.parts:
            p.close()


def as_rows(force_nN: np.ndarray | Rows) -> Rows:
    """``force_nN`` as :class:`Rows` (an array: chunks of :data:`ROW_CHUNK` rows)."""
    return force_nN if isinstance(force_nN, Rows) else ArrayRows(force_nN)


@dataclass
class Dataset:
    """A simulated dataset: parameters in memory, forces in memory or :class:`Rows` read
    from the file (:func:`open_dataset`)."""

    force_nN: np.ndarray | Rows
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
        f = self.force_nN  # hashed a chunk at a time: the same digest, bounded memory
        for block in (f.read(s, e) for s, e in f.chunks()) if isinstance(f, Rows) else (f,):
            h.update(np.ascontiguousarray(block, dtype=np.float32).tobytes())
        for k in ("U0_eV", "K_N_m"):
            h.update(np.ascontiguousarray(self.params[k], dtype=np.float64).tobytes())
        return h.hexdigest()[:16]

    def in_memory(self) -> Dataset:
        """This dataset with its forces read into memory (itself if they already are)."""
        if not isinstance(self.force_nN, Rows):
            return self
        return Dataset(np.asarray(self.force_nN), self.x_nm, self.params, self.attrs)


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


def _check_sweep(p: Path, fmt: Any, done: np.ndarray) -> None:
    """Raise a one-line DatasetError unless ``p`` is a complete stickslip sweep."""
    if fmt != FORMAT:
        raise DatasetError(f"{p}: not a stickslip dataset (format {FORMAT} expected)")
    if not bool(np.all(done)):
        raise DatasetError(f"{p}: incomplete dataset (finish it with --resume)")


def _load_zarr(p: Path, rows: slice | np.ndarray | None, forces: bool) -> Dataset:
    g = _open_zarr(p)
    try:
        _check_sweep(p, g.attrs.get("format"), g["done"][:])

        def take(a: Any) -> np.ndarray:
            if rows is None:
                return np.asarray(a[...])
            return np.asarray(a[rows] if isinstance(rows, slice) else a.oindex[np.asarray(rows)])

        params = {k: take(a) for k, a in g["params"].arrays()}
        force = take(g["force_nN"]) if forces else FileRows(p)
        return Dataset(force_nN=force, x_nm=np.asarray(g["x_nm"][:]), params=params,
                       attrs=dict(g.attrs))  # fmt: skip
    except DatasetError:
        raise
    except Exception as e:  # zarr raises its own error types for damaged stores
        raise DatasetError(f"{p}: unreadable Zarr store ({type(e).__name__}: {e})") from None


def _read(path: str | os.PathLike, rows: slice | np.ndarray | None, forces: bool) -> Dataset:
    """A checked sweep file or Zarr store: rows ``rows`` (all: None) of the parameters,
    with the forces read (``forces``) or left on disk (:class:`FileRows`)."""
    p = Path(path)
    if not p.exists():
        raise DatasetError(f"{p}: file not found")
    if is_zarr_path(p) or p.is_dir():
        return _load_zarr(p, rows, forces)
    try:
        with h5py.File(p, "r") as f:
            _check_sweep(p, f.attrs.get("format"), f["done"][:])
            sel = slice(None) if rows is None else rows
            force = f["force_nN"][sel] if forces else FileRows(p)
            params = {k: v[sel] for k, v in f["params"].items()}
            return Dataset(force_nN=force, x_nm=f["x_nm"][:], params=params, attrs=dict(f.attrs))
    except DatasetError:
        raise
    except (OSError, KeyError) as e:
        raise DatasetError(f"{p}: unreadable dataset ({e})") from None


def load_dataset(path: str | os.PathLike, rows: slice | np.ndarray | None = None) -> Dataset:
    """Read a sweep file or Zarr store (all rows, or a selection).

    Raises
    ------
    DatasetError
        If the file is missing, not HDF5 or Zarr, not a stickslip sweep, or incomplete.
    """
    return _read(path, rows, forces=True)


def open_dataset(path: str | os.PathLike) -> Dataset:
    """A sweep file or Zarr store with its forces left on disk (:class:`FileRows`).

    Positions, parameters and attributes are read into memory (a few numbers per row);
    the forces are read a chunk at a time when used, so a set larger than memory can be
    trained on. The same checks as :func:`load_dataset`.

    Raises
    ------
    DatasetError
        If the file is missing, not HDF5 or Zarr, not a stickslip sweep, or incomplete.
    """
    return _read(path, None, forces=False)


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
    if any(isinstance(d.force_nN, Rows) for d in sets):  # streamed parts stay on disk
        force: np.ndarray | Rows = ConcatRows([as_rows(d.force_nN) for d in sets])
    else:
        force = np.vstack([d.force_nN for d in sets])
    return Dataset(
        force_nN=force,
        x_nm=first.x_nm,
        params={k: np.concatenate([d.params[k] for d in sets]) for k in keep},
        attrs={
            **first.attrs,
            "n": sum(d.n for d in sets),
            "config": json.dumps([d.config_json for d in sets]),
        },  # fmt: skip
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
