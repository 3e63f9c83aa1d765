"""Where the per-map answer shows: the report, friction-load's estimates, the job's files."""

import csv
import math
import re

import numpy as np
import pytest

from stickslip.diagnostics import load_fits as lf
from stickslip.diagnostics.report_html import write_report
from stickslip.estimators import pooling as pl
from stickslip.estimators.table import ResultTable
from stickslip.jobs import infer as inf
from stickslip.traces.trace import Trace

CAL = pl.PoolingCalibration(sys_single=dict.fromkeys(pl.POOL_TARGETS, 0.03),
                            sys_both=dict.fromkeys(pl.POOL_TARGETS, 0.02))  # fmt: skip


def _rows(n=40, load=2.0, U0=1.5, change=None, file="m.spm", seed=4251):
    rng = np.random.default_rng(seed)
    rows = []
    for d in ("trace", "retrace"):
        for line in range(n):
            u = U0 * (1.5 if change is not None and line >= change else 1.0)
            row = {"trace": f"{file}:Lat:{d}:L{line:03d}", "quality": "ok", "file": file,
                   "channel": "Lat", "direction": d, "line": line, "load": load,
                   "load_unit": "nN"}  # fmt: skip
            for key, val, rel in (("F_mean_nN", 0.5 + load, 0.1), ("U0_eV", u, 0.05),
                                  ("K_N_m", 10.0, 0.03), ("eta", 5.226 * u, 0.06)):  # fmt: skip
                est = val * math.exp(rng.normal(0, rel / 2))
                row.update({key: est, f"{key}_std": rel * est,
                            f"{key}_lo68": est * math.exp(-rel), f"{key}_hi68": est * math.exp(rel),
                            f"{key}_lo95": est * math.exp(-pl.Z95 * rel),
                            f"{key}_hi95": est * math.exp(pl.Z95 * rel)})  # fmt: skip
            rows.append(row)
    return rows


def test_report_opens_with_the_per_map_answer_and_marks_change(tmp_path):
    rows = _rows(change=25)
    rng = np.random.default_rng(1)
    traces = [Trace(x_nm=np.arange(64) * 0.1, force_nN=rng.normal(size=64) + (d == "trace"),
                    name=r["trace"], source="m.spm",
                    meta={"line": r["line"], "direction": r["direction"], "channel": "Lat"})
              for r in rows for d in [r["direction"]]]  # fmt: skip
    table = ResultTable(rows=rows, intervals=True)
    groups = pl.group_table(rows, CAL)
    assert any(g["change_line"] is not None for g in groups)
    path = write_report(tmp_path / "r.html", table, traces, {}, groups=groups)
    text = path.read_text()
    sections = re.findall(r'<section id="([^"]+)"', text)
    assert sections[0] == "answer" and "maps" in sections
    assert "Per-map answer" in text and "tau" in text
    assert "dashed: change point" in text
    assert "1st-99th percentile of each direction" in text
    # without groups, no such section
    text = write_report(tmp_path / "s.html", table, traces, {}).read_text()
    assert 'id="answer"' not in text


def test_friction_load_estimates_are_the_pooled_answer():
    rows = [r for load in (1.0, 2.0, 3.0, 4.0) for r in _rows(load=load, file=f"m{load}.spm")]
    # as read back from CSV: strings
    rows = [{k: str(v) for k, v in r.items()} for r in rows]
    s = lf.estimates_by_load(rows)
    assert [r["load"] for r in s] == [1.0, 2.0, 3.0, 4.0]
    g = pl.group_table(_rows(load=1.0, file="m1.0.spm"))
    both = next(x for x in g if x["direction"] == "both" and x["segment"] == "all")
    assert s[0]["U0_eV_mean"] == pytest.approx(both["U0_eV"], rel=1e-6)
    assert (s[0]["U0_eV_lo"], s[0]["U0_eV_hi"]) == pytest.approx((both["U0_eV_lo68"],
                                                                  both["U0_eV_hi68"]))
    assert s[0]["U0_eV_interval"] == "pooled 68 % interval of the map"
    laws, why = lf.fit_pooled_friction(s)
    assert not why
    mu, _ = laws[0].param("mu")
    assert mu == pytest.approx(1.0, rel=0.1)  # F = 0.5 + load


def test_job_writes_groups_beside_the_table_and_marks_lines(tmp_path):
    rows = _rows(n=30)
    rows[7]["U0_eV"] *= 3.0  # a line that breaks the pattern
    for k in ("lo68", "hi68", "lo95", "hi95"):
        rows[7][f"U0_eV_{k}"] *= 3.0
    result = inf.InferResult(table=ResultTable(rows=rows, intervals=True), traces=[None] * 60)
    inf.add_map_groups(result)
    assert rows[7][inf.MAP_REASON] == pl.OUTLIER_REASON
    assert sum(inf.MAP_REASON in r for r in rows) == 1
    written = inf.write_outputs(result, tmp_path / "out.csv")
    assert tmp_path / "out.groups.csv" in written
    with (tmp_path / "out.groups.csv").open() as fh:
        got = list(csv.DictReader(fh))
    assert [g["direction"] for g in got] == ["trace", "retrace", "both"]
    assert got[0]["flagged_lines"] == "7" and got[0]["n_left_out"] == "1"
    assert "per-map pooled answer" in inf.groups_text(result)
