"""Per-map pooling: random-effects maths, the systematic floor, outlier lines, change points,
and the groups table."""

import dataclasses
import json
import math

import numpy as np
import pytest
from scipy import optimize, stats

from stickslip.estimators import pooling as pl
from stickslip.estimators.table import ResultTable

CAL = pl.PoolingCalibration(sys_single=dict.fromkeys(pl.POOL_TARGETS, 0.03),
                            sys_both=dict.fromkeys(pl.POOL_TARGETS, 0.02))  # fmt: skip


# ---------------------------------------------------------------------------- maths


def test_dersimonian_laird_hand_computed():
    # w = (2, 1, 0.5), mu_w = 5/7, Q = 26/7, S1 - S2/S1 = 3.5 - 5.25/3.5 = 2
    assert pl.dersimonian_laird([0.0, 1.0, 3.0], [0.5, 1.0, 2.0]) == pytest.approx(6 / 7)
    # equal variances: tau2 = sample variance - v
    assert pl.dersimonian_laird([0.0, 2.0, 4.0], [1.0, 1.0, 1.0]) == pytest.approx(3.0)
    assert pl.dersimonian_laird([1.0, 1.1, 0.9], [1.0, 1.0, 1.0]) == 0.0


def test_reml_maximises_the_restricted_likelihood():
    rng = np.random.default_rng(4231)
    v = rng.uniform(0.01, 0.2, 40)
    y = rng.normal(0.3, np.sqrt(v + 0.05))

    def nll(t2):
        w = 1 / (v + t2)
        mu = np.sum(w * y) / np.sum(w)
        return 0.5 * (np.sum(np.log(v + t2)) + np.log(np.sum(w)) + np.sum(w * (y - mu) ** 2))

    best = optimize.minimize_scalar(nll, bounds=(0, 2), method="bounded",
                                    options={"xatol": 1e-10}).x  # fmt: skip
    assert pl.reml_tau2(y, v) == pytest.approx(best, rel=1e-4)
    # equal variances: REML is the sample variance minus v, as DL
    assert pl.reml_tau2([0.0, 2.0, 4.0], [1.0, 1.0, 1.0]) == pytest.approx(3.0)


def test_q_profile_ends_solve_the_chi2_equations():
    rng = np.random.default_rng(4232)
    v = rng.uniform(0.01, 0.05, 30)
    y = rng.normal(0, np.sqrt(v + 0.04))
    lo, hi = pl.q_profile(y, v)
    fit = pl.random_effects(y, v)
    assert 0 < lo < fit.tau2 < hi

    def q(t2):
        w = 1 / (v + t2)
        return np.sum(w * (y - np.sum(w * y) / np.sum(w)) ** 2)

    assert q(lo) == pytest.approx(stats.chi2.ppf(0.975, 29), rel=1e-6)
    assert q(hi) == pytest.approx(stats.chi2.ppf(0.025, 29), rel=1e-6)


def test_line_scale_reads_log_intervals():
    y, v = pl.line_scale(np.array([2.0]), np.array([1.0]), np.array([4.0]), np.array([9.0]),
                         log=True)  # fmt: skip
    assert y[0] == pytest.approx(math.log(2))
    assert math.sqrt(v[0]) == pytest.approx(math.log(4) / (2 * pl.Z95))
    # no interval: the std relative to the value
    y, v = pl.line_scale(np.array([2.0]), np.array([np.nan]), np.array([np.nan]),
                         np.array([0.2]), log=True)  # fmt: skip
    assert math.sqrt(v[0]) == pytest.approx(0.1)


def _coverage(sys_rel, n_maps=400, n_lines=256, shared=0.05, seed=4233):
    rng = np.random.default_rng(seed)
    hits = 0
    for _ in range(n_maps):
        b = rng.normal(0, shared)  # the error every line of the map shares
        sd = rng.uniform(0.05, 0.15, n_lines)
        y = b + rng.normal(0, sd)
        p = pl.pool_target(y, sd * sd, sys_rel, log=True)
        hits += abs(p.mu) <= pl.Z95 * p.se
    return hits / n_maps


def test_systematic_floor_keeps_coverage_when_lines_share_an_error():
    assert _coverage(0.0) < 0.5  # 1/sqrt(N) alone promises far too much
    assert 0.92 <= _coverage(0.05) <= 0.98


def _friction_coverage(friction_nN: float, sys_rel: float, sys_abs: float, n_maps=400,
                       offset_nN=0.3, seed=4236) -> float:  # fmt: skip
    """Pooled <F> coverage of maps whose lines share an offset of the same size whatever
    the friction (as a crosstalk offset in one scan direction)."""
    rng = np.random.default_rng(seed)
    hits = 0
    for _ in range(n_maps):
        b = rng.normal(0, offset_nN)
        sd = rng.uniform(0.05, 0.15, 128)
        p = pl.pool_target(friction_nN + b + rng.normal(0, sd), sd * sd, sys_rel, False, sys_abs)
        hits += abs(p.mu - friction_nN) <= pl.Z95 * p.se
    return hits / n_maps


def _tau(truth: np.ndarray, noise: float, interval_sd: float, seed: int) -> float:
    """tau of one map's lines (truth per line + noise) given intervals of ``interval_sd``."""
    y = truth + np.random.default_rng(seed).normal(0, noise, truth.size)
    return math.sqrt(pl.pool_target(y, np.full(y.size, interval_sd**2), 0.0, True).tau2)


def test_tau_of_a_smooth_variation_is_not_hidden_by_conservative_intervals():
    # ln U0 varies by +-20 % along the slow axis (rms 0.141); the lines' intervals say
    # twice the noise they carry, which alone left tau at about zero
    n = 128
    smooth = 0.2 * np.sin(2 * np.pi * np.arange(n) / n + 0.3)
    taus = [_tau(smooth, 0.1, 0.2, seed) for seed in range(20)]
    assert 0.11 <= float(np.median(taus)) <= 0.17
    assert pl.neighbour_scale(smooth + 0.1 * np.random.default_rng(1).standard_normal(n),
                              np.full(n, 0.04)) < 0.5  # fmt: skip
    # a homogeneous map under the same intervals: no spread made up
    assert np.median([_tau(np.zeros(n), 0.1, 0.2, seed) for seed in range(20)]) < 0.03
    # a spread from line to line with no order: never less than the intervals alone give
    iid = np.random.default_rng(7).normal(0, 0.15, n)
    y = iid + np.random.default_rng(8).normal(0, 0.1, n)
    v = np.full(n, 0.2**2)
    assert pl.pool_target(y, v, 0.0, True).tau2 >= pl.random_effects(y, v).tau2 - 1e-12
    # too few lines to tell: the intervals as they are
    assert pl.neighbour_scale(y[:20], v[:20]) == 1.0


def test_friction_floor_has_an_absolute_part():
    # an offset in nN: a floor relative to <F> covers high friction, not low
    assert _friction_coverage(0.5, 0.6, 0.0) < 0.85 < 0.99 <= _friction_coverage(5.0, 0.6, 0.0)
    # the absolute part covers both alike
    for friction in (0.5, 5.0):
        assert 0.92 <= _friction_coverage(friction, 0.0, 0.3) <= 0.98
    # the floor adds in quadrature to the statistical error
    p = pl.pool_target(np.full(4, 2.0), np.full(4, 0.04), 0.1, False, 0.3)
    assert p.sys == pytest.approx(math.hypot(0.3, 0.2))
    assert pl.pool_target(np.full(4, 2.0), np.full(4, 0.04), 0.1, True, 0.3).sys == 0.1


def _barrier_coverage(U0_eV: float, sys_rel: float, offset_part_nN: float, n_maps=400,
                      offset_nN=0.3, lattice_nm=0.246, seed=4238) -> float:  # fmt: skip
    """Pooled U0 coverage of maps whose lines share an offset of the force's zero (one scan
    direction): it moves every line's ln U0 by its share of the largest force, F_max =
    pi U0 / a, as the line model reads it."""
    rng = np.random.default_rng(seed)
    fmax = pl.force_scale_nN(math.log(U0_eV), lattice_nm)
    hits = 0
    for _ in range(n_maps):
        shift = rng.normal(0, offset_nN) / fmax
        sd = rng.uniform(0.05, 0.15, 128)
        y = math.log(U0_eV) + shift + rng.normal(0, sd)
        p = pl.pool_target(y, sd * sd, sys_rel, True, offset_part_nN,
                           pl.force_scale_nN(float(np.mean(y)), lattice_nm))  # fmt: skip
        hits += abs(p.mu - math.log(U0_eV)) <= pl.Z95 * p.se
    return hits / n_maps


def test_barrier_floor_has_an_offset_part_over_the_largest_force():
    assert pl.force_scale_nN(math.log(1.0), 0.246) == pytest.approx(
        math.pi * 0.1602176634 / 0.246)  # fmt: skip
    # one floor in log units sized for a middling barrier: low barriers under-covered,
    # high ones over-covered (the offset is a larger share of a small F_max)
    mid = 0.3 / pl.force_scale_nN(math.log(1.5), 0.246)
    assert _barrier_coverage(0.8, mid, 0.0) < 0.85 < 0.99 <= _barrier_coverage(4.0, mid, 0.0)
    # the offset part covers both alike (F_max read off the pooled barrier, which the
    # offset moves too: a little under 0.95 where it is a third of F_max)
    for U0 in (0.8, 4.0):
        assert 0.92 <= _barrier_coverage(U0, 0.0, 0.3) <= 0.98
    # the two parts add in quadrature; without F_max the offset part is nothing
    p = pl.pool_target(np.full(4, 0.0), np.full(4, 0.04), 0.1, True, 0.3, 2.0)
    assert p.sys == pytest.approx(math.hypot(0.1, 0.15))
    assert pl.pool_target(np.full(4, 0.0), np.full(4, 0.04), 0.1, True, 0.3).sys == 0.1


def test_calibration_without_the_absolute_part_reads_as_relative_only():
    old = {k: v for k, v in pl.bundled_calibration().to_dict().items()
           if k not in ("sys_single_nN", "sys_both_nN")}  # a file written before it
    cal = pl.PoolingCalibration.from_dict(old)
    assert cal.sys_nN("trace") == cal.sys_nN(pl.BOTH) == 0.0
    older = {k: v for k, v in old.items()
             if k not in ("sys_single_offset_nN", "sys_both_offset_nN")}  # fmt: skip
    cal = pl.PoolingCalibration.from_dict(older)
    assert cal.sys_abs("U0_eV", "trace") == cal.sys_abs("K_N_m", pl.BOTH) == 0.0


def test_group_floor_follows_the_pooled_barrier_and_the_rows_lattice(tmp_path):
    cal = dataclasses.replace(CAL, sys_single_offset_nN={"U0_eV": 0.3, "K_N_m": 0.1},
                              sys_both_offset_nN={"U0_eV": 0.1})  # fmt: skip
    path = tmp_path / "cal.json"
    cal.save(path)
    assert pl.PoolingCalibration.from_dict(json.loads(path.read_text())) == cal
    zero = pl.PoolingCalibration(sys_single=dict.fromkeys(pl.POOL_TARGETS, 0.0),
                                 sys_both=dict.fromkeys(pl.POOL_TARGETS, 0.0))  # fmt: skip
    rows = _map_rows()
    for r in rows:
        r["lattice_nm"] = 0.3
    stat = {g["direction"]: g for g in pl.pool_groups(rows, zero).groups}
    for g in pl.pool_groups(rows, cal).groups:
        d = g["direction"]
        fmax = pl.force_scale_nN(math.log(g["U0_eV"]), 0.3)
        for key in ("U0_eV", "K_N_m", "eta"):
            floor = math.hypot(cal.sys(key, d), cal.sys_abs(key, d) / fmax)
            se_stat = math.log(stat[d][f"{key}_hi95"] / stat[d][key]) / pl.Z95
            assert g[key] == pytest.approx(stat[d][key], rel=1e-12)
            assert math.log(g[f"{key}_hi95"] / g[key]) == pytest.approx(
                pl.Z95 * math.hypot(se_stat, floor), rel=1e-9)  # fmt: skip


# ---------------------------------------------------------------------------- lines


def test_outlier_lines_flagged_and_normal_lines_kept():
    rng = np.random.default_rng(4234)
    n = 300
    sd = np.full((n, 2), 0.05)
    Y = rng.normal(0, 0.05, (n, 2))
    bad = np.array([10, 100, 200, 250])
    Y[bad, 0] += 0.6
    flags = pl.flag_outliers(Y, sd * sd, 3.5)
    assert flags[bad].all()
    assert flags[np.setdiff1d(np.arange(n), bad)].mean() <= 0.02


def test_change_point_found_on_synthetic_log_estimates():
    rng = np.random.default_rng(4235)
    found = []
    for _ in range(30):
        n = int(rng.integers(32, 200))
        c = int(rng.integers(8, n - 8))
        Y = rng.normal(0, 0.05, (n, 3))
        Y[c:, 1] += np.log(1.3)  # U0 up by 30 % from line c on
        cp = pl.find_change(Y, 0.99, 4)
        found.append(cp.index is not None and abs(cp.index - c) <= 3)
    assert np.mean(found) >= 0.9


def test_change_point_false_alarms_on_homogeneous_series():
    rng = np.random.default_rng(4236)
    alarms = [pl.find_change(rng.normal(0, 0.05, (128, 3)), 0.99, 4).index is not None
              for _ in range(200)]  # fmt: skip
    assert np.mean(alarms) <= 0.05
    # a burst of three wild lines is not a change
    Y = rng.normal(0, 0.05, (128, 3))
    Y[60:63] += 1.0
    assert pl.find_change(Y, 0.99, 4).index is None


# ---------------------------------------------------------------------------- groups


def _map_rows(n=64, change=None, seed=4237, refused=(), outliers=(), evidence=None):
    """Rows as the line model writes them for one map in two directions. ``evidence``:
    {line: (slow, spikes[, local])} excess over the normal lines' evidence (which then
    every row carries; None: no row has evidence columns)."""
    rng = np.random.default_rng(seed)
    rng_e = np.random.default_rng([seed, 1])  # the estimates as without evidence
    rows = []
    for d, offset in (("trace", 0.1), ("retrace", -0.1)):
        for line in range(n):
            U0 = 1.5 * (1.4 if change is not None and line >= change else 1.0)
            K, F = 10.0, 1.6 + offset
            row = {"trace": f"m:Lat:{d}:L{line:03d}", "quality": "ok", "file": "m.spm",
                   "channel": "Lat", "direction": d, "line": line, "load": 2.0,
                   "load_unit": "nN"}  # fmt: skip
            for key, val, rel in (("F_mean_nN", F, 0.1), ("U0_eV", U0, 0.05), ("K_N_m", K, 0.03),
                                  ("eta", 52.26 * U0 / K, 0.06)):
                est = val * math.exp(rng.normal(0, rel / 2))
                if line in outliers and key == "U0_eV":
                    est *= 2.0
                row[key] = est
                row[f"{key}_std"] = rel * est
                row[f"{key}_lo95"] = est * math.exp(-pl.Z95 * rel)
                row[f"{key}_hi95"] = est * math.exp(pl.Z95 * rel)
            if evidence is not None:  # normal lines: ln-ratios within +-0.3 (robust sd 0.22)
                extra = (*evidence.get(line, (0.0, 0.0)), 0.0, 0.0, 0.0)
                row["evidence_slow"] = -1.5 + rng_e.uniform(-0.3, 0.3) + extra[0]
                row["evidence_spikes"] = 2.0 + rng_e.uniform(-0.3, 0.3) + extra[1]
                row["evidence_local"] = 0.5 + rng_e.uniform(-0.3, 0.3) + extra[2]
            if line in refused:
                row = {k: v for k, v in row.items() if k not in pl.POOL_TARGETS}
                row["quality"] = "no slips found"
            rows.append(row)
    return rows


def test_groups_of_one_map_directions_and_both():
    rows = _map_rows(refused=(5,), outliers=(20,))
    res = pl.pool_groups(rows, CAL)
    by = {g["direction"]: g for g in res.groups}
    assert set(by) == {"trace", "retrace", "both"}
    g = by["trace"]
    assert g["n_lines"] == 62 and g["n_left_out"] == 2  # one refused, one outlier
    assert g["flagged_lines"] == "20" and g["change_line"] is None
    assert g["U0_eV_lo95"] < 1.5 < g["U0_eV_hi95"]
    # the floor: the 95 % half-width is at least z95 * sigma_sys of ln U0
    assert math.log(g["U0_eV_hi95"] / g["U0_eV"]) >= pl.Z95 * 0.03 - 1e-12
    # offsets of opposite sign per direction cancel in 'both'
    assert by["trace"]["F_mean_nN"] > 1.6 > by["retrace"]["F_mean_nN"]
    assert by["both"]["F_mean_nN"] == pytest.approx(1.6, rel=0.02)
    assert by["both"]["n_lines"] == 124
    reasons = {rows[i]["trace"] for i in res.reasons}
    assert reasons == {"m:Lat:trace:L020", "m:Lat:retrace:L020"}
    assert set(res.reasons.values()) == {pl.OUTLIER_REASON}


def test_change_point_pools_either_side():
    groups = pl.group_table(_map_rows(n=96, change=40), CAL)
    whole = [g for g in groups if g["segment"] == "all"]
    assert all(abs(g["change_line"] - 40) <= 3 for g in whole)
    before = next(g for g in groups if g["segment"] == "before" and g["direction"] == "both")
    after = next(g for g in groups if g["segment"] == "after" and g["direction"] == "both")
    assert before["U0_eV"] == pytest.approx(1.5, rel=0.05)
    assert after["U0_eV"] == pytest.approx(2.1, rel=0.05)


def test_a_change_into_lines_out_of_domain_is_found():
    # a domain of another material whose lines the verdict leaves out: they pool nothing,
    # but their estimates still place the change
    rows = _map_rows(n=96, change=40)
    for r in rows:
        if r["line"] >= 40 and (r["line"] - 40) % 32:
            r["in_domain"] = False  # two lines after the change left in domain
    groups = pl.group_table(rows, CAL)
    whole = [g for g in groups if g["segment"] == "all"]
    assert all(abs(g["change_line"] - 40) <= 3 for g in whole)
    after = next(g for g in groups if g["segment"] == "after" and g["direction"] == "both")
    assert after["n_lines"] == 4  # lines 40 and 72, both directions


def test_table_groups_frame_has_the_columns():
    frame = ResultTable(rows=_map_rows(n=16)).groups(CAL)
    assert list(frame.columns) == list(pl.GROUP_COLUMNS)
    for k in ("F_mean_nN", "U0_eV", "K_N_m", "eta"):
        for s in ("", "_lo68", "_hi68", "_lo95", "_hi95", "_tau"):
            assert f"{k}{s}" in frame.columns
    assert list(frame["direction"]) == ["trace", "retrace", "both"]
    assert (frame["n_lines"] == [16, 16, 32]).all()
    assert (frame["U0_eV_lo95"] < frame["U0_eV_lo68"]).all()
    # single traces (no line number) make no group
    assert ResultTable(rows=[{"trace": "a", "quality": "ok", "U0_eV": 1.0}]).groups().empty


def test_bundled_calibration_reads():
    cal = pl.bundled_calibration()
    assert set(cal.sys_single) >= set(pl.POOL_TARGETS) and cal.flag_z > 2
    assert all(v > 0 for v in cal.sys_both.values())


def test_outliers_judged_by_the_maps_own_scatter():
    # lines agree ten times better than their intervals say: a line 8 scatters off is
    # inconsistent with its map, though inside its own interval
    rng = np.random.default_rng(4238)
    Y = rng.normal(0, 0.005, (100, 1))
    Y[42] = 0.04
    V = np.full((100, 1), 0.05**2)
    flags = pl.flag_outliers(Y, V, 3.5)
    assert flags[42] and flags.sum() <= 2
    # too few lines to tell their scatter: their intervals decide
    assert not pl.flag_outliers(Y[30:50], V[30:50], 3.5).any()


# ---------------------------------------------------------------------------- evidence


#: Thresholds at a robust 4 sigma: no normal line of :func:`_map_rows` passes them.
CAL_E = dataclasses.replace(CAL, evidence_z={"slow": 4.0, "spikes": 4.0, "local": 4.0,
                                             "local_both": 4.0})  # fmt: skip


def test_a_line_that_shows_what_its_map_does_not_is_flagged_and_left_out():
    rows = _map_rows(evidence={17: (0.0, 3.0), 33: (3.0, 0.0), 40: (0.0, 0.0, 3.0)})
    res = pl.pool_groups(rows, CAL_E)
    by = {g["direction"]: g for g in res.groups}
    assert by["trace"]["flagged_lines"] == "17 33 40" and by["trace"]["n_lines"] == 61
    assert by["both"]["n_lines"] == 122 and by["both"]["n_left_out"] == 6
    why = {rows[i]["trace"]: r for i, r in res.reasons.items()}
    spikes = "shows what the other lines of its map do not: spikes"
    slow = ("shows what the other lines of its map do not: slow, non-periodic content "
            "(a drift or a step)")
    local = ("shows what the other lines of its map do not: a local anomaly of a few "
             "stick-slip cycles in both scan directions (a defect)")
    assert why == {"m:Lat:trace:L017": spikes, "m:Lat:retrace:L017": spikes,
                   "m:Lat:trace:L033": slow, "m:Lat:retrace:L033": slow,
                   "m:Lat:trace:L040": local, "m:Lat:retrace:L040": local}
    # a line that shows several says them all
    assert pl.evidence_reason([True, True, False]) == pl.EVIDENCE_REASON + \
        "slow, non-periodic content (a drift or a step) and spikes"
    # its estimates were fine: the pool is the same as without the lines
    clean = [r for r in rows if r["line"] not in (17, 33, 40)]
    ref = {g["direction"]: g for g in pl.pool_groups(clean, CAL_E).groups}
    assert by["both"]["U0_eV"] == pytest.approx(ref["both"]["U0_eV"], rel=1e-12)


def test_a_homogeneous_map_flags_nothing_by_evidence():
    for seed in range(4260, 4265):
        res = pl.pool_groups(_map_rows(n=128, seed=seed, evidence={}), CAL_E)
        assert set(res.reasons.values()) <= {pl.OUTLIER_REASON}
    # the default thresholds are set for a small share of normal lines (calibrated on
    # simulated maps at 1 % for the three together): on Gaussian groups they pass less
    rng = np.random.default_rng(4262)
    rate = np.mean([pl.flag_evidence(rng.normal(0, 1, (128, len(pl.JUDGED_EVIDENCE))),
                                     pl.PoolingCalibration().evidence_threshold()).any(axis=1)
                    for _ in range(200)])  # fmt: skip
    assert rate <= 0.01
    # the scale is the map's own: the same map with ten times the scatter, one line ten
    # times further out, is judged alike
    rng = np.random.default_rng(4261)
    E = rng.normal(0, 0.2, (64, 2))
    E[5, 1] += 3.0
    assert pl.flag_evidence(E, [6.0, 6.0]).nonzero() == (np.array([5]), np.array([1]))
    assert (pl.flag_evidence(10 * E + 7.0, [6.0, 6.0]) == pl.flag_evidence(E, [6.0, 6.0])).all()
    # a line that shows less than its map is cleaner, not odd
    E[9, 0] -= 3.0
    assert not pl.flag_evidence(E, [6.0, 6.0])[9].any()
    # too few lines to judge, or no evidence: nothing
    assert not pl.flag_evidence(E[:7], [6.0, 6.0]).any()
    assert not pl.flag_evidence(np.full((64, 2), np.nan), [6.0, 6.0]).any()


def test_rows_without_evidence_pool_as_before():
    rows = _map_rows(outliers=(20,))
    assert not any(c in r for r in rows for c in pl.JUDGED_EVIDENCE_COLUMNS)
    res = pl.pool_groups(rows, CAL)
    assert set(res.reasons.values()) == {pl.OUTLIER_REASON}
    assert {g["flagged_lines"] for g in res.groups} == {"20"}
    # and with evidence from a table read back (strings, some cells empty)
    text = _map_rows(outliers=(20,), evidence={})
    for r in text:
        r["evidence_slow"] = "" if r["line"] % 3 else str(r["evidence_slow"])
        r["evidence_spikes"] = str(r["evidence_spikes"])
    again = pl.pool_groups(text, CAL)
    assert set(again.reasons.values()) == {pl.OUTLIER_REASON}
    assert {g["flagged_lines"] for g in again.groups} == {"20"}


def test_evidence_thresholds_default_when_the_file_lacks_them():
    d = pl.PoolingCalibration().to_dict()
    del d["evidence_z"]
    cal = pl.PoolingCalibration.from_dict(d)
    assert cal.evidence_z == pl.DEFAULT_EVIDENCE_Z
    assert list(pl.PoolingCalibration(evidence_z={"spikes": 4.0}).evidence_threshold()) == \
        [pl.DEFAULT_EVIDENCE_Z["slow"], 4.0, pl.DEFAULT_EVIDENCE_Z["local"]]  # fmt: skip
    assert set(pl.bundled_calibration().evidence_z) == set(pl.EVIDENCE_TEXT)


def test_evidence_scores_by_row_cover_the_map_lines_against_the_usable_ones():
    rows = _map_rows(n=32, refused=(3,), evidence={8: (0.0, 3.0), 3: (0.0, 0.0, 30.0)})
    scores = pl.evidence_scores_by_row(rows)
    assert len(scores) == 2 * 32  # the refused line is scored too
    top = max(scores, key=lambda i: scores[i][1])
    assert rows[top]["line"] == 8 and scores[top][1] > 8
    # the refused line stands out and does not move the yardstick of the others
    ref = pl.evidence_scores_by_row(_map_rows(n=32, refused=(3,), evidence={8: (0.0, 3.0)}))
    for i, s in scores.items():
        assert s[2] > 50 if rows[i]["line"] == 3 else s[2] == pytest.approx(ref[i][2])


def test_a_line_without_a_usable_estimate_is_flagged_for_what_it_shows():
    # line 9 is out of domain in both directions and carries spikes, line 12 out of
    # domain and normal: only line 9 is flagged, with its reason, and neither is pooled
    rows = _map_rows(n=64, evidence={9: (0.0, 3.0)})
    for r in rows:
        if r["line"] in (9, 12):
            r["in_domain"] = False
    res = pl.pool_groups(rows, CAL_E)
    by = {g["direction"]: g for g in res.groups}
    assert by["trace"]["flagged_lines"] == "9"
    assert by["trace"]["n_lines"] == 62 and by["trace"]["n_left_out"] == 2
    why = {(rows[i]["direction"], rows[i]["line"]): w for i, w in res.reasons.items()}
    assert why == {(d, 9): pl.EVIDENCE_REASON + "spikes" for d in ("trace", "retrace")}
    # without evidence columns such lines are left out and not flagged
    plain = _map_rows(n=64)
    for r in plain:
        if r["line"] in (9, 12):
            r["in_domain"] = False
    assert not pl.pool_groups(plain, CAL_E).reasons


# ---------------------------------------------------------------------------- both directions


def _local_rows(n=64, seed=4238, excess=None, directions=("trace", "retrace")):
    """:func:`_map_rows` with ``excess`` {(direction, line): robust sds} added to the rows'
    local evidence (in units of the normal rows' robust sd, measured), in ``directions``."""
    rows = [r for r in _map_rows(n=n, seed=seed, evidence={}) if r["direction"] in directions]
    for d in directions:
        e = np.array([r["evidence_local"] for r in rows if r["direction"] == d])
        med = float(np.median(e))
        sd = 1.4826 * float(np.median(np.abs(e - med)))
        for r in rows:
            if r["direction"] == d:
                if (d, r["line"]) in (excess or {}):
                    r["evidence_local"] = med + excess[(d, r["line"])] * sd
    return rows


def _why(rows, res):
    """The lines flagged by evidence (the synthetic estimates put a few outside)."""
    return {(rows[i]["direction"], rows[i]["line"]): w for i, w in res.reasons.items()
            if w != pl.OUTLIER_REASON}  # fmt: skip


def test_paired_scores_add_the_two_directions():
    assert pl.paired_scores(3.0, 3.0) == pytest.approx(6.0 / math.sqrt(2.0))
    assert pl.paired_scores(5.0, -5.0) == 0.0
    assert np.isnan(pl.paired_scores(np.nan, 3.0))
    # two independent normal scores: the sum has the spread of one
    rng = np.random.default_rng(4236)
    z = pl.paired_scores(rng.normal(size=20000), rng.normal(size=20000))
    assert np.std(z) == pytest.approx(1.0, abs=0.03)


def test_a_moderate_local_anomaly_in_both_directions_is_flagged_where_one_is_not():
    # line 20 at 3.3 robust sds in both directions, line 30 in the trace only, line 31 in
    # the retrace only; thresholds 4 (one direction) and 4 (both): 20 alone passes
    rows = _local_rows(excess={("trace", 20): 3.3, ("retrace", 20): 3.3,
                               ("trace", 30): 3.3, ("retrace", 31): 3.3})  # fmt: skip
    pz = {(rows[i]["direction"], rows[i]["line"]): z
          for i, z in pl.paired_scores_by_row(rows).items()}  # fmt: skip
    assert pz[("trace", 20)] == pz[("retrace", 20)] > 4.2
    assert max(pz[("trace", 30)], pz[("retrace", 31)]) < 3.5
    res = pl.pool_groups(rows, CAL_E)
    text = pl.EVIDENCE_REASON + pl.EVIDENCE_TEXT[pl.LOCAL_BOTH]
    assert _why(rows, res) == {("trace", 20): text, ("retrace", 20): text}
    by = {g["direction"]: g for g in res.groups}
    assert all("20" in by[d]["flagged_lines"].split() for d in ("trace", "retrace", "both"))
    # the paired threshold is its own: raised above the pair's score, nothing is flagged
    high = dataclasses.replace(CAL_E, evidence_z={**CAL_E.evidence_z, "local_both": 6.0})
    assert not _why(rows, pl.pool_groups(rows, high))
    # a strong anomaly in one direction still shows in the pair (10 sds: 7 in the pair)
    one = _local_rows(excess={("trace", 12): 10.0})
    assert _why(one, pl.pool_groups(one, CAL_E)) == {("trace", 12): text, ("retrace", 12): text}


def test_a_line_seen_in_one_direction_keeps_the_one_direction_rule():
    single = pl.EVIDENCE_REASON + pl.EVIDENCE_TEXT[pl.LOCAL]
    # a map of one direction: 3.3 sds is not flagged, 5 sds is, by the local rule
    rows = _local_rows(excess={("trace", 20): 3.3, ("trace", 40): 5.0}, directions=("trace",))
    res = pl.pool_groups(rows, CAL_E)
    assert _why(rows, res) == {("trace", 40): single}
    assert [g["direction"] for g in res.groups] == ["trace"]
    # the one-direction threshold is the local one, not the paired one
    low = dataclasses.replace(CAL_E, evidence_z={**CAL_E.evidence_z, "local": 3.0})
    assert _why(rows, pl.pool_groups(rows, low)) == {("trace", 20): single,
                                                     ("trace", 40): single}
    # in a map of both directions, a line whose retrace row has no local evidence is
    # judged by its trace row alone
    both = _local_rows(excess={("trace", 40): 5.0, ("retrace", 40): 0.0})
    for r in both:
        if r["direction"] == "retrace" and r["line"] == 40:
            r["evidence_local"] = None
    assert _why(both, pl.pool_groups(both, CAL_E)) == {("trace", 40): single}


def test_change_threshold_batches_draw_the_same_series():
    # the Monte Carlo draws its series in batches, in the order one at a time would
    rng = np.random.default_rng([4299, 40, 3, 4])
    one_by_one = [np.nanmax(pl.change_statistic(rng.standard_normal((40, 3)), 4))
                  for _ in range(300)]  # fmt: skip
    pl.change_threshold.cache_clear()
    assert pl.change_threshold(40, 3, 0.9, 4, reps=300) == pytest.approx(
        float(np.quantile(one_by_one, 0.9)), rel=1e-12)


def test_tabled_change_threshold_matches_the_monte_carlo_between_grid_points():
    table = {"level": 0.99, "min_segment": 4, "n": [64, 128],
             "3": [pl.change_threshold(64, 3, 0.99, 4), pl.change_threshold(128, 3, 0.99, 4)]}
    direct = pl.change_threshold(96, 3, 0.99, 4)
    assert pl._tabled_threshold(table, 96, 3, 0.99, 4) == pytest.approx(direct, rel=0.05)
    # at a grid point exactly the Monte Carlo's; outside the table, or for another
    # level, the Monte Carlo itself
    assert pl._tabled_threshold(table, 64, 3, 0.99, 4) == pl.change_threshold(64, 3, 0.99, 4)
    assert pl._tabled_threshold(table, 40, 3, 0.99, 4) == pl.change_threshold(40, 3, 0.99, 4)
    assert pl._tabled_threshold(table, 96, 3, 0.95, 4) == pl.change_threshold(96, 3, 0.95, 4)


def test_bundled_calibration_tables_the_change_threshold():
    cal = pl.bundled_calibration()
    t = cal.change_table
    assert t["level"] == cal.change_level and t["min_segment"] == cal.min_segment
    assert t["n"][0] <= 8 and t["n"][-1] >= 1024 and {"3", "6"} <= set(t)
    assert np.all(np.diff(t["3"]) > -0.5)  # grows with n, up to the Monte Carlo's noise
