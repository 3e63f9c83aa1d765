"""NT-MDT ``.mdt`` reader: the real GaAs_map.mdt, synthetic friction maps, damaged copies."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from stickslip.cli.main import app
from stickslip.traces.formats.mdt import read_mdt
from stickslip.traces.readers import collect_traces, read_file, read_scan
from stickslip.traces.trace import TraceReadError

GAAS = (Path(__file__).resolve().parents[2].parent / "shared" / "data" / "ntmdt-mdt"
        / "GaAs_map.mdt")
STEP_UM = 0.011767974683082529  # pixel pitch stated by both image frames
FLOAT32 = -(4 + 23 * 256)


@pytest.fixture
def gaas() -> Path:
    if not GAAS.is_file():
        pytest.skip(f"real data file missing: {GAAS} (clone shared/ beside the project)")
    return GAAS


# ----------------------------------------------------------------------------- builders
# Minimal MDT files written from the public format description, to test what the real
# file lacks (lateral-force frames, old scanned-data frames).


def _frame(type_code: int, body: bytes, var_size: int = 0) -> bytes:
    head = struct.pack("<IHBB6HH", 22 + len(body), type_code, 0, 7, 2024, 5, 6, 7, 8, 9, var_size)
    return head + body


def _mdt(frames: list[bytes]) -> bytes:
    data = b"".join(frames)
    return struct.pack("<4sI4sH19s", b"\x01\xb0\x93\xff", len(data), b"\0" * 4,
                       len(frames) - 1, b"\0" * 19) + data


def _calibration(unit: str, bias: float, scale: float, n: int, dtype: int) -> bytes:
    u = unit.encode()
    fields = struct.pack("<IIIQdQddQQiI", 0, 0, len(u), 0, 0.0, 0, bias, scale, 0,
                         n - 1 if n else 2**64 - 1, dtype, 0)
    return struct.pack("<II", 8 + len(fields) + len(u), len(fields)) + fields + u


def _mda_image(title: str, img: np.ndarray, unit: str = "V", step_um: float = 0.0005,
               xml: str = "") -> bytes:
    ny, nx = img.shape
    t, x = title.encode(), xml.encode("utf-16-le")
    head = struct.pack("<II32s4s8I", 76, 0, b"\0" * 32, b"\0" * 4, len(t), len(x), 0, 0, 0, 0,
                       0, img.size * 4)
    array = struct.pack("<QIII", img.size, 4, 2, 1)
    cals = (_calibration("um", 0.0, step_um, nx, -8) + _calibration("um", 0.0, step_um, ny, -8)
            + _calibration(unit, 0.0, 1.0, 0, FLOAT32))
    body = (head + t + x + b"\0" * 4 + struct.pack("<I", len(array)) + array + cals
            + img.astype("<f4").tobytes())
    return _frame(106, body)


def _scanned(title: str, raw: np.ndarray, adc: int, z_step: float, z_unit: int,
             step_a: float = 5.0, velocity_a_per_s: float = 600.0) -> bytes:
    ny, nx = raw.shape
    scales = struct.pack("<ffhffhffh", 0.0, step_a, 0, 0.0, step_a, 0, 0.0, z_step, z_unit)
    scan_vars = struct.pack("<BBHHHfHBBBBBBfffBBiiB", adc, 1, nx, ny, 0, 1.0, 0, 0, 0, 0, 0, 0, 0,
                            velocity_a_per_s, 0.0, 0.0, 0, 0, 0, 0, 0)
    var_block = scales + scan_vars + b"\0" * 34
    t = title.encode("cp1251")
    body = (var_block + struct.pack("<4H", 0, nx, ny, 0) + raw.astype("<i2").tobytes()
            + struct.pack("<I", len(t)) + t + struct.pack("<I", 0))
    return _frame(0, body, var_size=len(var_block))


def _write(tmp_path: Path, name: str, data: bytes) -> Path:
    p = tmp_path / name
    p.write_bytes(data)
    return p


def _run(args: list) -> object:
    return CliRunner().invoke(app, [str(a) for a in args])


def _error_lines(result) -> list[str]:
    return [ln for ln in result.stderr.splitlines() if ln.startswith("stickslip: error:")]


# ----------------------------------------------------------------------------- real file


def test_real_file_frame_structure(gaas):
    scan = read_mdt(gaas)
    assert scan.fmt == "NT-MDT MDT"
    assert [f.type_code for f in scan.frames] == [3, 106, 106, 190]
    text, fwd, bwd, curves = scan.frames
    assert text.kind == "text" and text.title == "Text Frame" and "GaAs 77" in text.note
    for frame, title in ((fwd, "1F:Iprobe"), (bwd, "1B:Iprobe")):
        assert frame.kind == "MDA image" and frame.title == title
        assert frame.shape == (256, 256) and frame.unit == "nA"
        assert [(a.name, a.unit, a.size) for a in frame.axes] == [("x", "um", 256),
                                                                  ("y", "um", 256)]
        assert frame.axes[0].step == pytest.approx(STEP_UM)
    assert curves.kind == "spectroscopy curves" and curves.unit == "nA"
    assert curves.shape == (150, 587)
    assert [(a.name, a.unit, a.size) for a in curves.axes] == [("BVValue", "V", 587)]
    assert "25 points, 150 curves of Iprobe" in curves.note


def test_real_file_channels_and_metadata(gaas):
    scan = read_scan(gaas)  # through the registry
    assert [(c.name, c.direction, c.unit, c.shape) for c in scan.channels] == [
        ("Iprobe", "trace", "nA", (256, 256)), ("Iprobe", "retrace", "nA", (256, 256))]
    assert all(c.data is None for c in scan.channels)  # not lateral: listed, not loaded
    assert scan.lateral() == []
    assert scan.scan_size_nm == pytest.approx(256 * STEP_UM * 1000)
    assert scan.meta["velocity_nm_per_s"] == pytest.approx(2999.7656, rel=1e-6)  # 3 um/s
    assert scan.meta["scan_rate_hz"] == pytest.approx(2999.7656 / (2 * 256 * STEP_UM * 1000))


def test_real_file_data_match_the_stated_data_offset(gaas):
    """The image found by walking the calibrations is where the header's offset says."""
    scan = read_mdt(gaas, all_data=True)
    raw = gaas.read_bytes()
    for ch, frame_start in zip(scan.channels, (729, 569713), strict=True):
        data_offset, data_size = struct.unpack_from("<II", raw, frame_start + 22 + 68)
        assert data_size == 256 * 256 * 8
        expected = np.frombuffer(raw, "<f8", 256 * 256, data_offset).reshape(256, 256)
        assert ch.data is not None and ch.data.shape == (256, 256)
        np.testing.assert_array_equal(ch.data, expected)
        assert np.isfinite(ch.data).all() and ch.data.std() > 0


def test_real_file_gives_no_traces(gaas):
    with pytest.raises(TraceReadError, match=r"no lateral-force channel \(found: Iprobe"):
        read_file(gaas)


# ----------------------------------------------------------------------------- CLI


def test_cli_inspect_lists_the_frames(gaas):
    r = _run(["inspect", gaas])
    assert r.exit_code == 0, r.stderr
    out = r.stdout
    assert "format: NT-MDT MDT" in out
    assert "scan size: 3012.6 nm, 256 lines x 256 pixels (pixel 11.77 nm)" in out
    assert "frames (4):" in out
    assert "frame 0: type 3 (text) 'Text Frame'; 7 characters: 'GaAs 77'" in out
    assert ("frame 1: type 106 (MDA image) '1F:Iprobe'; 256x256 nA; "
            "axes x 256 x 0.011768 um, y 256 x 0.011768 um") in out
    assert "frame 2: type 106 (MDA image) '1B:Iprobe'; 256x256 nA" in out
    assert "frame 3: type 190 (spectroscopy curves); 150x587 nA; axes BVValue 587" in out
    assert "traces: none (no lateral-force channel)" in out
    assert r.stderr == ""


@pytest.mark.parametrize("command", ["label", "infer"])
def test_cli_label_and_infer_refuse_in_one_line(gaas, tmp_path, command):
    r = _run([command, gaas, "--out", tmp_path / "x.csv"])
    assert r.exit_code == 1
    errors = _error_lines(r)
    assert len(errors) == 1, r.stderr
    assert "GaAs_map.mdt: no lateral-force channel" in errors[0]
    assert "Traceback" not in r.stderr + r.stdout


# ----------------------------------------------------------------------------- synthetic


def _friction_map(ny: int = 4, nx: int = 32) -> np.ndarray:
    x = np.arange(nx)
    return np.stack([0.2 + 0.05 * np.sin(x / 3.0 + i) for i in range(ny)])


def test_synthetic_mda_friction_map_becomes_traces(tmp_path):
    trace_v = _friction_map()
    retrace_v = -trace_v[:, ::-1] + 0.01
    xml = "<Scan><scshRateUnits>um/sec</scshRateUnits><scshRate>2</scshRate></Scan>"
    path = _write(tmp_path, "lfm.mdt", _mdt([
        _mda_image("1F:Height", trace_v * 0, unit="nm", xml=xml),
        _mda_image("1F:LF", trace_v, xml=xml),
        _mda_image("1B:LF", retrace_v, xml=xml),
    ]))
    scan = read_mdt(path)
    assert [(c.name, c.direction, c.is_lateral) for c in scan.channels] == [
        ("Height", "trace", False), ("LF", "trace", True), ("LF", "retrace", True)]
    assert scan.scan_size_nm == pytest.approx(32 * 0.5)
    assert scan.meta["velocity_nm_per_s"] == pytest.approx(2000.0)
    traces = read_file(path, calibration_nN_per_V=10.0)
    assert len(traces) == 8
    first = traces[0]
    assert first.name == "lfm:LF:trace:L000"
    assert first.meta["unit"] == "nN" and first.meta["calibrated"]
    np.testing.assert_allclose(first.force_nN, 10.0 * trace_v[0], rtol=1e-6)
    np.testing.assert_allclose(np.diff(first.x_nm), 0.5)
    back = next(t for t in traces if t.meta["direction"] == "retrace")
    np.testing.assert_allclose(back.force_nN, 10.0 * -retrace_v[0][::-1], rtol=1e-5)


def test_synthetic_old_scanned_lateral_frame(tmp_path):
    raw = np.arange(3 * 20, dtype=np.int16).reshape(3, 20) - 30
    path = _write(tmp_path, "old.mdt", _mdt([_scanned("", raw, adc=2, z_step=0.01, z_unit=2)]))
    scan = read_mdt(path)
    (frame,) = scan.frames
    assert (frame.type_code, frame.kind, frame.shape, frame.unit) == (0, "scanned data",
                                                                      (3, 20), "V")
    (ch,) = scan.channels
    assert ch.name == "Lateral F" and ch.is_lateral and ch.unit == "V"
    np.testing.assert_allclose(ch.data, 0.01 * raw)
    assert scan.scan_size_nm == pytest.approx(20 * 0.5)  # 5 angstrom steps
    assert scan.meta["velocity_nm_per_s"] == pytest.approx(60.0)  # 600 angstrom/s
    traces = read_file(path)
    assert len(traces) == 3 and traces[0].meta["unit"] == "V"
    assert not traces[0].meta["calibrated"]


def test_lateral_signal_in_nanoamperes_is_refused_in_one_line(tmp_path):
    path = _write(tmp_path, "na.mdt", _mdt([_mda_image("1F:LF", _friction_map(), unit="nA")]))
    with pytest.raises(TraceReadError, match="channel LF: unit 'nA' is neither a force"):
        read_file(path)


# ----------------------------------------------------------------------------- damaged input


def _one_line_error(path: Path) -> str:
    """Reading must fail (or succeed) cleanly: only TraceReadError, one line, naming the file."""
    try:
        read_mdt(path)
    except TraceReadError as e:
        msg = str(e)
        assert "\n" not in msg and path.name in msg
        return msg
    return ""


@pytest.mark.parametrize("length", [0, 3, 20, 33, 54, 729, 800, 45_000, 600_000, -1])
def test_truncated_copies_fail_in_one_line(gaas, tmp_path, length):
    data = gaas.read_bytes()
    path = _write(tmp_path, f"cut{length}.mdt", data[:length])
    msg = _one_line_error(path)
    assert msg, "a truncated file must not read"
    assert "NT-MDT" in msg


def test_corrupted_copies_never_crash(gaas, tmp_path):
    data = bytearray(gaas.read_bytes())
    rng = np.random.default_rng(21)
    # the headers: file, text frame, MDA headers and calibrations, the curves frame's blocks
    regions = [(0, 33), (33, 729), (729, 729 + 1200), (569713, 569713 + 300),
               (1138697, 1138697 + 2000)]
    for k in range(40):
        bad = bytearray(data)
        lo, hi = regions[k % len(regions)]
        for pos in rng.integers(lo, hi, size=1 + k % 4):
            bad[pos] = int(rng.integers(0, 256))
        _one_line_error(_write(tmp_path, f"bad{k}.mdt", bytes(bad)))
    # size fields set to extremes
    for offset, fmt, value in [(4, "<I", 2**32 - 1), (12, "<H", 65535), (33, "<I", 5),
                               (729, "<I", 2**31), (729 + 22, "<I", 2**32 - 1),
                               (729 + 22 + 76 + 9 + 43068 + 1104 + 4, "<I", 2**31)]:
        bad = bytearray(data)
        struct.pack_into(fmt, bad, offset, value)
        assert _one_line_error(_write(tmp_path, f"size{offset}.mdt", bytes(bad)))
    # a damaged spectroscopy frame is only listed: the images still read
    bad = bytearray(data)
    struct.pack_into("<I", bad, 1138697 + 22, 2**31)  # its block count
    scan = read_mdt(_write(tmp_path, "curves.mdt", bytes(bad)))
    assert len(scan.channels) == 2 and scan.frames[3].note.startswith("damaged (")


def test_batch_with_damaged_file_still_reads_the_good_one(gaas, tmp_path):
    good = _write(tmp_path, "good.mdt", _mdt([_mda_image("1F:LF", _friction_map())]))
    cut = _write(tmp_path, "cut.mdt", gaas.read_bytes()[:5000])
    junk = _write(tmp_path, "junk.mdt", b"not an mdt file at all" * 10)
    traces, errors = collect_traces([cut, good, junk])
    assert len(traces) == 4 and {t.meta["channel"] for t in traces} == {"LF"}
    text = [str(e) for e in errors]
    assert len(text) == 2
    assert "cut.mdt: truncated NT-MDT file" in text[0]
    assert "junk.mdt: not an NT-MDT file" in text[1]
    r = _run(["inspect", cut, good, junk])
    assert r.exit_code == 1
    assert len(_error_lines(r)) == 2 and "Traceback" not in r.stderr
    assert "good.mdt" in r.stdout and "traces: 4 (trace), unit V" in r.stdout


_SMALL = _mdt([_frame(3, struct.pack("<I", 4) + b"\0" * 14 + b"note" + struct.pack("<I", 0)),
               _scanned("", np.arange(24, dtype=np.int16).reshape(3, 8), adc=2, z_step=0.01,
                        z_unit=2),
               _mda_image("1F:LF", _friction_map(3, 8)), _mda_image("1B:LF", _friction_map(3, 8))])


@settings(max_examples=150, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(cut=st.integers(0, len(_SMALL)), flips=st.lists(
    st.tuples(st.integers(0, len(_SMALL) - 1), st.integers(0, 255)), max_size=6))
def test_fuzzed_small_files_never_crash(tmp_path, cut, flips):
    data = bytearray(_SMALL)
    for pos, value in flips:
        data[pos] = value
    _one_line_error(_write(tmp_path, "fuzz.mdt", bytes(data)))
    _one_line_error(_write(tmp_path, "fuzzcut.mdt", bytes(data[:cut])))


def test_small_fuzz_seed_reads(tmp_path):
    scan = read_mdt(_write(tmp_path, "seed.mdt", _SMALL))
    assert [f.type_code for f in scan.frames] == [3, 0, 106, 106]
    assert scan.frames[0].note == "4 characters: 'note'"
    assert [(c.name, c.direction) for c in scan.channels] == [
        ("Lateral F", ""), ("LF", "trace"), ("LF", "retrace")]
