"""MATLAB .mat files: named vectors as columns, a time axis with the speed, a signal
without a unit with a calibration, version 7.3 (HDF5) files, and the real recording."""

from __future__ import annotations

import h5py
import numpy as np
import pytest
from scipy.io import savemat

from stickslip.traces import TraceReadError, collect_traces
from stickslip.traces.formats import reader_options
from stickslip.traces.readers import read_file

from .conftest import SHARED_DATA

MACRO = SHARED_DATA / "macro-stickslip" / "k1002Nm_v42.mat"


def _sawtooth(n: int = 400, period: int = 40) -> np.ndarray:
    return 0.5 * (np.arange(n) % period) / period


def test_named_vectors_read_as_the_csv_columns_with_their_units(tmp_path):
    x_um = np.arange(400) * 1e-3
    F = _sawtooth()
    p = tmp_path / "line.mat"
    savemat(p, {"x_um": x_um, "force_pN": F * 1e3, "note": np.ones((3, 3))})
    (t,) = read_file(p)
    assert np.allclose(t.x_nm, x_um * 1e3) and np.allclose(t.force_nN, F)
    assert t.meta["format"] == "MATLAB .mat"


def test_a_time_axis_needs_the_speed_and_gives_x_from_zero(tmp_path):
    t_s = 93.9 + np.arange(400) / 2000.0  # a recording's clock, not started at 0
    p = tmp_path / "timed.mat"
    savemat(p, {"t": t_s, "force_mN": _sawtooth()})
    with pytest.raises(TraceReadError, match="--velocity"):
        read_file(p)
    (t,) = read_file(p, **reader_options(velocity_nm_per_s=42e3))
    assert t.x_nm[0] == 0.0 and np.allclose(np.diff(t.x_nm), 42e3 / 2000.0)
    assert np.allclose(t.force_nN, _sawtooth() * 1e6)
    assert t.meta["velocity_nm_per_s"] == 42e3


def test_a_signal_without_a_unit_is_read_with_the_calibration_or_refused(tmp_path):
    p = tmp_path / "rig.mat"
    savemat(p, {"t": np.arange(400) / 2000.0, "Fnorm": _sawtooth()})
    traces, errors = collect_traces([p])
    assert not traces and "'Fnorm' has no unit" in errors[0].reason
    assert "--calibration" in errors[0].reason and "--velocity" in errors[0].reason
    (t,) = read_file(p, **reader_options(7.0, velocity_nm_per_s=1e3))
    assert np.allclose(t.force_nN, 7.0 * _sawtooth())
    assert "Fnorm" in t.meta["signal"]


def test_a_version_7_3_file_is_read_as_hdf5(tmp_path):
    """MATLAB's -v7.3 files are HDF5 behind a 512-byte text header."""
    p = tmp_path / "v73.mat"
    with h5py.File(p, "w", userblock_size=512) as h:
        h["x_nm"] = np.arange(400, dtype=float)[None, :] * 0.05  # MATLAB's (1, n) row
        h["force_nN"] = _sawtooth()[None, :]
    with open(p, "r+b") as f:
        f.write(b"MATLAB 7.3 MAT-file, Platform: GLNXA64".ljust(128, b" "))
    (t,) = read_file(p)
    assert np.allclose(t.x_nm, np.arange(400) * 0.05) and np.allclose(t.force_nN, _sawtooth())


@pytest.mark.parametrize("content", [b"", b"MATLAB 5.0 MAT-file" + bytes(40), b"\x00" * 300])
def test_a_damaged_or_empty_file_is_one_sentence(tmp_path, content):
    p = tmp_path / "bad.mat"
    p.write_bytes(content)
    traces, errors = collect_traces([p])
    assert not traces and len(errors) == 1
    assert "Error" not in errors[0].reason and len(errors[0].reason.split()) >= 4


def test_a_file_without_vectors_says_what_to_save(tmp_path):
    p = tmp_path / "image.mat"
    savemat(p, {"img": np.ones((8, 8))})
    with pytest.raises(TraceReadError, match="no vector"):
        read_file(p)


def test_the_real_spring_block_recording_reads_to_its_spring():
    """The shared paper-on-paper recording (k = 1002 N/m, v = 42 um/s, Fnorm = F / m g
    with m = 30.7 g): read as a user states it, its stick slope is the spring."""
    if not MACRO.is_file():
        pytest.skip(f"real data missing: {MACRO} (clone shared/ beside the project)")
    from stickslip.estimators.classical import estimate_trace

    m_g_nN = 0.0307 * 9.81 * 1e9
    (t,) = read_file(MACRO, **reader_options(m_g_nN, velocity_nm_per_s=42e3))
    assert t.n == 751_281 and t.x_nm[-1] == pytest.approx(42e3 * (1 / 2000) * 751_280)
    est = estimate_trace(t.x_nm, t.force_nN, temperature_K=0)
    assert est.quality == "ok" and est.k_exp_N_m == pytest.approx(1002.0, rel=0.10)
