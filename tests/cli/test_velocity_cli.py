"""``stickslip friction-velocity`` on simulated velocity series, good and bad inputs."""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Sequence
from pathlib import Path

import h5py
import numpy as np
import pytest
from typer.testing import CliRunner

from stickslip.cli.main import app
from stickslip.simulators import PhysicalSettings, simulate
from stickslip.traces.trace import write_trace_csv
from stickslip.units import fmax_nN

U0, K = 1.0, 3.0  # eta = 17: thermally activated up to about 1e4 nm/s at 296 K
F_MAX = float(fmax_nN(U0, 0.246))


def _series(folder: Path, velocities: Sequence[float], lines: int, seed: int = 11) -> list[Path]:
    """One HDF5 file per velocity (stating it), 2 nm lines of 96 pixels."""
    folder.mkdir(parents=True, exist_ok=True)
    out = []
    for i, v in enumerate(velocities):
        r = simulate(np.full(lines, U0), np.full(lines, K),
                     PhysicalSettings(velocity_nm_per_s=v, length_nm=2.0, pixels=96),
                     seed=seed + i)  # fmt: skip
        path = folder / f"series_v{v:g}.h5"
        with h5py.File(path, "w") as fh:
            fh["force_nN"] = r.force_nN
            fh["x_nm"] = r.x_nm
            fh["params/velocity_nm_per_s"] = np.full(lines, float(v))
        out.append(path)
        if i == 0:  # one plain CSV line: it does not state its velocity
            write_trace_csv(folder / "line.csv", r.x_nm, r.force_nN[0])
    return out


def _run(args: list) -> object:
    return CliRunner().invoke(app, [str(a) for a in args])


def _errors(result) -> list[str]:
    return [ln for ln in result.stderr.splitlines() if ln.startswith("stickslip: error:")]


def _rows(path: Path) -> list[dict[str, str]]:
    return list(csv.DictReader(path.open()))


def test_friction_velocity_end_to_end_with_bad_inputs(tmp_path):
    files = _series(tmp_path / "s", [1000, 2000, 4000, 8000], lines=8)
    junk = tmp_path / "junk.csv"
    junk.write_text("not,a,trace\n")
    out, plot = tmp_path / "res" / "fv.csv", tmp_path / "res" / "fv.png"
    out.parent.mkdir()
    r = _run(["friction-velocity", *files, tmp_path / "s" / "line.csv", junk, "--out", out,
              "--plot", plot, "--check-lines", "8"])  # fmt: skip
    assert r.exit_code == 1, r.output
    errors = _errors(r)
    assert len(errors) == 2
    assert any("line.csv: velocity unknown" in e and "--velocities" in e for e in errors)
    assert any("junk.csv" in e for e in errors)
    # good inputs still processed: every output written, no temporary file left
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    rows = _rows(out)
    assert len(rows) == 34 and sum(x["quality"] == "ok" for x in rows) >= 30
    assert {x["velocity_source"] for x in rows if x["quality"] == "ok"} == {"file"}
    by_v = _rows(out.with_name("fv.by_velocity.csv"))
    assert [float(x["velocity_nm_per_s"]) for x in by_v] == [1000, 2000, 4000, 8000]
    peaks = [float(x["F_peak_nN"]) for x in by_v]
    assert all(b > a for a, b in zip(peaks, peaks[1:], strict=False))  # rises with v
    assert all(abs(float(x["z_sim"])) < 4 for x in by_v)  # the simulator reproduces it
    fits = {(x["quantity"], x["parameter"]): x for x in _rows(out.with_name("fv.velocity_fit.csv"))}
    fc = fits[("F_peak_nN", "F_c")]
    assert float(fc["lo68"]) < float(fc["value"]) and 1.5 < float(fc["value"]) < 2.5
    assert ("F_mean_nN", "F_c") in fits and ("simulator check", "RMS z") in fits
    assert "athermal check" in r.stdout and "simulator check" in r.stdout
    assert not [p for p in out.parent.iterdir() if p.name.startswith(".")]


def test_friction_velocity_given_velocities_fill_in_and_file_values_win(tmp_path):
    _series(tmp_path / "s", [1000, 2000, 4000, 8000], lines=8, seed=21)
    out = tmp_path / "fv.json"
    r = _run(["friction-velocity", tmp_path / "s", "--velocities", "1000", "--out", out,
              "--plot", tmp_path / "fv.svg", "--no-check"])  # fmt: skip
    assert r.exit_code == 0, r.output
    rows = json.loads(out.read_text())
    csv_row = next(x for x in rows if x["trace"] == "line")
    assert csv_row["velocity_source"] == "flag" and csv_row["velocity_nm_per_s"] == 1000
    assert {x["velocity_nm_per_s"] for x in rows} == {1000, 2000, 4000, 8000}
    # the files that state another velocity keep it, with one note each
    assert r.stderr.count("is not used") == 3
    assert "simulator check" not in r.stdout
    assert (tmp_path / "fv.velocity_fit.json").is_file()


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--velocities", "30,x"], "bad velocity 'x'"),
        (["--velocities", "30,-1"], "must be > 0"),
        (["--velocities", "1,2"], "2 values for 1 files"),
        (["--temperature", "0"], "--temperature must be > 0"),
        (["--out", "t.txt"], "unknown table format"),
        (["--plot", "t.jpg"], "--plot t.jpg"),
    ],
)
def test_friction_velocity_usage_errors(tmp_path, extra, message):
    trace = tmp_path / "a.csv"
    write_trace_csv(trace, np.linspace(0, 2, 64), np.sin(np.linspace(0, 20, 64)))
    args = ["friction-velocity", trace, "--out", tmp_path / "t.csv", "--plot",
            tmp_path / "t.png", "--no-check", *extra]  # fmt: skip
    r = _run(args)
    assert r.exit_code == 2, r.output
    assert len(_errors(r)) == 1 and message in r.stderr


@pytest.mark.slow
def test_two_decades_recover_the_athermal_peak_and_pass_the_simulator_check(tmp_path):
    """100 to 1e4 nm/s, 32 lines each: F_c agrees with pi U0/a within its interval."""
    files = _series(tmp_path / "s", [100, 316.2, 1000, 3162, 10000], lines=32, seed=31)
    out = tmp_path / "fv.csv"
    r = _run(["friction-velocity", *files, "--out", out, "--plot", tmp_path / "fv.png"])
    assert r.exit_code == 0, r.output
    print(r.stdout)  # the figures quoted in the README (pytest -s)
    fits = {(x["quantity"], x["parameter"]): x for x in _rows(out.with_name("fv.velocity_fit.csv"))}
    fc = fits[("F_peak_nN", "F_c")]
    hi = float(fc["hi68"]) if fc["hi68"] not in ("", "inf") else math.inf
    assert float(fc["lo68"]) <= F_MAX <= hi
    assert abs(float(fc["value"]) - F_MAX) <= 2 * float(fc["std"])
    assert float(fits[("simulator check", "RMS z")]["value"]) < 2.5
