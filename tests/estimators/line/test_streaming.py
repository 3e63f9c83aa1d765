"""Training streamed from disk: chunked reading, reproducible batches, HDF5 = Zarr, and a
tiny training run from an HDF5 file."""

from __future__ import annotations

from functools import partial

import numpy as np
import pytest
import torch

from stickslip.estimators.line.ensemble import LineSpec
from stickslip.estimators.line.streaming import LineBatches, StreamSettings, shuffle_buffer
from stickslip.estimators.line.training import (
    LineTrainConfig,
    _prepare_rows,
    train_line_ensemble,
)
from stickslip.traces.dataset import (
    ArrayRows,
    create_dataset_file,
    open_dataset,
    write_rows,
)

PIXELS = 300
X_NM = np.arange(PIXELS) * LineSpec().pixel_nm


def _lines(n: int, seed: int = 0) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Hand-made sawtooth-plus-sine lines (no simulation) and their parameter table."""
    rng = np.random.default_rng(seed)
    K, U0 = rng.uniform(2, 20, n), rng.uniform(0.5, 3, n)
    a = np.full(n, 0.246)
    saw = (X_NM / 0.246) % 1.0
    force = K[:, None] * 0.246 * saw + 0.1 * np.sin(X_NM / 0.7 + rng.uniform(0, 6, (n, 1)))
    params = {"U0_eV": U0, "K_N_m": K, "F_mean_nN": force.mean(axis=1), "lattice_nm": a,
              "velocity_nm_per_s": np.full(n, 60.0), "eta": 52.26 * U0 / K,
              "mod_amplitude": np.where(np.arange(n) % 3 == 0, 0.0, 0.1),
              "defect_count": np.zeros(n, int)}  # fmt: skip
    return force.astype(np.float32), params


def _write(path, force, params, shard_rows=None):
    create_dataset_file(path, force.shape[0], X_NM, params, {"config": "{}"}, shard_rows)
    write_rows(path, np.arange(force.shape[0]), force, np.zeros(force.shape), {})
    return path


@pytest.fixture(scope="module")
def sets(tmp_path_factory):
    pytest.importorskip("zarr")
    d = tmp_path_factory.mktemp("stream")
    force, params = _lines(300)
    return force, params, _write(d / "s.h5", force, params), _write(d / "s.zarr", force, params)


def _batches(force_nN, params, workers=1, seed=0, batch=32, shuffle=96, member=0):
    cfg = LineTrainConfig(seed=seed)
    prepare = partial(_prepare_rows, params=params, x_nm=X_NM, spec=LineSpec(crop=200),
                      config=cfg)  # fmt: skip
    train = np.arange(force_nN.shape[0])[np.arange(force_nN.shape[0]) % 10 != 0]
    flat = params["mod_amplitude"] == 0
    return LineBatches(force_nN, train, flat, prepare, batch, 0.25, seed, member,
                       StreamSettings(num_workers=workers, shuffle_rows=shuffle))  # fmt: skip


def test_chunked_reading_visits_every_training_row_once_per_epoch(sets):
    force, params, h5, _ = sets
    source = open_dataset(h5).force_nN
    assert source.chunk_rows == 64 and len(source.chunks()) == 5
    for workers in (1, 3):
        b = _batches(source, params, workers)
        for epoch in (0, 1):
            b.epoch = epoch
            seen = np.concatenate([idx for w in range(workers)
                                   for idx, rows in b.rows(w, b.rng(w))])  # fmt: skip
            assert np.array_equal(np.sort(seen), np.flatnonzero(b.keep))
        # rows come with their own forces, in a shuffled order
        idx, rows = next(b.rows(0, b.rng(0)))
        np.testing.assert_array_equal(rows, force[idx])
        assert not np.all(np.diff(idx) > 0)
    # the buffer alone: every row out once, in blocks of the asked size (the last short)
    blocks = [(np.arange(s, s + 10), np.arange(s, s + 10)[:, None] * 1.0) for s in range(0, 95, 10)]
    out = list(shuffle_buffer(blocks, 25, 8, np.random.default_rng(0)))
    assert [o[0].size for o in out] == [8] * 12 + [4]
    assert sorted(np.concatenate([o[0] for o in out]).tolist()) == list(range(100))
    assert all(np.array_equal(i, r[:, 0]) for i, r in out)


def test_batches_are_reproducible_for_a_seed_and_differ_between_epochs(sets):
    force, params, _, _ = sets

    def epoch(workers, seed=0, e=0):
        b = _batches(ArrayRows(force), params, workers, seed)
        b.epoch = e
        return list(b)

    first = epoch(2)
    assert len(first) == _batches(ArrayRows(force), params, 2).batches_per_epoch() == 7
    for one, two in zip(first, epoch(2), strict=True):
        assert all(torch.equal(a, b) for a, b in zip(one, two, strict=True))
    assert not torch.equal(first[0][2], epoch(2, e=1)[0][2])
    assert not torch.equal(first[0][2], epoch(2, seed=1)[0][2])
    # no loader processes: the batches of one worker
    assert all(torch.equal(a[0], b[0]) for a, b in zip(epoch(0), epoch(1), strict=True))


def test_a_zarr_store_and_an_hdf5_file_give_the_same_batches(sets):
    force, params, h5, zs = sets
    out = []
    for path in (h5, zs):
        b = _batches(open_dataset(path).force_nN, params, workers=1)
        out.append(list(b))
    mem = list(_batches(ArrayRows(force), params, workers=1))
    for h, z, m in zip(*out, mem, strict=True):
        for a, b_, c in zip(h, z, m, strict=True):
            assert torch.equal(a, b_) and torch.equal(a, c)


def test_training_from_an_hdf5_file_end_to_end(sets):
    force, params, h5, _ = sets
    data = open_dataset(h5)
    cfg = LineTrainConfig(members=1, epochs=2, batch_size=32, val_fraction=0.2, mse_epochs=1,
                          calibration_draws=2)  # fmt: skip
    torch.set_num_threads(1)
    ens, report = train_line_ensemble(
        data.force_nN,
        data.x_nm,
        data.params,
        cfg,
        LineSpec(crop=200),
        progress=False,
        stream=StreamSettings(num_workers=1, shuffle_rows=128),
    )
    assert len(ens.members) == 1 and report["n_train"] == 240
    assert len(report["history"]) == 2 and np.isfinite(report["history"][-1]["loss"])
    assert report["loader"]["num_workers"] == 1
    # the in-memory array trains through the same path to the same model
    _, again = train_line_ensemble(
        force,
        X_NM,
        params,
        cfg,
        LineSpec(crop=200),
        progress=False,
        stream=StreamSettings(num_workers=0, shuffle_rows=128),
    )
    assert again["history"][-1]["loss"] == pytest.approx(report["history"][-1]["loss"], rel=1e-5)
