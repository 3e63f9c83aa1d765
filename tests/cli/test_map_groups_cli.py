"""`infer` on a friction map writes the per-map pooled answer (`<out>.groups.csv`)."""

import csv
import json

import numpy as np
import pytest
from typer.testing import CliRunner

from stickslip.cli.main import app
from stickslip.estimators.pooling import GROUP_COLUMNS
from stickslip.simulators import simulate

runner = CliRunner()
N_LINES = 10


def _write_gwy(path, trace, retrace_raw):
    objects = pytest.importorskip("gwyfile.objects")
    c = objects.GwyContainer()
    for i, (title, img) in enumerate((("Friction Forward", trace),
                                      ("Friction Backward", retrace_raw))):  # fmt: skip
        c[f"/{i}/data"] = objects.GwyDataField(
            img * 1e-9, xreal=11e-9, yreal=11e-9, si_unit_xy=objects.GwySIUnit(unitstr="m"),
            si_unit_z=objects.GwySIUnit(unitstr="N"))
        c[f"/{i}/data/title"] = title
    c.tofile(str(path))
    return path


@pytest.fixture(scope="module")
def gwy_map(tmp_path_factory):
    """A Gwyddion map of N_LINES simulated lines in both directions (forces in N)."""
    pytest.importorskip("gwyfile.objects")
    f = simulate(np.full(2 * N_LINES, 1.5), np.full(2 * N_LINES, 10.0), seed=4241).force_nN
    trace = f[:N_LINES] + 0.2  # an offset that does not reverse with the scan
    retrace_raw = -f[N_LINES:][:, ::-1] + 0.2  # stored in x order, raw sign
    return _write_gwy(tmp_path_factory.mktemp("map") / "map.gwy", trace, retrace_raw)


def test_infer_writes_groups_csv(gwy_map, tmp_path):
    out = tmp_path / "r.csv"
    r = runner.invoke(app, ["infer", str(gwy_map), "--out", str(out), "--no-classical"])
    assert r.exit_code == 0, r.output
    assert "per-map pooled answer" in r.output
    path = tmp_path / "r.groups.csv"
    assert path.exists()
    with path.open() as fh:
        reader = csv.DictReader(fh)
        assert tuple(reader.fieldnames) == GROUP_COLUMNS
        rows = list(reader)
    by = {row["direction"]: row for row in rows if row["segment"] == "all"}
    assert set(by) == {"trace", "retrace", "both"}
    assert int(by["both"]["n_lines"]) + int(by["both"]["n_left_out"]) == 2 * N_LINES
    for key in ("F_mean_nN", "U0_eV", "K_N_m", "eta"):
        lo, v, hi = (float(by["both"][f"{key}{s}"]) for s in ("_lo95", "", "_hi95"))
        assert lo < v < hi
    assert 1.2 < float(by["both"]["U0_eV"]) < 1.8
    # the offset: trace above retrace, 'both' between
    assert float(by["trace"]["F_mean_nN"]) > float(by["both"]["F_mean_nN"]) \
        > float(by["retrace"]["F_mean_nN"])  # fmt: skip


def test_groups_follow_the_output_format(gwy_map, tmp_path):
    out = tmp_path / "r.json"
    r = runner.invoke(app, ["infer", str(gwy_map), "--out", str(out), "--no-classical"])
    assert r.exit_code == 0, r.output
    groups = json.loads((tmp_path / "r.groups.json").read_text())
    assert [g["direction"] for g in groups if g["segment"] == "all"] == \
        ["trace", "retrace", "both"]  # fmt: skip
    assert set(groups[0]) == set(GROUP_COLUMNS)


def test_single_traces_write_no_groups(tmp_path):
    f = simulate([1.5], [10.0], seed=4243).force_nN[0]
    p = tmp_path / "line.csv"
    np.savetxt(p, np.column_stack([np.arange(f.size) * 11.0 / f.size, f]), delimiter=",",
               header="x_nm,force_nN", comments="")  # fmt: skip
    r = runner.invoke(app, ["infer", str(p), "--out", str(tmp_path / "r.csv"), "--no-classical"])
    assert r.exit_code == 0, r.output
    assert not (tmp_path / "r.groups.csv").exists()


def test_a_spike_burst_line_is_left_out_with_its_reason(tmp_path):
    pytest.importorskip("gwyfile.objects")
    n = 16
    rng = np.random.default_rng(4247)
    f = simulate(np.full(2 * n, 1.5), np.full(2 * n, 10.0), seed=4245).force_nN
    f += rng.normal(0, 0.05, f.shape)  # some detector noise, as on a measured map
    for row in (5, n + 5):  # line 5, both directions: a burst of 8 spikes of 3 nN
        f[row, rng.choice(f.shape[1], 8, replace=False)] += 3.0
    path = _write_gwy(tmp_path / "spikes.gwy", f[:n], -f[n:][:, ::-1])
    out = tmp_path / "r.csv"
    r = runner.invoke(app, ["infer", str(path), "--out", str(out), "--no-classical"])
    assert r.exit_code == 0, r.output
    with out.open() as fh:
        rows = list(csv.DictReader(fh))
    # the line model writes what each line shows
    assert all(np.isfinite(float(row[c])) for row in rows
               for c in ("evidence_slow", "evidence_spikes", "evidence_local"))  # fmt: skip
    why = {(row["direction"], int(row["line"])): row["map_reason"] for row in rows
           if row["map_reason"]}  # fmt: skip
    # spikes show in the second differences, and add slow non-periodic content as well
    for d in ("trace", "retrace"):
        assert why.get((d, 5), "").startswith("shows what the other lines of its map do not: ")
        assert "spikes" in why[(d, 5)]
    assert sum(1 for (_, line), w in why.items() if line != 5 and "spikes" in w) == 0
    with (tmp_path / "r.groups.csv").open() as fh:
        groups = {g["direction"]: g for g in csv.DictReader(fh) if g["segment"] == "all"}
    assert "5" in groups["both"]["flagged_lines"].split()
