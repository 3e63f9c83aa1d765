"""Every estimator through the one interface: same table, conditions, refusals, files."""

from __future__ import annotations

import json
from importlib.resources import files

import numpy as np
import pytest
import torch

from stickslip.conditions import GRAPHITE, resolve
from stickslip.estimators.base import Estimator, TraceEstimator
from stickslip.estimators.load import load_estimator
from stickslip.estimators.table import (
    CONDITION_COLUMNS,
    HEAD,
    STD_COLUMNS,
    TARGETS,
    TableFormatError,
    domain_verdict,
    read_table,
)
from stickslip.estimators.window.modelfile import ModelFileError
from stickslip.simulators import PhysicalSettings, simulate
from stickslip.traces.trace import Trace

NAMES = ("classical", "window", None)


@pytest.fixture(scope="module")
def traces():
    """Two clean paper-preset traces, one on MoS2 stated in its file, and one too short."""
    r = simulate([1.5, 3.0], [12.0, 25.0], PhysicalSettings(), seed=11)
    m = simulate([2.0], [15.0], PhysicalSettings(lattice_nm=0.316), seed=12)
    out = [Trace(r.x_nm, r.force_nN[i], f"t{i}", "sim.h5", {"line": i}) for i in range(2)]
    out.append(Trace(m.x_nm, m.force_nN[0], "mos2", "mos2.csv", {"lattice_nm": 0.316}))
    out.append(Trace(r.x_nm[:20], r.force_nN[0, :20], "short", "short.csv"))
    return out


@pytest.fixture(scope="module", params=NAMES, ids=["classical", "window", "line"])
def estimator(request):
    return load_estimator(request.param)


def test_every_estimator_satisfies_the_protocol(estimator):
    assert isinstance(estimator, Estimator)
    assert estimator.kind in ("classical", "window", "line") and estimator.describe()


def test_one_table_layout_for_every_estimator(estimator, traces):
    table = estimator.predict(traces)
    assert [r["trace"] for r in table.rows] == ["t0", "t1", "mos2", "short"]
    cols = table.columns
    assert cols[:3] == list(HEAD) and cols[3:7] == list(TARGETS)
    assert cols[7:11] == list(STD_COLUMNS)
    assert all(c in cols for c in CONDITION_COLUMNS) and "file" in cols
    assert ("U0_eV_lo95" in cols) == estimator.intervals
    ok = {r["trace"]: r for r in table.rows if r["quality"] == "ok"}
    # the clean traces are estimated within a few per cent by every estimator
    assert ok["t0"]["U0_eV"] == pytest.approx(1.5, rel=0.08)
    assert ok["t1"]["K_N_m"] == pytest.approx(25.0, rel=0.08)
    assert ok["mos2"]["U0_eV"] == pytest.approx(2.0, rel=0.15)
    frame = table.to_frame()
    assert len(frame) == 4 and list(frame.columns) == cols


def test_conditions_flag_then_file_then_model(estimator, traces):
    rows = estimator.predict(traces[:3], velocity_nm_per_s=30.0).rows
    assert [r["lattice_source"] for r in rows] == ["model", "model", "file"]
    assert [r["lattice_nm"] for r in rows] == [GRAPHITE.lattice_nm] * 2 + [0.316]
    assert {r["velocity_source"] for r in rows} == {"flag"}
    assert {r["velocity_nm_per_s"] for r in rows} == {30.0}
    rows = estimator.predict(traces[2:3], lattice_nm=0.25).rows
    assert rows[0]["lattice_nm"] == 0.25 and rows[0]["lattice_source"] == "flag"


def test_resolve_prefers_the_user_then_the_file():
    c = resolve({"lattice_nm": 0.3, "temperature_K": 10.0}, GRAPHITE, velocity_nm_per_s=5.0)
    assert (c.lattice_nm, c.lattice_source) == (0.3, "file")
    assert (c.velocity_nm_per_s, c.velocity_source) == (5.0, "flag")
    assert (c.temperature_K, c.temperature_source) == (10.0, "file")
    c = resolve({}, GRAPHITE)
    assert c.lattice_source == c.velocity_source == c.temperature_source == "model"


def test_a_table_whose_every_row_is_refused_has_the_same_columns(estimator, traces):
    # code written against one table (df["U0_eV"]) must not break on a file of refusals
    full = estimator.predict(traces).columns
    refused = estimator.predict(traces[-1:])
    assert refused.rows[0]["quality"] != "ok"
    cols = refused.columns
    assert cols[:3] == list(HEAD) and cols[3:7] == list(TARGETS)
    assert cols[7:11] == list(STD_COLUMNS)
    assert [c for c in full if c in cols] == [c for c in cols if c in full]  # same order
    frame = refused.to_frame()
    assert frame["U0_eV"].isna().all() and list(frame.columns) == cols


def test_a_refused_trace_is_a_row_with_its_reason(traces):
    for name in ("window", None):
        row = load_estimator(name).predict(traces).rows[-1]
        assert row["trace"] == "short" and row["quality"] != "ok" and "U0_eV" not in row
        assert "short" in row["quality"] or "pixel" in row["quality"]


def test_nonsense_forces_and_positions_are_refused_with_a_reason(estimator, traces, recwarn):
    """Forces of 1e30 nN, a scan of 0.01 nm or 2e5 nm, positions that are NaN or go back,
    a lattice stated in pm: every estimator refuses them, saying why, and warns nothing."""
    t = traces[0]
    bad_x = t.x_nm.copy()
    bad_x[5] = np.nan
    cases = {
        "huge": Trace(t.x_nm, t.force_nN * 1e30, "huge"),
        "tiny": Trace(t.x_nm * 1e-3, t.force_nN, "tiny"),
        "long": Trace(t.x_nm * 2e4, t.force_nN, "long"),
        "nan_x": Trace(bad_x, t.force_nN, "nan_x"),
        "back": Trace(t.x_nm[::-1].copy(), t.force_nN, "back"),
        "pm": Trace(t.x_nm, t.force_nN, "pm", meta={"lattice_nm": 246.0}),
    }
    words = {"huge": "force outside any physical range", "tiny": "too short",
             "long": "scan length outside", "nan_x": "NaN", "back": "not strictly increasing",
             "pm": "lattice spacing outside any physical range"}  # fmt: skip
    rows = estimator.predict([t, *cases.values()]).rows
    assert rows[0]["quality"] == "ok"
    for row in rows[1:]:
        assert row["quality"] != "ok" and words[row["trace"]] in row["quality"], row["quality"]
        assert "U0_eV" not in row and len(row["quality"].split()) >= 4
        if estimator.domain_verdict:
            assert row["in_domain"] is False
    assert "e+30 nN" in rows[1]["quality"] and "from the file" in rows[-1]["quality"]
    assert not [w for w in recwarn if issubclass(w.category, RuntimeWarning)]


class _Overflowing(TraceEstimator):
    """An estimator whose numbers overflow (what a line far outside a model's reach gives)."""

    name = "overflowing"
    intervals = True
    bad = "U0_eV"

    def estimate(self, traces, conditions):
        res = {k: 1.0 for k in TARGETS} | {k: 0.1 for k in STD_COLUMNS}
        res |= {f"{k}_{b}": v for k in TARGETS for b, v in (("lo68", 0.9), ("hi68", 1.1),
                                                            ("lo95", 0.8), ("hi95", 1.2))}
        res[self.bad] = float("inf")
        return [dict(res) for _ in traces], []


@pytest.mark.parametrize("bad", ["U0_eV", "K_N_m_std", "eta_hi95", "F_mean_nN_lo68"])
def test_a_nonfinite_estimate_is_never_ok(traces, bad):
    est = _Overflowing()
    est.bad = bad
    row = est.predict(traces[:1]).rows[0]
    # a value that overflows is a unit or condition slip; a value with an unbounded
    # uncertainty is a line the model cannot place
    lead = ("the estimate is not a finite number" if bad == "U0_eV"
            else "the estimate's uncertainty is unbounded")  # fmt: skip
    assert row["quality"].startswith(lead)
    assert bad in row["quality"] and "U0_eV" not in row
    assert row["in_domain"] is False and row["domain_reason"] == f"no estimate: {row['quality']}"
    assert row["lattice_nm"] == GRAPHITE.lattice_nm and row["file"] == "sim.h5"


def test_table_files_follow_the_extension(traces, tmp_path):
    table = load_estimator(None).predict(traces)
    csv_text = table.write(tmp_path / "r.csv").read_bytes()
    assert b"\r\n" not in csv_text  # LF line endings
    rows = read_table(tmp_path / "r.csv")
    assert rows[-1]["U0_eV"] == "" and rows[-1]["quality"] != "ok"  # missing: an empty cell
    doc = json.loads((table.write(tmp_path / "r.json")).read_text())
    assert len(doc) == 4 and doc[-1]["U0_eV"] is None
    with pytest.raises(TableFormatError, match=r"\.txt"):
        table.write(tmp_path / "r.txt")
    assert not (tmp_path / "r.txt").exists()


def test_the_verdict_reads_the_same_from_memory_and_from_a_file(traces, tmp_path):
    table = load_estimator(None).predict(traces)
    in_memory = [domain_verdict(r) for r in table.rows]
    assert in_memory[-1] is False and all(v is True for v in in_memory[:-1])
    back = read_table(table.write(tmp_path / "r.csv"))  # "True"/"False" cells
    assert [domain_verdict(r) for r in back] == in_memory
    back = json.loads(table.write(tmp_path / "r.json").read_text())  # JSON booleans
    assert [domain_verdict(r) for r in back] == in_memory
    # no verdict: an estimator without one, or a missing value
    assert domain_verdict({"U0_eV": 1.0}) is None and domain_verdict({"in_domain": ""}) is None


def test_loading_dispatches_on_the_file(tmp_path):
    window = files("stickslip") / "resources" / "default_model.pt"
    line = files("stickslip") / "resources" / "line_model.pt"
    assert load_estimator(str(window)).kind == "window"
    assert load_estimator(str(line)).kind == "line"
    assert load_estimator("classical").kind == "classical"
    torch.save({"format": "something-else", "stickslip_version": "0.1"}, tmp_path / "x.pt")
    for bad in (tmp_path / "x.pt", tmp_path / "missing.pt"):
        with pytest.raises(ModelFileError, match=str(bad.name)):
            load_estimator(bad)


def test_estimates_do_not_depend_on_the_batch(traces):
    est = load_estimator(None)
    together = est.predict(traces[:2]).column("U0_eV")
    alone = np.array([est.predict([t]).column("U0_eV")[0] for t in traces[:2]])
    np.testing.assert_allclose(together, alone, rtol=1e-5)
