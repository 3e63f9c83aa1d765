"""Plain formats, the map-to-trace library, and vendor readers on written or bundled files."""

from __future__ import annotations

import re
import struct
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from stickslip.traces import TraceReadError, collect_traces, read_trace_csv, write_trace_csv
from stickslip.traces.formats import (
    Channel,
    ScanFile,
    assign_loads,
    friction_loop,
    group_by_load,
    map_to_traces,
    reader_options,
    summarise_by_load,
)
from stickslip.traces.formats.common import damage_reason
from stickslip.traces.readers import read_file, read_scan
from stickslip.traces.trace import read_notes

N = 64


def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def _ramp(n: int = N) -> np.ndarray:
    return np.linspace(0.0, 1.0, n)


# --- plain text -----------------------------------------------------------------------


def test_csv_nN_roundtrip(tmp_path):
    p = tmp_path / "a.csv"
    write_trace_csv(p, np.arange(N) * 0.1, np.sin(np.arange(N)))
    t = read_trace_csv(p)
    assert t.name == "a" and t.meta["unit"] == "nN" and t.n == N
    np.testing.assert_allclose(t.force_nN, np.sin(np.arange(N)), rtol=1e-8)


def test_empty_path_is_an_error_not_the_current_folder(tmp_path, monkeypatch):
    good = tmp_path / "a.csv"
    write_trace_csv(good, np.arange(64) * 0.02, np.sin(np.arange(64.0)))
    monkeypatch.chdir(tmp_path)  # "" must not read a.csv a second time from here
    traces, errors = collect_traces([good, ""])
    assert len(traces) == 1
    assert [str(e) for e in errors] == ["'': empty path"]


def test_csv_without_columns_names_the_needed_ones(tmp_path):
    p = _write(tmp_path / "b.csv", "a,b\n" + "\n".join(f"{i},{i}" for i in range(N)))
    with pytest.raises(TraceReadError, match="x_nm,force_nN"):
        read_trace_csv(p)


def test_force_in_volts_with_and_without_calibration(tmp_path):
    rows = "\n".join(f"{i * 0.1},{0.5 + 0.01 * i}" for i in range(N))
    p = _write(tmp_path / "v.csv", "x_nm,force_V\n" + rows)
    (t,), _ = collect_traces([p])
    assert t.meta["unit"] == "V" and t.meta["calibrated"] is False
    assert t.force_nN[1] == pytest.approx(0.51)
    (c,), _ = collect_traces([p], **reader_options(calibration_nN_per_V=20.0))
    assert c.meta["unit"] == "nN" and c.force_nN[1] == pytest.approx(10.2)


@pytest.mark.parametrize(("x_col", "x_to_nm", "f_col", "f_to_nN"), [
    ("x_um", 1e3, "force_N", 1e9), ("x_A", 0.1, "force_pN", 1e-3),
    ("x_m", 1e9, "force_uN", 1e3), ("x_pm", 1e-3, "force_nN", 1.0),
])  # fmt: skip
def test_columns_in_other_units_are_converted_to_nm_and_nN(tmp_path, x_col, x_to_nm, f_col,
                                                           f_to_nN):  # fmt: skip
    x, f = np.arange(N) * 0.5, 1.0 + np.sin(np.arange(N))
    body = "\n".join(f"{a!r},{b!r}" for a, b in zip(x.tolist(), f.tolist(), strict=True))
    (t,), errors = collect_traces([_write(tmp_path / "u.csv", f"{x_col},{f_col}\n{body}")])
    assert not errors and t.meta["unit"] == "nN" and t.meta["calibrated"] is True
    np.testing.assert_allclose(t.x_nm, x * x_to_nm, rtol=1e-12)
    np.testing.assert_allclose(t.force_nN, f * f_to_nN, rtol=1e-12)


def test_an_unknown_unit_names_the_units_read(tmp_path):
    body = "\n".join(f"{i},{i}" for i in range(N))
    _, (e,) = collect_traces([_write(tmp_path / "u.csv", f"x_inch,force_lbf\n{body}")])
    assert "x_inch,force_lbf" in str(e) and "um" in str(e) and "pN" in str(e)


def test_trace_retrace_columns_tab_separated(tmp_path):
    x = np.arange(N) * 0.5
    tr, rt = 1.0 + 0.1 * np.sin(x), -1.0 + 0.1 * np.cos(x)
    body = "\n".join(f"{a}\t{b}\t{c}" for a, b, c in zip(x, tr, rt, strict=True))
    p = _write(tmp_path / "loop.txt", "x_nm\ttrace_nN\tretrace_nN\n" + body)
    traces, errors = collect_traces([p])
    assert not errors and len(traces) == 2
    t, r = traces
    assert t.meta["unit"] == "nN" and t.meta["scan_size_nm"] == pytest.approx(N * 0.5)
    np.testing.assert_allclose(r.force_nN, -rt[::-1])
    assert t.meta["loop_friction"] == pytest.approx(((tr - rt) / 2).mean())


@pytest.mark.parametrize(
    ("text", "reason"),
    [
        ("", "empty file"),
        ("# only a comment\n", "empty file"),
        ("x_nm,force_nN,force_V\n1,2,3\n", "mixed units"),
        ("x_nm,trace_nN,retrace_V\n1,2,3\n", "mixed units"),
        ("x_nm,force_nN\n1,abc\n", "non-numeric"),
        ("x_nm,force_nN\n" + "\n".join(f"{i},1" for i in range(5)), "at least 16"),
        ("x_nm,force_nN\n" + "\n".join(f"{-i},1" for i in range(20)), "not strictly increasing"),
        ("1,2\n3,4\n", "3 columns"),
    ],
)
def test_bad_text_gives_one_line_reason(tmp_path, text, reason):
    p = _write(tmp_path / "bad.csv", text)
    traces, errors = collect_traces([p])
    assert not traces and len(errors) == 1
    assert reason in str(errors[0]) and "\n" not in str(errors[0])


@pytest.mark.parametrize("sep", [";", "\t"])
def test_european_csv_with_decimal_commas_reads_as_the_comma_csv(tmp_path, sep):
    """A European-locale spreadsheet export (``;`` or tab between the columns, decimal
    commas) gives the same trace as the plain CSV, and says how it was read."""
    x, f = np.arange(N) * 0.0215, 0.1234 + np.sin(np.arange(N) / 3.0)
    plain = _write(tmp_path / "plain.csv", "x_nm,force_nN\n" + "".join(
        f"{a:.4f},{b:.4f}\n" for a, b in zip(x, f, strict=True)))
    euro = _write(tmp_path / "euro.csv", f"x_nm{sep}force_nN\n" + "".join(
        f"{a:.4f}{sep}{b:.4f}\n".replace(".", ",") for a, b in zip(x, f, strict=True)))
    (p,), (e,) = read_file(plain), read_file(euro)
    np.testing.assert_array_equal(e.x_nm, p.x_nm)
    np.testing.assert_array_equal(e.force_nN, p.force_nN)
    assert e.force_nN[0] == pytest.approx(0.1234)
    name = {";": "semicolon", "\t": "tab"}[sep]
    assert e.meta["read_note"] == f"read as {name}-separated with decimal commas"
    assert "read_note" not in p.meta
    assert read_notes([p, e, e]) == [f"{euro}: read as {name}-separated with decimal commas"]


def test_semicolon_csv_with_decimal_points_and_comma_csv_are_unchanged(tmp_path):
    x = np.arange(N) * 0.5
    semi = _write(tmp_path / "semi.csv", "x_nm;force_nN\n" + "".join(
        f"{a};{a / 10}\n" for a in x))
    (t,) = read_file(semi)
    np.testing.assert_allclose(t.force_nN, x / 10) and "read_note" not in t.meta
    # a comma CSV whose cells hold no decimals is never read as decimal commas
    ints = _write(tmp_path / "ints.csv", "x_nm,force_nN\n" + "".join(
        f"{i},{i % 7}\n" for i in range(N)))
    (t,) = read_file(ints)
    assert t.x_nm[-1] == N - 1 and "read_note" not in t.meta


def test_european_csv_note_reaches_the_run(tmp_path):
    from stickslip.estimators.classical.estimator import ClassicalEstimator

    x = np.arange(N) * 0.0215
    euro = _write(tmp_path / "euro.csv", "x_nm;force_nN\n" + "".join(
        f"{a:.4f};{b:.4f}\n".replace(".", ",") for a, b in zip(x, np.sin(x * 9), strict=True)))
    table = ClassicalEstimator().predict(read_file(euro))
    assert f"{euro}: read as semicolon-separated with decimal commas" in table.notes
    assert "read_note" not in table.columns


@pytest.mark.parametrize(("suffix", "body", "words"), [
    (".nid", b"[DataSet]\nVersion=2\n\xff\xfe garbage",
     "a part every Nanosurf NID file has is missing (no 'DataSet')"),
    (".gwy", b"GWYP" + b"GwyContainer\x00" + b"\xff" * 64,
     "the file's body is damaged or not text where a text header was expected"),
    (".ibw", b"\x05\x00" + b"\x00" * 40, "the file ends early or its Asylum/Igor IBW data"),
])
def test_damaged_vendor_file_is_one_sentence(tmp_path, suffix, body, words):
    """A vendor file whose body is damaged: what is wrong and what to try, the file
    named, never a bare exception name."""
    p = tmp_path / f"damaged{suffix}"
    p.write_bytes(body)
    with pytest.raises(TraceReadError) as e:
        read_file(p)
    msg = str(e.value)
    assert msg.startswith(f"{p}: ") and "\n" not in msg and words in msg
    assert "re-export it from the instrument software" in msg
    assert not re.search(r"\w+(Error|Exception)\b", msg), msg


@pytest.mark.parametrize(("error", "words"), [
    (UnicodeDecodeError("utf-8", b"\xff", 0, 1, "invalid start byte"),
     "the file's body is damaged or not text where a text header was expected"),
    (KeyError("DataSet"), "a part every Nanosurf NID file has is missing (no 'DataSet')"),
    (struct.error("unpack requires a buffer of 4 bytes"), "the file ends early"),
    (MemoryError(), "the Nanosurf NID header states sizes no real file has"),
    (RuntimeError("odd"), "not a readable Nanosurf NID file"),
])
def test_damage_reasons_are_sentences(tmp_path, error, words):
    reason = damage_reason(error, tmp_path / "scan.nid")
    assert reason.startswith(words) and "instrument software" in reason
    assert type(error).__name__ not in reason


def test_npy_layouts(tmp_path):
    np.save(tmp_path / "two.npy", np.column_stack([np.arange(N) * 0.2, _ramp()]))
    np.save(tmp_path / "one.npy", _ramp())
    rec = np.zeros(N, dtype=[("trace", float), ("retrace", float)])
    rec["trace"], rec["retrace"] = 2.0, 1.0
    np.save(tmp_path / "rec.npy", rec)
    np.save(tmp_path / "bad.npy", np.zeros((3, 4, 5)))
    traces, errors = collect_traces([tmp_path], **reader_options(scan_size_nm=11.0))
    names = sorted(t.name for t in traces)
    assert names == ["one", "rec:Friction:retrace:L000", "rec:Friction:trace:L000", "two"]
    one = next(t for t in traces if t.name == "one")
    assert one.x_nm[1] == pytest.approx(11.0 / N)
    assert len(errors) == 1 and "shape (3, 4, 5)" in str(errors[0])


def test_npy_with_a_python2_style_header_gives_no_warning(tmp_path, recwarn):
    # numpy warns (and advises saving again) before it parses such a header; a user
    # gets the file read or one clean error, never that warning
    np.save(tmp_path / "a.npy", _ramp())
    raw = (tmp_path / "a.npy").read_bytes()
    (tmp_path / "b.npy").write_bytes(raw.replace(f"({N},)".encode(), f"({N}L)".encode()))
    with pytest.raises(TraceReadError, match="damaged .npy"):
        read_file(tmp_path / "b.npy")
    assert not [w for w in recwarn if issubclass(w.category, UserWarning)]


def test_project_hdf5(tmp_path):
    p = tmp_path / "set.h5"
    with h5py.File(p, "w") as f:
        f.attrs["lattice_nm"] = 0.246
        g = f.create_group("train")
        g["x_nm"] = np.arange(N) * 11 / N
        g["force_nN"] = np.vstack([_ramp(), 2 * _ramp(), 3 * _ramp()])
        g["U0_eV"] = np.array([0.5, 1.0, 1.5])
    traces, errors = collect_traces([p])
    assert not errors and len(traces) == 3
    assert traces[2].meta["U0_eV"] == 1.5 and traces[2].meta["lattice_nm"] == 0.246
    np.testing.assert_allclose(traces[1].force_nN, 2 * _ramp())
    sweep = tmp_path / "sweep.h5"  # the simulated-sweep layout (stickslip.traces.dataset)
    with h5py.File(sweep, "w") as f:
        f.attrs["format"], f.attrs["config"] = "stickslip-sweep-1", "{}"
        f["force_nN"] = np.vstack([_ramp(), 2 * _ramp()])
        f["x_nm"] = np.arange(N) * 11 / N
        f["support_nm"] = np.zeros((2, N))
        f["done"] = np.array([True, False])
        f["params/K_N_m"] = np.array([10.0, 20.0])
    (t,), errors = collect_traces([sweep])
    assert not errors and t.meta["K_N_m"] == 10.0 and "config" not in t.meta
    with h5py.File(tmp_path / "empty.h5", "w") as f:
        f["other"] = np.zeros(3)
    _, errors = collect_traces([tmp_path / "empty.h5"])
    assert "force_nN" in str(errors[0])


# --- maps library ---------------------------------------------------------------------


def _scan(unit: str = "V", meta: dict | None = None) -> ScanFile:
    rng = np.random.default_rng(0)
    t = 1.0 + 0.1 * rng.standard_normal((6, N))
    r = 0.6 + 0.1 * rng.standard_normal((6, N))
    return ScanFile(
        path=Path("m.gwy"), fmt="test", scan_size_nm=11.0, meta=dict(meta or {}),
        channels=[Channel("Height", "trace", "m", (6, N), None),
                  Channel("Lateral force", "trace", unit, (6, N), t),
                  Channel("Lateral force", "retrace", unit, (6, N), r)],
    )


def test_map_to_traces_directions_loop_and_names():
    scan = _scan()
    traces = map_to_traces(scan, directions=("trace", "retrace", "loop"))
    assert len(traces) == 6 * 3
    assert traces[0].name == "m:Lateral force:trace:L000"
    t, r = scan.channels[1].data, scan.channels[2].data
    loop = [x for x in traces if x.meta["direction"] == "loop"][2]
    np.testing.assert_allclose(loop.force_nN, (t[2] - r[2]) / 2)
    f, o = friction_loop(t, r)
    np.testing.assert_allclose(f, (t - r).mean(axis=1) / 2)
    np.testing.assert_allclose(o, (t + r).mean(axis=1) / 2)
    assert loop.meta["loop_friction"] == pytest.approx(f[2])
    np.testing.assert_allclose(traces[0].x_nm[1], 11.0 / N)


def test_user_calibration_wins_over_the_stored_one_and_newton_channels_convert():
    traces = map_to_traces(_scan(meta={"calibration_nN_per_V": 3.0}), calibration_nN_per_V=7.0)
    assert traces[0].force_nN[0] == pytest.approx(7.0 * _scan().channels[1].data[0, 0])
    assert traces[0].meta["calibration_source"] == "flag"
    stored = map_to_traces(_scan(meta={"calibration_nN_per_V": 3.0}))
    assert stored[0].force_nN[0] == pytest.approx(3.0 * _scan().channels[1].data[0, 0])
    n = map_to_traces(_scan(unit="N"))
    assert n[0].meta["unit"] == "nN" and n[0].force_nN[0] == pytest.approx(
        1e9 * _scan().channels[1].data[0, 0])
    with pytest.raises(TraceReadError, match="neither a force nor a voltage"):
        map_to_traces(_scan(unit="m"))


def test_no_lateral_channel_is_an_error():
    scan = _scan()
    scan.channels = scan.channels[:1]
    with pytest.raises(TraceReadError, match=r"no lateral-force channel \(found: Height"):
        map_to_traces(scan)


def test_assign_and_group_by_load():
    traces = assign_loads(map_to_traces(_scan()), 2, [10.0, 5.0, 1.0])
    groups = group_by_load(traces)
    assert [g[0] for g in groups] == [1.0, 5.0, 10.0]
    assert all(len(g[1]) == 4 for g in groups)
    rows = [{"load": 1.0, "f": 2.0}, {"load": 1.0, "f": 4.0}, {"load": None, "f": 9.0}]
    summary = summarise_by_load(rows, ["f"])
    assert summary[0]["f_mean"] == 3.0 and summary[0]["n"] == 2
    assert summary[-1]["load"] is None


@pytest.mark.parametrize(
    "kwargs",
    [{"calibration_nN_per_V": -1.0}, {"lines_per_load": 0}, {"loads": [1.0]},
     {"scan_size_nm": 0.0}, {"directions": ["sideways"]}],
)
def test_reader_options_rejects_bad_values(kwargs):
    with pytest.raises(ValueError):
        reader_options(**kwargs)


def test_reader_options_keeps_given_values_only():
    assert reader_options() == {}
    assert reader_options(2.0, 10, [1.0, 2.0]) == {
        "calibration_nN_per_V": 2.0, "lines_per_load": 10, "loads": [1.0, 2.0], "load_unit": "nN"
    }


# --- vendor formats without real files here -------------------------------------------


def test_gwyddion_written_with_gwyfile(tmp_path):
    objects = pytest.importorskip("gwyfile.objects")
    c = objects.GwyContainer()
    rng = np.random.default_rng(1)
    imgs = {"Friction Forward": 0.3 + rng.random((4, N)), "Friction Backward": rng.random((4, N)),
            "Height": rng.random((4, N))}
    for i, (title, img) in enumerate(imgs.items()):
        c[f"/{i}/data"] = objects.GwyDataField(
            img, xreal=11e-9, yreal=11e-9, si_unit_xy=objects.GwySIUnit(unitstr="m"),
            si_unit_z=objects.GwySIUnit(unitstr="V"))
        c[f"/{i}/data/title"] = title
    p = tmp_path / "map.gwy"
    c.tofile(str(p))
    scan = read_scan(p)
    assert {(ch.name, ch.direction) for ch in scan.lateral()} == {
        ("Friction Forward", "trace"), ("Friction Backward", "retrace")}
    assert scan.scan_size_nm == pytest.approx(11.0)
    traces = read_file(p, **reader_options(calibration_nN_per_V=5.0))
    assert len(traces) == 8 and traces[0].meta["unit"] == "nN"
    retr = next(t for t in traces if t.meta["direction"] == "retrace" and t.meta["line"] == 1)
    np.testing.assert_allclose(retr.force_nN, -5.0 * imgs["Friction Backward"][1][::-1])
    # a Gwyddion file without lateral channels
    d = objects.GwyContainer()
    d["/0/data"] = objects.GwyDataField(rng.random((4, N)))
    d["/0/data/title"] = "Height"
    d.tofile(str(tmp_path / "height.gwy"))
    with pytest.raises(TraceReadError, match="no lateral-force channel"):
        read_file(tmp_path / "height.gwy")


def _nid_example() -> Path:
    try:
        import NSFopen
    except ImportError:
        pytest.skip("NSFopen (formats extra) not installed")
    p = Path(NSFopen.__file__).parent / "example" / "Lateral_Force" / "SBS-PMMA.nid"
    if not p.is_file():
        pytest.skip("NSFopen's bundled lateral-force example is not installed")
    return p


def test_nanosurf_real_example_file():
    scan = read_scan(_nid_example())
    lat = {c.direction: c for c in scan.lateral()}
    assert set(lat) == {"trace", "retrace"}
    assert lat["trace"].name == "Friction force" and lat["trace"].unit == "V"
    assert lat["trace"].data.shape == (256, 256)
    assert round(float(lat["trace"].data.mean()), 4) == 0.7323
    assert round(float(lat["retrace"].data.mean()), 4) == 0.8534
    assert scan.scan_size_nm == pytest.approx(25000.0)
    assert scan.meta["velocity_nm_per_s"] == pytest.approx(50000.0)
    assert scan.meta["load"] == pytest.approx(20.0) and scan.meta["load_unit"] == "nN"
    traces = read_file(_nid_example())
    assert len(traces) == 512 and traces[0].meta["unit"] == "V"


def test_missing_extra_names_it(tmp_path, monkeypatch):
    p = tmp_path / "x.gwy"
    p.write_bytes(b"GWYP" + b"\0" * 32)
    monkeypatch.setitem(sys.modules, "gwyfile", None)  # makes `import gwyfile` fail
    with pytest.raises(TraceReadError, match=r"\.gwy files needs the optional extra: pip install "
                       r"'stickslip\[formats\]'"):
        read_file(p)


@pytest.mark.parametrize("suffix", [".ibw", ".nid", ".gwy", ".spm", ".000", ".npy", ".h5"])
def test_garbage_under_known_suffix_is_a_clean_error(tmp_path, suffix):
    p = tmp_path / f"junk{suffix}"
    p.write_bytes(b"\x05\x00" + bytes(range(256)) * 4)
    with pytest.raises(TraceReadError) as e:
        read_file(p)
    assert "\n" not in str(e.value) and str(p) in str(e.value)


def test_a_csv_against_time_reads_with_the_speed(tmp_path):
    p = _write(tmp_path / "timed.csv", "time_ms,force_nN\n" + "".join(
        f"{10 + 0.5 * i},{np.sin(i / 5):.6f}\n" for i in range(N)))  # fmt: skip
    with pytest.raises(TraceReadError, match="time axis"):
        read_file(p)
    (t,) = read_file(p, **reader_options(velocity_nm_per_s=20.0))
    assert np.allclose(t.x_nm, np.arange(N) * 0.5e-3 * 20.0)
    assert t.meta["velocity_nm_per_s"] == 20.0
    with pytest.raises(ValueError, match="velocity"):
        reader_options(velocity_nm_per_s=-1.0)
