"""Trace/retrace pairs: the offset that does not reverse with the scan cancels."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from stickslip.estimators.calibration import Z68
from stickslip.estimators.pairs import (
    OFFSET,
    PAIR,
    PAIR_COLUMNS,
    add_pair_columns,
    find_pairs,
    offset_free_pairs,
    pair_friction,
    pair_parameters,
    shared_offset,
)
from stickslip.traces.formats.common import Channel, ScanFile
from stickslip.traces.formats.maps import friction_loop, map_to_traces
from stickslip.traces.trace import Trace

PIXELS = 256
SIZE_NM = 5.5
OFFSET_NN = 0.7


def sawtooth(x_nm: np.ndarray, lattice_nm: float, peak_nN: float, phase: float) -> np.ndarray:
    """A stick-slip-like line in its scan direction: slow rise, sudden drop."""
    return peak_nN * (2.0 * (((x_nm / lattice_nm) + phase) % 1.0) - 1.0) + 0.4 * peak_nN


def synthetic_map(lines: int = 3) -> tuple[ScanFile, np.ndarray]:
    """A friction map with a known lateral offset; returns it and each line's true
    friction (mean over both directions)."""
    x = np.arange(PIXELS) * SIZE_NM / PIXELS
    rng = np.random.default_rng(3)
    fwd = np.stack([sawtooth(x, 0.246, 1.0 + 0.2 * i, rng.random()) for i in range(lines)])
    bwd = np.stack([sawtooth(x, 0.246, 1.1 + 0.2 * i, rng.random()) for i in range(lines)])
    # raw lateral signal: friction + offset forward, -friction + offset backward; the
    # backward line is stored with columns in increasing x, as every vendor does
    trace_img = fwd + OFFSET_NN
    retrace_img = (-bwd + OFFSET_NN)[:, ::-1]
    scan = ScanFile(
        path=Path("map.spm"), fmt="test", scan_size_nm=SIZE_NM,
        channels=[Channel("Friction", "trace", "nN", trace_img.shape, trace_img),
                  Channel("Friction", "retrace", "nN", retrace_img.shape, retrace_img)],
    )  # fmt: skip
    return scan, 0.5 * (fwd.mean(axis=1) + bwd.mean(axis=1))


def mean_rows(traces: list[Trace], half_width_nN: float = 0.1) -> list[dict]:
    """Rows of an estimator that reads each line's friction as its mean force."""
    rows = []
    for t in traces:
        m = float(np.mean(t.force_nN))
        rows.append({"trace": t.name, "F_mean_nN": m, "F_mean_nN_std": half_width_nN,
                     "F_mean_nN_lo68": m - half_width_nN, "F_mean_nN_hi68": m + half_width_nN,
                     "F_mean_nN_lo95": m - 2 * half_width_nN,
                     "F_mean_nN_hi95": m + 2 * half_width_nN})  # fmt: skip
    return rows


def test_the_offset_cancels_in_the_pair_and_not_in_the_rows():
    scan, friction = synthetic_map()
    traces = map_to_traces(scan)
    rows = mean_rows(traces)
    assert add_pair_columns(rows, traces) == 3
    for t, row in zip(traces, rows, strict=True):
        line = t.meta["line"]
        sign = 1.0 if t.meta["direction"] == "trace" else -1.0
        # each row alone is off by the offset, with the sign of its direction ...
        assert row["F_mean_nN"] - friction[line] == pytest.approx(sign * OFFSET_NN, abs=0.15)
        # ... the pair is not, and it finds the offset (to the difference between the
        # two directions' friction, which it cannot tell from an offset)
        assert row[PAIR] == pytest.approx(friction[line], abs=1e-9)
        assert row[OFFSET] == pytest.approx(OFFSET_NN, abs=0.05)
        assert row["pair_trace"] != row["trace"]


def test_the_pair_is_the_friction_loop_of_the_raw_images():
    scan, _ = synthetic_map()
    traces = map_to_traces(scan)
    rows = mean_rows(traces)
    add_pair_columns(rows, traces)
    loop, offset = friction_loop(scan.channels[0].data, scan.channels[1].data)
    for t, row in zip(traces, rows, strict=True):
        assert row[PAIR] == pytest.approx(loop[t.meta["line"]], abs=1e-12)
        assert row[OFFSET] == pytest.approx(offset[t.meta["line"]], abs=1e-12)


def test_pair_interval_is_the_mean_of_the_rows_intervals():
    t = {"F_mean_nN": 1.0, "F_mean_nN_std": 0.1, "F_mean_nN_lo95": 0.8, "F_mean_nN_hi95": 1.2}
    r = {"F_mean_nN": 2.0, "F_mean_nN_std": 0.3, "F_mean_nN_lo95": 1.4, "F_mean_nN_hi95": 2.6}
    p = pair_friction(t, r)
    assert p[PAIR] == pytest.approx(1.5)
    assert p[OFFSET] == pytest.approx(-0.5)
    assert p[f"{PAIR}_std"] == pytest.approx(0.2)
    assert (p[f"{PAIR}_lo95"], p[f"{PAIR}_hi95"]) == pytest.approx((1.1, 1.9))
    assert f"{PAIR}_lo68" not in p  # neither row has it
    assert pair_friction(t, {"F_mean_nN": None}) == {}


def test_with_the_models_own_std_the_pair_leaves_the_offset_term_out():
    # rows whose <F> intervals carry an offset prior (wide) and the model's std (narrow)
    t = {"F_mean_nN": 1.0, "F_mean_nN_std": 0.3, "F_mean_nN_lo95": 0.45, "F_mean_nN_hi95": 1.55,
         "F_model_std_nN": 0.02}
    r = {"F_mean_nN": 2.0, "F_mean_nN_std": 0.3, "F_mean_nN_lo95": 1.45, "F_mean_nN_hi95": 2.55,
         "F_model_std_nN": 0.04}  # fmt: skip
    p = pair_friction(t, r)
    assert p[f"{PAIR}_std"] == pytest.approx(0.03)
    assert p[f"{PAIR}_hi95"] - p[PAIR] == pytest.approx(1.959964 * 0.03, rel=1e-5)
    assert p[PAIR] - p[f"{PAIR}_lo68"] == pytest.approx(0.994458 * 0.03, rel=1e-5)


def test_only_one_trace_and_one_retrace_of_a_line_pair():
    scan, _ = synthetic_map(lines=2)
    traces = map_to_traces(scan)
    pairs = find_pairs(traces)
    assert len(pairs) == 2
    for i, j in pairs:
        assert traces[i].meta["direction"] == "trace"
        assert traces[j].meta["direction"] == "retrace"
        assert traces[i].meta["line"] == traces[j].meta["line"]
    # the same file read twice: which rows belong together is a guess, so none pair
    assert find_pairs(traces + traces) == []
    # a line with one direction, a plain trace, and a missing trace do not pair
    plain = Trace(np.arange(32.0), np.zeros(32), "plain")
    assert find_pairs([traces[0], plain, None]) == []
    # another channel of the same file is another pair
    other = [Trace(t.x_nm, t.force_nN, t.name, t.source, {**t.meta, "channel": "Lateral"})
             for t in traces]  # fmt: skip
    assert len(find_pairs(traces + other)) == 4


def test_rows_without_a_friction_estimate_get_no_pair_columns():
    scan, _ = synthetic_map(lines=1)
    traces = map_to_traces(scan)
    rows = mean_rows(traces)
    rows[1] = {"trace": traces[1].name, "quality": "too few slips"}
    assert add_pair_columns(rows, traces) == 0
    assert PAIR not in rows[0] and PAIR not in rows[1]


def pt_row(U0: float, K: float, eta: float, half_width_ln: float | None) -> dict:
    """A row with log-normal intervals of the given log half-width (68 %; twice at 95 %)."""
    row: dict = {"U0_eV": U0, "K_N_m": K, "eta": eta}
    if half_width_ln is not None:
        for key, v in (("U0_eV", U0), ("K_N_m", K), ("eta", eta)):
            for b, z in (("lo68", -1), ("hi68", 1), ("lo95", -2), ("hi95", 2)):
                row[f"{key}_{b}"] = v * np.exp(z * half_width_ln)
    return row


def test_an_offset_that_moves_the_two_directions_apart_cancels_in_the_pair_parameters():
    # an offset reads as +d in one direction's ln U0 and -d in the other's
    d, h = 0.2, 0.1
    t = pt_row(2.0 * np.exp(d), 10.0 * np.exp(-d / 2), 5.0 * np.exp(d), h)
    r = pt_row(2.0 * np.exp(-d), 10.0 * np.exp(d / 2), 5.0 * np.exp(-d), h)
    out = pair_parameters(t, r)
    assert out["U0_pair_eV"] == pytest.approx(2.0)
    assert out["K_pair_N_m"] == pytest.approx(10.0)
    assert out["eta_pair"] == pytest.approx(5.0)
    # the rows' log half-widths combine as independent errors: h / sqrt(2)
    assert np.log(out["U0_pair_eV_hi68"] / out["U0_pair_eV"]) == pytest.approx(h / np.sqrt(2))
    assert np.log(out["U0_pair_eV"] / out["U0_pair_eV_lo95"]) == pytest.approx(2 * h / np.sqrt(2))
    # the std is the log-normal's with that 68 % interval
    e = h / np.sqrt(2) / Z68
    assert out["U0_pair_eV_std"] == pytest.approx(2.0 * np.sqrt(np.expm1(e * e) * np.exp(e * e)))


def test_pair_parameters_need_both_rows():
    full = pt_row(2.0, 10.0, 5.0, 0.1)
    # no intervals on one row: the values only
    out = pair_parameters(full, pt_row(2.2, 11.0, 5.5, None))
    assert out["U0_pair_eV"] == pytest.approx(np.sqrt(2.0 * 2.2))
    assert "U0_pair_eV_lo95" not in out and "U0_pair_eV_std" not in out
    # a row without U0 (a refusal) or with a non-positive one gives no U0 pair
    assert "U0_pair_eV" not in pair_parameters(full, {"quality": "too noisy"})
    assert "K_pair_N_m" not in pair_parameters(full, {**full, "K_N_m": 0.0})


def test_map_rows_get_the_pair_parameters_on_both_rows():
    scan, _ = synthetic_map(lines=2)
    traces = map_to_traces(scan)
    rows = [{**r, **pt_row(2.0 + 0.1 * i, 10.0, 5.0, 0.1)} for i, r in
            enumerate(mean_rows(traces))]  # fmt: skip
    before = [set(r) for r in rows]
    assert add_pair_columns(rows, traces) == 2
    # every column a pair adds is a documented one, and all of them are there
    for r, keys in zip(rows, before, strict=True):
        assert set(r) - keys == set(PAIR_COLUMNS)
    for it, ir in find_pairs(traces):
        assert rows[it]["U0_pair_eV"] == rows[ir]["U0_pair_eV"]
        both = rows[it]["U0_eV"] * rows[ir]["U0_eV"]
        assert rows[it]["U0_pair_eV"] == pytest.approx(np.sqrt(both))


def tilted_map(lines: int = 2) -> tuple[ScanFile, np.ndarray]:
    """A map whose offset varies along x (a tilt and a curvature, the same in both
    directions) under sawteeth of different phases; returns it and the offset (lines,
    pixels) in physical x order."""
    x = np.arange(PIXELS) * SIZE_NM / PIXELS
    u = x / SIZE_NM
    rng = np.random.default_rng(5)
    fwd = np.stack([sawtooth(x, 0.246, 1.0, rng.random()) for _ in range(lines)])
    bwd = np.stack([sawtooth(x, 0.246, 1.0, rng.random()) for _ in range(lines)])
    off = np.stack([-3.0 + 4.0 * u - 2.5 * (i + 1) * u**2 for i in range(lines)])
    trace_img = fwd + off
    retrace_img = -bwd[:, ::-1] + off  # the backward scan's friction, stored in x order
    scan = ScanFile(
        path=Path("tilt.spm"), fmt="test", scan_size_nm=SIZE_NM,
        channels=[Channel("Friction", "trace", "nN", trace_img.shape, trace_img),
                  Channel("Friction", "retrace", "nN", retrace_img.shape, retrace_img)],
    )  # fmt: skip
    return scan, off


def test_the_shared_offset_of_a_pair_is_found_along_the_line():
    scan, off = tilted_map()
    traces = map_to_traces(scan)
    pairs = find_pairs(traces)
    assert len(pairs) == 2
    period = 0.246 / (SIZE_NM / PIXELS)
    for it, ir in pairs:
        o = shared_offset(traces[it].force_nN, traces[ir].force_nN, period)
        truth = off[traces[it].meta["line"]]
        # the sawteeth's own period means cancel; what is left is the offset (1.5-3 nN,
        # varying by 1.6-2.6 nN along the line) to the point sampling of a sawtooth of
        # 11.4 samples per period: within 5 % of its peak-to-peak 2 nN
        assert np.max(np.abs(o - truth)) < 0.1
        # one line's own level is its friction (0.4 nN here) plus the offset
        assert abs(float(np.mean(traces[it].force_nN) - np.mean(truth))) > 0.3


def test_offset_free_pairs_takes_the_offset_off_both_rows_and_leaves_lone_lines():
    scan, off = tilted_map()
    traces = map_to_traces(scan)
    lone = Trace(traces[0].x_nm, traces[0].force_nN.copy(), "lone", "other.csv")
    out, n = offset_free_pairs([*traces, lone], [0.246] * (len(traces) + 1))
    assert n == 2 and out[-1] is lone
    for t, new in zip(traces, out, strict=False):
        line = t.meta["line"]
        truth = off[line] if t.meta["direction"] == "trace" else -off[line][::-1]
        # each row less its offset: a sawtooth about its friction, with no tilt left
        resid = new.force_nN - (t.force_nN - truth)
        assert np.max(np.abs(resid)) < 0.1
