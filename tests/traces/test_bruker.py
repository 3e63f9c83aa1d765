"""Real Bruker NanoScope friction maps (../shared/data/bruker-friction-ramp)."""

from __future__ import annotations

import numpy as np
import pytest

from stickslip.traces import TraceReadError, collect_traces
from stickslip.traces.formats import friction_loop, reader_options
from stickslip.traces.readers import read_file, read_scan

RAMP_FILES = ["si.0_00144.spm", "si.0_00150.spm", "si.0_00160.spm", "si.0_00170.spm",
              "si.0_00175.spm"]


def _friction(scan):
    return {c.direction: c for c in scan.lateral()}


def test_friction_channels_both_directions_shape_units_means(ramp_dir):
    scan = read_scan(ramp_dir / "si.0_00150.spm")
    ch = _friction(scan)
    assert set(ch) == {"trace", "retrace"}
    for c in ch.values():
        assert c.name == "Friction"
        assert c.unit == "V"
        assert c.data.shape == (32, 32)
    assert round(float(ch["trace"].data.mean()), 3) == 2.911
    assert round(float(ch["retrace"].data.mean()), 3) == 2.860
    assert scan.scan_size_nm == pytest.approx(2000.0)
    assert scan.meta["scan_rate_hz"] == pytest.approx(2.00115)
    assert scan.meta["velocity_nm_per_s"] == pytest.approx(2 * 2000 * 2.00115)
    assert scan.meta["load"] == pytest.approx(-0.8)
    assert scan.meta["load_unit"] == "V"
    names = [(c.name, c.direction) for c in scan.channels]
    assert ("Height", "retrace") in names and ("Deflection Error", "retrace") in names


def test_map_becomes_one_trace_per_line_and_direction(ramp_dir):
    path = ramp_dir / "si.0_00150.spm"
    scan = read_scan(path)
    ch = _friction(scan)
    traces = read_file(path)
    assert len(traces) == 64
    by_name = {t.name: t for t in traces}
    t0 = by_name["si.0_00150:Friction:trace:L000"]
    r5 = by_name["si.0_00150:Friction:retrace:L005"]
    np.testing.assert_allclose(t0.force_nN, ch["trace"].data[0])
    # retrace reversed in x and sign-flipped: friction in the scan direction
    np.testing.assert_allclose(r5.force_nN, -ch["retrace"].data[5][::-1])
    np.testing.assert_allclose(t0.x_nm, np.arange(32) * 62.5)
    assert t0.meta["unit"] == "V" and t0.meta["calibrated"] is False
    assert t0.meta["file"] == str(path) and t0.meta["channel"] == "Friction"
    assert r5.meta["direction"] == "retrace" and r5.meta["line"] == 5
    assert r5.meta["load"] == pytest.approx(-0.8)
    fric, off = friction_loop(ch["trace"].data, ch["retrace"].data)
    assert r5.meta["loop_friction"] == pytest.approx(fric[5])
    assert r5.meta["loop_offset"] == pytest.approx(off[5])
    # the mean of both directions' friction is half the trace-retrace difference
    both = np.mean([t.force_nN.mean() for t in traces if t.meta["line"] == 5])
    assert both == pytest.approx(fric[5])


def test_calibration_converts_volts_to_nN(ramp_dir):
    traces = read_file(ramp_dir / "si.0_00150.spm", **reader_options(calibration_nN_per_V=12.5))
    assert all(t.meta["unit"] == "nN" and t.meta["calibrated"] for t in traces)
    assert round(float(np.mean([t.force_nN.mean() for t in traces if
                                t.meta["direction"] == "trace"])), 2) == round(2.91133 * 12.5, 2)


def test_half_difference_rises_with_setpoint(ramp_dir):
    points = []
    for name in RAMP_FILES:
        ch = _friction(read_scan(ramp_dir / name))
        friction, _ = friction_loop(ch["trace"].data, ch["retrace"].data)
        points.append((read_scan(ramp_dir / name).meta["load"], float(friction.mean())))
    setpoints = [p[0] for p in points]
    assert setpoints == pytest.approx([-1.4, -0.8, 0.2, 1.2, 1.7])
    frictions = [p[1] for p in points]
    assert all(b > a for a, b in zip(frictions, frictions[1:], strict=False))
    assert frictions[0] == pytest.approx(0.01542, abs=1e-4)
    assert frictions[-1] == pytest.approx(0.04187, abs=1e-4)


def test_force_curve_is_a_clean_error(ramp_dir):
    with pytest.raises(TraceReadError, match="no lateral-force channel") as e:
        read_file(ramp_dir / "si.0_00143.spm")
    assert "\n" not in str(e.value)


def test_folder_reads_all_and_reports_the_force_curve(ramp_dir):
    traces, errors = collect_traces([ramp_dir])
    assert len(errors) == 1 and "si.0_00143.spm" in str(errors[0])
    assert len(traces) == 5 * 64 + 2  # five maps plus the text friction loop


def test_lines_per_load_groups_lines(ramp_dir):
    opts = reader_options(lines_per_load=8, loads=[40, 30, 20, 10])
    traces = read_file(ramp_dir / "si.0_00150.spm", **opts)
    line9 = [t for t in traces if t.meta["line"] == 9]
    assert {t.meta["load_group"] for t in line9} == {1}
    assert {t.meta["load"] for t in line9} == {30.0}
    with pytest.raises(TraceReadError, match="only 2 loads"):
        read_file(ramp_dir / "si.0_00150.spm", **reader_options(lines_per_load=8, loads=[1, 2]))


def test_example_profile_reads_as_friction_loop(ramp_dir):
    path = ramp_dir / "exampleFrictionProfileFull.txt"
    raw = np.loadtxt(path)
    traces, errors = collect_traces([path])
    assert not errors
    assert [t.meta["direction"] for t in traces] == ["trace", "retrace"]
    t, r = traces
    np.testing.assert_allclose(t.force_nN, raw[:, 1])
    np.testing.assert_allclose(r.force_nN, -raw[::-1, 2])
    assert t.meta["loop_friction"] == pytest.approx(((raw[:, 1] - raw[:, 2]) / 2).mean())
    assert t.meta["loop_friction"] == pytest.approx(0.03214, abs=1e-4)
    assert t.meta["unit"] == "V"
