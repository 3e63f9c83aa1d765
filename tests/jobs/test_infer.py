"""The ``infer`` job's lines for the terminal: out-of-domain reasons, refusals, the table."""

from __future__ import annotations

import numpy as np

from stickslip.estimators.table import ResultTable
from stickslip.jobs.infer import InferResult, summary_text
from stickslip.traces.trace import Trace


def _row(name: str, in_domain: bool | None, reason: str | None = None) -> dict:
    row = {"trace": name, "quality": "ok", "F_mean_nN": 1.0, "U0_eV": 1.0, "K_N_m": 10.0,
           "eta": 5.0, "U0_eV_std": 0.1, "K_N_m_std": 0.5}  # fmt: skip
    if in_domain is not None:
        row.update(in_domain=in_domain, domain_reason=reason)
    return row


def _result(rows: list[dict], sources: list[str]) -> InferResult:
    x = np.arange(64) * 0.02
    traces = [Trace(x, np.zeros_like(x), r["trace"], source=s)
              for r, s in zip(rows, sources, strict=True)]  # fmt: skip
    return InferResult(table=ResultTable(rows=rows, estimator="line-cnn"), traces=[*traces])


def test_a_maps_lines_are_grouped_by_the_kind_of_reason():
    # a map's lines differ in the numbers of their reason, not in its kind: one line per
    # file and kind, with the count; a lone trace keeps its whole reason
    far = "line unlike the training lines (embedding distance {:.2f}x the limit)"
    rows = [_row(f"map/fwd/{i}", False, far.format(1.1 + i / 10)) for i in range(5)]
    rows += [_row("map/fwd/5", True), _row("map/fwd/6", False, "eta below the trained window")]
    rows += [_row("single", False, far.format(2.0))]
    res = _result(rows, ["map.spm"] * 7 + ["single.csv"])
    assert res.out_of_domain() == [0, 1, 2, 3, 4, 6, 7]
    assert res.domain_lines() == [
        "map.spm: 5 lines: line unlike the training lines",
        "map/fwd/6: eta below the trained window",
        "single: line unlike the training lines (embedding distance 2.00x the limit)",
    ]
    assert res.domain_lines(limit=1) == ["map.spm: 5 lines: line unlike the training lines",
                                         "... and 2 more (domain_reason)"]  # fmt: skip


def test_rows_without_an_estimate_or_a_verdict_are_not_out_of_domain():
    refused = {"trace": "bad", "quality": "too short", "in_domain": False}
    res = _result([refused, _row("plain", None), _row("in", True)], ["a", "b", "c"])
    assert res.out_of_domain() == [] and res.domain_lines() == []
    assert res.error_lines() == ["bad: too short"]


def test_the_terminal_table_marks_the_verdict_and_keeps_its_columns():
    rows = [_row("in", True), _row("out", False, "x"), _row("none", None)]
    rows[1]["K_N_m_std"] = 433.07  # a widened interval keeps the columns aligned
    lines = summary_text(ResultTable(rows=rows, estimator="line-cnn")).splitlines()
    assert [ln.split()[-1] for ln in lines] == ["domain", "in", "OUT", "-"]
    assert len({len(ln) for ln in lines[1:]}) == 1
    assert "+-433  " in lines[2]
    # without a verdict column (the window and classical estimators' tables), none
    plain = summary_text(ResultTable(rows=[_row("a", None)], estimator="classical"))
    assert "domain" not in plain


def test_a_trace_that_changes_part_way_is_split_where_both_parts_are_long_enough():
    from stickslip.jobs.infer import split_at_changes

    x = np.linspace(0.0, 11.0, 512)
    t = Trace(x_nm=x, force_nN=np.sin(x), name="line 7", meta={"line": 7, "direction": "trace"})
    parts = split_at_changes([{"change_nm": 4.0}], [t])
    assert [p.name for p in parts] == ["line 7 [x < 4.00 nm]", "line 7 [x >= 4.00 nm]"]
    assert parts[0].x_nm.max() < 4.0 <= parts[1].x_nm.min()
    assert parts[0].force_nN.size + parts[1].force_nN.size == 512
    assert "line" not in parts[0].meta  # the parts join no map's pooled answer
    # a part of under a fifth of the line, or no change: no split
    assert split_at_changes([{"change_nm": 1.0}], [t]) == []
    assert split_at_changes([{"change_nm": None}], [t]) == []
