"""Sharded sweeps: Zarr stores, Dask runs equal to the single-process run bit for bit,
resume by shard, and every reader taking a ``.zarr`` store as a dataset (issue 20)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from stickslip.cli.main import app
from stickslip.simulators import PhysicalSettings, SweepConfig, run_sweep
from stickslip.simulators import sweep as sweep_mod
from stickslip.simulators.shards import ClusterError, shard_bounds, shard_rows_for
from stickslip.traces.dataset import DatasetError, load_dataset, read_done
from stickslip.traces.readers import collect_traces, expand_paths

zarr = pytest.importorskip("zarr")
distributed = pytest.importorskip("distributed")

SHORT = PhysicalSettings(length_nm=1.0, pixels=16, velocity_nm_per_s=600.0)
CFG = SweepConfig(physics=SHORT, n=24, seed=7)
runner = CliRunner()


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The single-process HDF5 sweep every other run must equal."""
    out = tmp_path_factory.mktemp("ref") / "ref.h5"
    return load_dataset(run_sweep(CFG, out, progress=False))


@pytest.fixture(scope="module")
def scheduler():
    """An in-process Dask cluster, passed to run_sweep by its address."""
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                                  dashboard_address=":0") as cluster:  # fmt: skip
        yield cluster.scheduler_address


def _same(a, b):
    np.testing.assert_array_equal(a.force_nN, b.force_nN)  # bit for bit
    np.testing.assert_array_equal(a.x_nm, b.x_nm)
    assert set(a.params) == set(b.params)
    for k in a.params:
        np.testing.assert_array_equal(a.params[k], b.params[k], err_msg=k)
    for k in ("config", "seed", "stickslip_version", "n", "pixels", "format"):
        assert a.attrs[k] == b.attrs[k], k


def test_shard_layout():
    assert shard_rows_for(24, 3, 64) == 8 and shard_rows_for(25, 3, 64) == 9
    assert shard_rows_for(10, None, 64) == 10 and shard_rows_for(5, 50, 64) == 1
    assert shard_bounds(25, 9) == [(0, 9), (9, 18), (18, 25)]


def test_zarr_store_single_process_equals_hdf5(tmp_path, reference):
    out = run_sweep(CFG, tmp_path / "s.zarr", shards=3, progress=False)
    ds = load_dataset(out)
    _same(ds, reference)
    assert SweepConfig.from_json(ds.attrs["config"]) == CFG
    g = zarr.open_group(str(out), mode="r")
    assert g["force_nN"].chunks == (8, 16) and g["params"]["U0_eV"].chunks == (8,)
    assert g.attrs["shard_rows"] == 8
    sub = load_dataset(out, rows=np.array([3, 17]))
    np.testing.assert_array_equal(sub.force_nN, reference.force_nN[[3, 17]])


def test_dask_run_is_bit_for_bit_and_resumes_missing_shards(
    tmp_path, reference, scheduler, monkeypatch
):
    out = tmp_path / "s.zarr"
    part = sweep_mod.partial_path(out)
    real = sweep_mod.write_rows
    written = []

    def flaky(path, rows, *args, **kwargs):
        if len(written) == 1:
            raise KeyboardInterrupt  # the second shard never arrives
        written.append(np.sort(rows))
        return real(path, rows, *args, **kwargs)

    monkeypatch.setattr(sweep_mod, "write_rows", flaky)
    with pytest.raises(KeyboardInterrupt):
        run_sweep(CFG, out, dask=scheduler, shards=3, progress=False)
    assert not out.exists() and part.exists()
    assert list(np.flatnonzero(read_done(part))) == list(written[0])  # one whole shard
    assert written[0].size == 8 and written[0][0] % 8 == 0

    monkeypatch.setattr(sweep_mod, "write_rows", lambda p, rows, *a, **k: (
        written.append(np.sort(rows)), real(p, rows, *a, **k)))  # fmt: skip
    with pytest.raises(DatasetError, match="interrupted run"):
        run_sweep(CFG, out, dask=scheduler, shards=3, progress=False)
    run_sweep(CFG, out, dask=scheduler, shards=5, resume=True, progress=False)
    # the two missing shards of the store's own layout, nothing else
    assert sorted(r[0] for r in written[1:]) == sorted({0, 8, 16} - {written[0][0]})
    assert all(r.size == 8 for r in written[1:])
    _same(load_dataset(out), reference)


def test_unreachable_scheduler_is_one_line(tmp_path, monkeypatch):
    monkeypatch.setattr("stickslip.simulators.shards.CONNECT_TIMEOUT_S", 1.0)
    out = tmp_path / "s.zarr"
    with pytest.raises(ClusterError, match="cannot reach the Dask scheduler"):
        run_sweep(CFG, out, dask="tcp://127.0.0.1:9", progress=False)
    assert not out.exists() and not sweep_mod.partial_path(out).exists()  # nothing begun


def test_cli_dask_local_two_shards_equals_single_process(tmp_path, reference):
    out = tmp_path / "s.zarr"
    args = ["simulate", "--n", "24", "--seed", "7", "--velocity", "600", "--length", "1",
            "--pixels", "16", "--no-progress", "--out", str(out)]  # fmt: skip
    r = runner.invoke(app, [*args, "--dask", "local", "--shards", "2"])
    assert r.exit_code == 0, r.output
    _same(load_dataset(out), reference)
    assert json.loads(load_dataset(out).attrs["config"])["n"] == 24
    # a second run replaces the finished store, single-process this time
    r = runner.invoke(app, args)
    assert r.exit_code == 0, r.output
    _same(load_dataset(out), reference)


def test_readers_take_a_zarr_store_as_a_dataset(tmp_path, reference):
    folder = tmp_path / "data"
    folder.mkdir()
    store = run_sweep(CFG, folder / "s.zarr", shards=2, progress=False)
    h5 = run_sweep(CFG, folder / "s.h5", progress=False)
    paths, errors = expand_paths([folder])
    assert not errors and paths == [h5, store]  # the store is not expanded into its files
    z, errz = collect_traces([store])
    h, errh = collect_traces([h5])
    assert not errz and not errh and len(z) == len(h) == 24
    for a, b in zip(z, h, strict=True):
        assert a.name == b.name
        np.testing.assert_array_equal(a.force_nN, b.force_nN)
        drop = {"file", "shard_rows"}
        assert {k: v for k, v in a.meta.items() if k not in drop} == {
            k: v for k, v in b.meta.items() if k not in drop}  # fmt: skip
    bad = tmp_path / "other.zarr"
    bad.mkdir()
    _, errors = collect_traces([bad])
    assert len(errors) == 1 and "not a Zarr store" in str(errors[0])


@pytest.mark.slow  # the classical estimator's first call compiles
def test_label_reads_a_zarr_store(tmp_path):
    store = run_sweep(SweepConfig(n=4, seed=3), tmp_path / "s.zarr", progress=False)
    out = tmp_path / "labels.csv"
    r = runner.invoke(app, ["label", str(store), "--out", str(out)])
    assert r.exit_code == 0, r.output
    assert len(out.read_text().splitlines()) == 5
