"""The project's simulated-dataset format: chunked HDF5.

Layout (one file = one sweep)::

    /force_nN        (N, pixels) float32, chunked by rows, compressed
    /x_nm            (pixels,)   recorded position, 0 at the first pixel
    /support_nm      (N, pixels) absolute support position at each pixel centre
    /params/<name>   (N,) per-trajectory table: U0_eV, K_N_m, eta, F_mean_nN, lattice_nm,
                     velocity_nm_per_s, temperature_K, damping_per_s, mass_kg, dt_s,
                     warmup_nm, index, and the substrate draw (mod_*, defect_* (N, D))
    /done            (N,) bool, rows already simulated (for --resume)
    attrs: format, config (JSON of SweepConfig), seed, stickslip_version, n, pixels

:func:`load_dataset` reads it back; the config in ``attrs`` regenerates it.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

FORMAT = "stickslip-sweep-1"
ROW_CHUNK = 64


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


def create_dataset_file(
    path: str | os.PathLike,
    n: int,
    x_nm: np.ndarray,
    params: dict[str, np.ndarray],
    attrs: dict,
) -> None:
    """Create an empty sweep file with the parameter table filled and no rows done."""
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


def write_rows(
    path: str | os.PathLike,
    rows: np.ndarray,
    force_nN: np.ndarray,
    support_nm: np.ndarray,
    extra_params: dict[str, np.ndarray],
) -> None:
    """Write simulated rows (and per-row results such as F_mean_nN), then mark them done."""
    with h5py.File(path, "r+") as f:
        sl = slice(int(rows[0]), int(rows[-1]) + 1)  # rows are a contiguous chunk
        f["force_nN"][sl] = force_nN
        f["support_nm"][sl] = support_nm
        for k, v in extra_params.items():
            f["params"][k][sl] = v
        f["done"][sl] = True
        f.flush()


def read_done(path: str | os.PathLike) -> np.ndarray:
    """Which rows of a (possibly partial) sweep file are complete."""
    with h5py.File(path, "r") as f:
        return f["done"][:]


def read_attrs(path: str | os.PathLike) -> dict:
    with h5py.File(path, "r") as f:
        return dict(f.attrs)


def load_dataset(path: str | os.PathLike, rows: slice | np.ndarray | None = None) -> Dataset:
    """Read a sweep file (all rows, or a selection).

    Raises
    ------
    DatasetError
        If the file is missing, not HDF5, not a stickslip sweep, or incomplete.
    """
    p = Path(path)
    if not p.exists():
        raise DatasetError(f"{p}: file not found")
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
