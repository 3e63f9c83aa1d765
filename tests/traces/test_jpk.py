"""JPK ``.jpk`` images through AFMReader (the optional ``jpk`` extra).

No real JPK file is available: the reading tests write small TIFF files with the JPK
tags (channel name, retrace flag, calibration slots, grid) using tifffile, and are
skipped when AFMReader is not installed. The missing-extra path always runs.
"""

from __future__ import annotations

import struct
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from stickslip.cli.main import app
from stickslip.traces.readers import read_file, read_scan
from stickslip.traces.trace import TraceReadError


def _run(args: list) -> object:
    return CliRunner().invoke(app, [str(a) for a in args])


def _tiff_like(tmp_path: Path, name: str = "scan.jpk") -> Path:
    p = tmp_path / name
    p.write_bytes(b"II*\x00" + b"\x00" * 200)
    return p


def test_missing_extra_names_the_file_and_the_extra(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "AFMReader", None)  # import AFMReader -> ImportError
    monkeypatch.setitem(sys.modules, "AFMReader.jpk", None)
    path = _tiff_like(tmp_path)
    with pytest.raises(TraceReadError) as e:
        read_file(path)
    msg = str(e.value)
    assert msg == (f"{path}: reading .jpk files needs the optional extra: "
                   "pip install 'stickslip[jpk]'")
    r = _run(["inspect", path])
    assert r.exit_code == 1
    assert r.stderr.strip() == f"stickslip: error: {msg}"


def test_not_a_tiff_is_refused_before_any_import(tmp_path):
    path = tmp_path / "notes.jpk"
    path.write_text("force curve exported as text\n")
    with pytest.raises(TraceReadError, match="notes.jpk: not a JPK image file"):
        read_file(path)


# ----------------------------------------------------------------------------- with AFMReader

UNIT_BY_SLOT = 0x80A2


def _write_jpk(path: Path, channels: list[tuple[str, int, str, np.ndarray, float, float]],
               length_m: float = 2e-6) -> None:
    """A JPK-tagged TIFF: thumbnail page with the grid, then one page per channel."""
    tifffile = pytest.importorskip("tifffile")
    ny, nx = channels[0][3].shape
    with tifffile.TiffWriter(path) as tw:
        tw.write(np.zeros((4, 4), np.uint8), extratags=[
            (0x8042, "d", 1, length_m, True), (0x8043, "d", 1, length_m * ny / nx, True),
            (0x8046, "I", 1, nx, True), (0x8047, "I", 1, ny, True)])
        for name, retrace, unit, raw, mult, offset in channels:
            tw.write(raw, extratags=[
                (0x8050, "s", 0, name, True), (0x8051, "I", 1, retrace, True),
                (0x8080, "I", 1, 2, True), (0x8081, "s", 0, "calibrated", True),
                (0x8090, "s", 0, "raw", True), (UNIT_BY_SLOT, "s", 0, "V", True),
                (0x80A3, "s", 0, "NullScaling", True),
                (0x8090 + 0x30, "s", 0, "calibrated", True),
                (UNIT_BY_SLOT + 0x30, "s", 0, unit, True),
                (0x80A3 + 0x30, "s", 0, "LinearScaling", True),
                (0x80A4 + 0x30, "d", 1, mult, True), (0x80A5 + 0x30, "d", 1, offset, True)])


@pytest.fixture
def afmreader():
    return pytest.importorskip("AFMReader.jpk", reason="AFMReader (the jpk extra) not installed")


def test_synthetic_jpk_lateral_channels(afmreader, tmp_path, capfd):
    rng = np.random.default_rng(3)
    raw = rng.integers(0, 60000, (6, 16), dtype=np.uint16)
    path = tmp_path / "map.jpk"
    _write_jpk(path, [("height", 0, "m", raw, 1e-10, 0.0),
                      ("hDeflection", 0, "V", raw, 1e-4, -1.0),
                      ("hDeflection", 1, "V", raw[:, ::-1].copy(), 1e-4, -1.0)])
    scan = read_scan(path)
    assert scan.fmt == "JPK"
    assert [(c.name, c.direction, c.unit, c.shape, c.is_lateral) for c in scan.channels] == [
        ("height", "trace", "m", (6, 16), False),
        ("Lateral deflection", "trace", "V", (6, 16), True),
        ("Lateral deflection", "retrace", "V", (6, 16), True)]
    np.testing.assert_allclose(scan.channels[1].data, raw * 1e-4 - 1.0)  # stored row order
    assert scan.scan_size_nm == pytest.approx(2000.0)
    traces = read_file(path, calibration_nN_per_V=5.0)
    assert len(traces) == 12 and traces[0].name == "map:Lateral deflection:trace:L000"
    np.testing.assert_allclose(traces[0].force_nN, 5.0 * (raw[0] * 1e-4 - 1.0))
    np.testing.assert_allclose(np.diff(traces[0].x_nm), 125.0)
    assert "AFMReader" not in capfd.readouterr().err  # its loguru output is silenced


def test_damaged_jpk_gives_one_line(afmreader, tmp_path, capfd):
    path = tmp_path / "broken.jpk"
    path.write_bytes(b"II*\x00" + struct.pack("<IH", 8, 500) + b"\xff" * 300)  # bad IFD
    with pytest.raises(TraceReadError, match="broken.jpk: not a readable JPK image file") as e:
        read_file(path)
    assert "\n" not in str(e.value)
    empty = _tiff_like(tmp_path, "empty.jpk")  # no IFD at all: tifffile only warns
    r = _run(["inspect", path, empty])
    assert r.exit_code == 1
    assert len(r.stderr.strip().splitlines()) == 2, r.stderr
    assert "empty.jpk: no JPK image channels" in r.stderr
    assert capfd.readouterr().err == ""


def test_jpk_without_image_channels(afmreader, tmp_path):
    tifffile = pytest.importorskip("tifffile")
    path = tmp_path / "plain.jpk"
    tifffile.imwrite(path, np.zeros((3, 3), np.uint8))
    with pytest.raises(TraceReadError, match="plain.jpk: no JPK image channels"):
        read_file(path)
