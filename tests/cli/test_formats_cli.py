"""``stickslip inspect`` and ``stickslip friction-load`` on real and bad files."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest
from typer.testing import CliRunner

from stickslip.cli.main import app

RAMP = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "bruker-friction-ramp"
RAMP_FILES = ["si.0_00144.spm", "si.0_00150.spm", "si.0_00160.spm", "si.0_00170.spm",
              "si.0_00175.spm"]


@pytest.fixture
def ramp() -> Path:
    if not RAMP.is_dir():
        pytest.skip(f"real data folder missing: {RAMP} (clone shared/ beside the project)")
    return RAMP


def _run(args: list[str]):
    return CliRunner().invoke(app, [str(a) for a in args])


def _error_lines(result) -> list[str]:
    return [ln for ln in result.stderr.splitlines() if ln.startswith("stickslip: error:")]


def test_inspect_real_map_and_bad_files(ramp, tmp_path):
    empty = tmp_path / "empty.csv"
    empty.write_text("")
    junk = tmp_path / "junk.spm"
    junk.write_bytes(b"\x00garbage" * 100)
    r = _run(["inspect", ramp / "si.0_00150.spm", ramp / "si.0_00143.spm", empty, junk,
              ramp / "exampleFrictionProfileFull.txt"])
    assert r.exit_code == 1
    out = r.stdout
    assert "format: Bruker NanoScope" in out
    assert "scan size: 2000 nm, 32 lines x 32 pixels (pixel 62.5 nm)" in out
    assert "scan rate: 2.00115 Hz, velocity: 8004.6 nm/s" in out
    assert "setpoint/load: -0.8 V" in out
    assert "Friction             trace    V    32x32  lateral" in out
    assert "Friction             retrace  V    32x32  lateral" in out
    assert "traces: 64 (retrace, trace), unit V" in out
    assert "first: si.0_00150:Friction:trace:L000" in out
    assert "exampleFrictionProfileFull:Friction:retrace:L000" in out  # later files still read
    errors = _error_lines(r)
    assert len(errors) == 3
    assert any("si.0_00143.spm: no lateral-force channel" in e for e in errors)
    assert any("empty.csv: empty file" in e for e in errors)
    assert any("junk.spm: not a Bruker NanoScope file" in e for e in errors)


def test_inspect_with_calibration_and_load_groups(ramp):
    r = _run(["inspect", ramp / "si.0_00150.spm", "--calibration", "10", "--lines-per-load",
              "16", "--loads", "20,10"])
    assert r.exit_code == 0, r.stderr
    assert "unit nN" in r.stdout and "not calibrated" not in r.stdout
    assert "load groups: 2; loads: 10, 20" in r.stdout


def test_inspect_usage_errors(ramp):
    r = _run(["inspect", ramp / "si.0_00150.spm", "--loads", "1,x", "--lines-per-load", "4"])
    assert r.exit_code == 2 and "bad load 'x'" in r.stderr
    r = _run(["inspect", ramp / "si.0_00150.spm", "--calibration", "-3"])
    assert r.exit_code == 2 and "calibration" in r.stderr


def test_friction_load_ramp(ramp, tmp_path):
    out, table = tmp_path / "fl" / "friction.png", tmp_path / "fl" / "friction.csv"
    out.parent.mkdir()
    files = [ramp / f for f in RAMP_FILES]
    r = _run(["friction-load", *files, "--out", out, "--csv", table])
    assert r.exit_code == 0, r.stderr
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    rows = list(csv.DictReader(table.open()))
    assert [float(x["load"]) for x in rows] == pytest.approx([-1.4, -0.8, 0.2, 1.2, 1.7])
    assert {x["load_unit"] for x in rows} == {"V"} and {x["n_lines"] for x in rows} == {"32"}
    friction = [float(x["friction_V"]) for x in rows]
    assert all(b > a for a, b in zip(friction, friction[1:], strict=False))
    assert friction[1] == pytest.approx(0.02557, abs=1e-4)
    assert not list(tmp_path.joinpath("fl").glob(".*"))  # no temporary files left


def test_friction_load_reports_bad_files_and_continues(ramp, tmp_path):
    out = tmp_path / "f.png"
    r = _run(["friction-load", ramp / "si.0_00144.spm", ramp / "si.0_00143.spm",
              ramp / "si.0_00175.spm", "--out", out])
    assert r.exit_code == 1
    assert len(_error_lines(r)) == 1 and "si.0_00143.spm" in r.stderr
    assert out.is_file() and len(r.stdout.strip().splitlines()) == 3  # header + 2 loads


def test_friction_load_loop_file_needs_loads(ramp, tmp_path):
    loop = ramp / "exampleFrictionProfileFull.txt"
    r = _run(["friction-load", loop, "--out", tmp_path / "a.png"])
    assert r.exit_code == 1 and "pass --loads" in r.stderr
    r = _run(["friction-load", loop, "--out", tmp_path / "a.png", "--loads", "5,6"])
    assert r.exit_code == 2 and "2 values for 1 files" in r.stderr
    r = _run(["friction-load", loop, "--out", tmp_path / "a.png", "--loads", "5"])
    assert r.exit_code == 0 and (tmp_path / "a.png").is_file()
    assert "5,nN,1,0.0321" in r.stdout


def test_friction_load_refuses_mixed_units(ramp, tmp_path):
    r = _run(["friction-load", ramp / "si.0_00144.spm", ramp / "exampleFrictionProfileFull.txt",
              "--out", tmp_path / "m.png", "--loads", "1,2"])
    # the .spm's loads come from --loads too: both in nN, friction both in V -> fine
    assert r.exit_code == 0, r.stderr
    cal = tmp_path / "cal.csv"
    cal.write_text("x_nm,trace_nN,retrace_nN\n" + "\n".join(f"{i},1,-1" for i in range(32)))
    r = _run(["friction-load", ramp / "si.0_00144.spm", cal, "--out", tmp_path / "m2.png",
              "--loads", "1,2"])
    assert r.exit_code == 1 and "mixed units" in r.stderr
    assert not (tmp_path / "m2.png").exists()


@pytest.mark.parametrize("name", ["table.csv", "plot", "folder.png"])
def test_friction_load_refuses_an_output_it_cannot_write_before_reading(ramp, tmp_path, name):
    out = tmp_path / name
    if name == "folder.png":
        out.mkdir()
    r = _run(["friction-load", ramp / "si.0_00144.spm", "--out", out])
    assert r.exit_code == 2
    (line,) = _error_lines(r)
    assert "--out" in line and str(out) in line
    assert r.exception is None or isinstance(r.exception, SystemExit)
    assert r.stdout == "" and sorted(p.name for p in tmp_path.iterdir()) == (
        ["folder.png"] if name == "folder.png" else [])
