"""`stickslip label`: labels CSV, bad input, usage errors."""

from __future__ import annotations

import csv

import numpy as np
import pytest
from typer.testing import CliRunner

from stickslip.cli.main import app
from stickslip.estimators.table import HEAD, STD_COLUMNS, TARGETS
from stickslip.simulators.config import PhysicalSettings
from stickslip.simulators.simulate import simulate
from stickslip.traces.trace import write_trace_csv

runner = CliRunner()


@pytest.fixture(scope="module")
def good_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("traces")
    r = simulate([2.0, 3.0], [20.0, 10.0], PhysicalSettings(), seed=4)
    for i in range(2):
        write_trace_csv(d / f"good{i}.csv", r.x_nm, r.force_nN[i])
    return d


def _rows(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_labels_csv(good_dir, tmp_path):
    out = tmp_path / "labels.csv"
    r = runner.invoke(app, ["label", str(good_dir), "--out", str(out), "--plots",
                            str(tmp_path / "plots")])  # fmt: skip
    assert r.exit_code == 0, r.output
    header = out.read_text().splitlines()[0].split(",")
    # the one table layout: head, estimates, their spread, then the conditions
    assert header[:11] == [*HEAD, *TARGETS, *STD_COLUMNS]
    assert "lattice_source" in header and "k_exp_N_m" in header and "regime" in header
    rows = {row["trace"]: row for row in _rows(out)}
    assert set(rows) == {"good0", "good1"}
    assert rows["good0"]["quality"] == "ok" and rows["good0"]["regime"] == "single slip"
    assert float(rows["good0"]["U0_eV"]) == pytest.approx(2.0, rel=0.08)
    assert float(rows["good1"]["K_N_m"]) == pytest.approx(10.0, rel=0.08)
    assert len(list((tmp_path / "plots").glob("*_good0.png"))) == 1


BAD = {
    "wrongcols": ("a,b\n1,2\n", "needs columns"),
    "nonnumeric": ("x_nm,force_nN\n" + "".join(f"{i},1\n" for i in range(20)) + "5,abc\n",
                   "non-numeric"),
    "nans": ("x_nm,force_nN\n" + "".join(f"{i},{'nan' if i == 3 else 1}\n" for i in range(20)),
             "NaN"),
    "short": ("x_nm,force_nN\n" + "".join(f"{i},1\n" for i in range(10)), "samples"),
    "nonmono": ("x_nm,force_nN\n" + "".join(f"{(i * 7) % 20},1\n" for i in range(20)),
                "increasing"),
}  # fmt: skip


def test_bad_inputs_are_reported_and_the_rest_labelled(good_dir, tmp_path):
    bad = tmp_path / "bad"
    bad.mkdir()
    for name, (text, _) in BAD.items():
        (bad / f"{name}.csv").write_text(text)
    out = tmp_path / "labels.csv"
    missing = tmp_path / "missing.csv"
    r = runner.invoke(app, ["label", str(good_dir), str(bad), str(missing), "--out", str(out)])
    assert r.exit_code == 1, r.output
    assert "Traceback" not in r.output
    err_lines = [ln for ln in r.output.splitlines() if "error:" in ln]
    assert len(err_lines) == len(BAD) + 1
    rows = {row["trace"]: row for row in _rows(out)}
    for name, (_, reason) in BAD.items():
        assert sum(name in ln for ln in err_lines) == 1
        assert reason.lower() in rows[name]["quality"].lower()
        assert rows[name]["U0_eV"] == ""
    assert rows["missing"]["quality"] == "file not found"
    assert rows["good0"]["quality"] == rows["good1"]["quality"] == "ok"


@pytest.mark.parametrize(
    "args",
    [
        ["label", "x.csv"],  # no --out
        ["label", "x.csv", "--out", "o.csv", "--lattice", "0"],
        ["label", "x.csv", "--out", "o.csv", "--lattice", "246"],  # pm, not nm
        ["label", "x.csv", "--out", "o.csv", "--temperature", "-1"],
        ["label", "x.csv", "--out", "o.csv", "--velocity", "abc"],
    ],
)
def test_usage_errors_exit_2(args, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    r = runner.invoke(app, args)
    assert r.exit_code == 2, r.output
    assert "Traceback" not in r.output
    assert not (tmp_path / "o.csv").exists()


def test_smooth_trace_is_flagged_not_failed(tmp_path):
    r = simulate([0.3], [40.0], PhysicalSettings(), seed=0)
    write_trace_csv(tmp_path / "smooth.csv", r.x_nm, r.force_nN[0])
    out = tmp_path / "labels.csv"
    res = runner.invoke(app, ["label", str(tmp_path / "smooth.csv"), "--out", str(out)])
    assert res.exit_code == 0, res.output
    row = _rows(out)[0]
    assert row["regime"] == "smooth" and row["quality"] == "smooth sliding"
    assert not np.isnan(float(row["F_mean_nN"]))


def test_nonsense_trace_is_refused_with_its_reason_and_no_warning(good_dir, tmp_path):
    """Forces of 1e30 nN: one error line saying why, no number written, no warning."""
    r = simulate([2.0], [20.0], PhysicalSettings(), seed=4)
    write_trace_csv(tmp_path / "huge.csv", r.x_nm, r.force_nN[0] * 1e30)
    out = tmp_path / "labels.csv"
    res = runner.invoke(app, ["label", str(tmp_path / "huge.csv"), str(good_dir / "good0.csv"),
                              "--out", str(out)])  # fmt: skip
    assert res.exit_code == 1, res.output
    assert "Warning" not in res.output and "overflow" not in res.output
    err = [ln for ln in res.stderr.splitlines() if "error:" in ln]
    assert len(err) == 1 and "huge: force outside any physical range" in err[0]
    rows = {row["trace"]: row for row in _rows(out)}
    assert rows["huge"]["U0_eV"] == "" and rows["good0"]["quality"] == "ok"


@pytest.mark.parametrize(("flag", "shown"), [([], False), (["-v"], True)])
def test_warnings_become_status_lines_under_verbose(tmp_path, monkeypatch, flag, shown):
    """A library warning raised during a command reaches the terminal only with -v, once."""
    import warnings

    import stickslip.jobs.infer as inf

    real = inf.read_inputs

    def noisy(*args, **kwargs):
        for _ in range(3):
            warnings.warn("overflow encountered in exp", RuntimeWarning, stacklevel=1)
        return real(*args, **kwargs)

    monkeypatch.setattr(inf, "read_inputs", noisy)
    (tmp_path / "a.csv").write_text("x_nm,force_nN\n")
    res = runner.invoke(app, [*flag, "label", str(tmp_path / "a.csv"), "--out",
                              str(tmp_path / "o.csv")])  # fmt: skip
    lines = [ln for ln in res.stderr.splitlines() if "overflow" in ln]
    assert len(lines) == (1 if shown else 0)  # once, not three times
    if shown:
        assert lines[0].startswith("warning: RuntimeWarning: overflow encountered in exp (")
    assert "Traceback" not in res.output


def test_a_matlab_recording_against_time_is_labelled_with_its_speed(tmp_path):
    """A .mat file of a time axis and a force: --velocity turns t into x = v t (the
    line's own speed), and without it the file is refused with that advice."""
    from scipy.io import savemat

    s = PhysicalSettings()
    r = simulate([2.0], [20.0], s, seed=5)
    p = tmp_path / "line.mat"
    savemat(p, {"t_ms": r.x_nm / s.velocity_nm_per_s * 1e3, "force_nN": r.force_nN[0]})
    out = tmp_path / "labels.csv"
    r1 = runner.invoke(app, ["label", str(p), "--out", str(out)])
    assert r1.exit_code == 1 and "--velocity" in r1.output
    r2 = runner.invoke(app, ["label", str(p), "--velocity", str(s.velocity_nm_per_s),
                             "--out", str(out)])  # fmt: skip
    assert r2.exit_code == 0, r2.output
    (row,) = _rows(out)
    assert row["quality"] == "ok" and float(row["U0_eV"]) == pytest.approx(2.0, rel=0.08)
    assert float(row["K_N_m"]) == pytest.approx(20.0, rel=0.08)
