"""Per-load reports of `label` on a real Bruker friction-versus-load ramp."""

import csv
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from stickslip.cli.main import app

RAMP = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "bruker-friction-ramp"
runner = CliRunner()


@pytest.mark.skipif(not RAMP.is_dir(), reason="shared/data (real files) not beside the project")
def test_label_reports_friction_per_load(tmp_path):
    files = [str(RAMP / f"si.0_00{n}.spm") for n in (144, 150, 160, 170, 175)]
    out = tmp_path / "labels.csv"
    r = runner.invoke(app, ["label", *files, "--calibration", "10", "--out", str(out)])
    assert r.exit_code == 0, r.output
    rows = list(csv.DictReader(out.with_name("labels.by_load.csv").open()))
    loads = [float(row["load"]) for row in rows]
    assert loads == [-1.4, -0.8, 0.2, 1.2, 1.7]
    assert all(row["n"] == "64" for row in rows)  # 32 lines x 2 directions per file
    # mean over trace and retrace = half the loop width: friction rises with the setpoint
    friction = np.array([float(row["F_mean_nN_mean"]) for row in rows])
    assert np.all(np.diff(friction) > 0)
    assert friction[0] == pytest.approx(0.1542, abs=2e-3)
    assert out.with_name("labels.by_load.png").stat().st_size > 1000
