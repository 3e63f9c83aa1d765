"""`stickslip simulate`: single traces, sweeps and bad parameters."""

import numpy as np
import pytest
from typer.testing import CliRunner

from stickslip.cli.main import app
from stickslip.traces import read_trace_csv
from stickslip.traces.dataset import load_dataset

runner = CliRunner()
FAST = ["--velocity", "600", "--length", "1", "--pixels", "32"]


def test_single_trace_csv(tmp_path):
    out = tmp_path / "t.csv"
    r = runner.invoke(app, ["simulate", "--u0", "1.0", "--k", "10", *FAST, "--out", str(out)])
    assert r.exit_code == 0, r.output
    assert out.read_text().splitlines()[0] == "x_nm,force_nN"
    tr = read_trace_csv(out)
    assert tr.n == 32 and tr.x_nm[0] == 0.0
    assert np.isclose(tr.x_nm[1], 1 / 32)
    assert 0.3 < tr.force_nN.max() < 2.1  # below F_max = 2.05 nN at 296 K


def test_fine_diagnostics(tmp_path):
    out = tmp_path / "t.csv"
    r = runner.invoke(app, ["simulate", "--u0", "1", "--k", "10", *FAST, "--fine", "4",
                            "--out", str(out)])  # fmt: skip
    assert r.exit_code == 0, r.output
    fine = np.loadtxt(tmp_path / "t.fine.csv", delimiter=",", skiprows=1)
    assert fine.shape == (128, 3)


def test_sweep_with_overrides(tmp_path):
    out = tmp_path / "s.h5"
    r = runner.invoke(app, ["simulate", "--n", "12", "--seed", "3", *FAST, "--temperature", "100",
                            "--u0-range", "1,2", "--k-range", "5,10", "--no-progress",
                            "--out", str(out)])  # fmt: skip
    assert r.exit_code == 0, r.output
    ds = load_dataset(out)
    assert ds.force_nN.shape == (12, 32)
    assert np.all(ds.params["temperature_K"] == 100)
    assert ds.params["U0_eV"].min() >= 1 and ds.params["K_N_m"].max() <= 10


@pytest.mark.parametrize(
    "args, message",
    [
        (["--u0", "1", "--k", "0"], "K must be > 0"),
        (["--u0", "1", "--k", "5", "--temperature", "-3"], "temperature must be >= 0"),
        (["--u0", "1", "--k", "5", "--pixels", "4"], "pixels must be >= 8"),
        (["--u0-range", "0.3,0.4", "--k-range", "40,50", "--eta-range", "30,40"], "no eta"),
        (["--u0", "1"], "both --u0 and --k"),
    ],
)
def test_bad_parameters_one_line_exit_2(tmp_path, args, message):
    out = tmp_path / "x.csv"
    r = runner.invoke(app, ["simulate", *args, "--out", str(out)])
    assert r.exit_code == 2
    err = r.stderr.strip().splitlines()
    assert len(err) == 1 and message in err[0]
    assert "Traceback" not in r.output
    assert not out.exists()
