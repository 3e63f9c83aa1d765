"""Draws of domain-randomised training sets (no simulation needed), and their cache."""

import json

import numpy as np

from stickslip.simulators.bench import BenchConfig
from stickslip.simulators.config import LAB_SUBSTRATE
from stickslip.simulators.randomised import (
    A_REF_NM,
    RandomisedConfig,
    cache_path,
    cached_randomised_set,
    draw_randomised,
    lab_config,
)
from stickslip.traces.dataset import Rows
from stickslip.units import eta_from


def test_reference_fraction_puts_lines_exactly_on_the_reference_lattice():
    cfg = RandomisedConfig(n=4000, seed=7, reference_fraction=0.3)
    t, _ = draw_randomised(cfg)
    on_ref = t["lattice_nm"] == A_REF_NM
    assert abs(on_ref.mean() - 0.3) < 0.03
    lo, hi = cfg.lattice_nm
    assert np.all((t["lattice_nm"][~on_ref] >= lo) & (t["lattice_nm"][~on_ref] <= hi))
    # eta is drawn in the reference frame and kept when a line moves to another lattice
    assert np.all((t["eta"] >= cfg.ranges.eta[0] * 0.999) & (t["eta"] <= cfg.ranges.eta[1] * 1.001))
    assert np.allclose(t["eta"], eta_from(t["U0_eV"], t["K_N_m"], t["lattice_nm"]))


def test_reference_fraction_leaves_the_other_draws_unchanged():
    a, _ = draw_randomised(RandomisedConfig(n=500, seed=3, reference_fraction=0.0))
    b, _ = draw_randomised(RandomisedConfig(n=500, seed=3, reference_fraction=0.4))
    moved = b["lattice_nm"] != a["lattice_nm"]
    assert 0.3 < moved.mean() < 0.5
    for k in ("K_N_m", "velocity_nm_per_s", "mod_amplitude", "defect_count"):
        assert np.array_equal(a[k], b[k])
    assert np.array_equal(a["U0_eV"][~moved], b["U0_eV"][~moved])


def test_clean_fraction_gives_flat_substrates():
    t, sub = draw_randomised(RandomisedConfig(n=2000, seed=11, clean_fraction=0.25))
    flat = (t["mod_amplitude"] == 0) & (t["defect_count"] == 0)
    assert 0.2 < flat.mean() < 0.35
    assert np.all(sub.defect_height[flat] == 0)


def test_config_round_trips_through_json():
    cfg = RandomisedConfig(n=10, seed=1)
    assert json.loads(cfg.to_json())["reference_fraction"] == cfg.reference_fraction


def test_config_read_back_from_json_including_older_files():
    cfg = RandomisedConfig(n=10, seed=1)
    assert RandomisedConfig.from_json(cfg.to_json()) == cfg
    old = json.loads(cfg.to_json())
    del old["reference_fraction"]  # a file written before the field existed
    back = RandomisedConfig.from_json(json.dumps(old))
    assert back.reference_fraction == 0.0 and back.ranges == cfg.ranges


def test_lab_config_draws_every_line_on_the_laboratory_substrate():
    cfg = lab_config(400, 9)
    assert cfg.substrate == LAB_SUBSTRATE == BenchConfig().substrate
    table, sub = draw_randomised(cfg)
    lo, hi = LAB_SUBSTRATE.modulation_amplitude
    assert np.all((table["mod_amplitude"] > lo) & (table["mod_amplitude"] <= hi))
    assert table["defect_count"].max() == LAB_SUBSTRATE.defects_per_line[1]
    assert np.all(np.abs(sub.defect_height) <= LAB_SUBSTRATE.defect_height[1])
    # the training sets' parameters, lattices and velocities
    broad, _ = draw_randomised(RandomisedConfig(n=400, seed=9))
    for k in ("U0_eV", "K_N_m", "lattice_nm", "velocity_nm_per_s"):
        np.testing.assert_array_equal(table[k], broad[k])


def test_cache_path_keeps_sets_of_other_settings_apart():
    plain = cache_path(RandomisedConfig(n=400, seed=9), "w")
    assert plain.name == "randomised_400_9.h5"  # the training sets' names stay as they were
    others = {cache_path(c, "w") for c in (lab_config(400, 9),
                                           RandomisedConfig(n=400, seed=9, reference_fraction=0.0))}
    assert plain not in others and len(others) == 2
    assert all(p.name.startswith("randomised_400_9_") for p in others)
    assert cache_path(lab_config(400, 9), "w") == cache_path(lab_config(400, 9), "w")


def test_cached_set_is_simulated_once_and_can_stay_on_disk(tmp_path):
    cfg = RandomisedConfig(n=3, seed=13, length_nm=1.0, pixels=32, chunk=2)
    loaded = cached_randomised_set(cfg, tmp_path, progress=False)
    path = cache_path(cfg, tmp_path)
    stamp = path.stat().st_mtime_ns
    lazy = cached_randomised_set(cfg, tmp_path, progress=False, lazy=True)
    assert path.stat().st_mtime_ns == stamp  # reused, not simulated again
    assert isinstance(lazy.force_nN, Rows) and not isinstance(loaded.force_nN, Rows)
    np.testing.assert_array_equal(np.asarray(lazy.force_nN), loaded.force_nN)
    np.testing.assert_array_equal(lazy.params["K_N_m"], loaded.params["K_N_m"])


def test_dynamics_prior_draws_in_its_ranges_and_leaves_the_other_draws_unchanged():
    from stickslip.simulators.config import PhysicalSettings
    from stickslip.simulators.randomised import DYNAMICS_PRIOR, VELOCITY_STEPS, with_dynamics

    base = RandomisedConfig(n=3000, seed=5)
    a, _ = draw_randomised(base)
    b, _ = draw_randomised(with_dynamics(base))
    for k in ("U0_eV", "K_N_m", "lattice_nm", "mod_amplitude", "defect_count"):
        assert np.array_equal(a[k], b[k])
    preset = PhysicalSettings()
    # the preset's dynamics without the prior
    assert np.all(a["damping_per_s"] == preset.damping_per_s)
    assert np.all(a["mass_kg"] == preset.mass_kg)
    assert np.all(a["temperature_K"] == base.temperature_K)
    v_lo, v_hi = DYNAMICS_PRIOR["velocity_range"]
    v = b["velocity_nm_per_s"]
    assert np.unique(v).size == VELOCITY_STEPS
    assert v.min() == v_lo and v.max() == v_hi
    # log-uniform: as many lines below the geometric middle as above it
    assert abs(np.mean(v < np.sqrt(v_lo * v_hi)) - 0.5) < 0.05
    T_lo, T_hi = DYNAMICS_PRIOR["temperature_range_K"]
    assert T_lo <= b["temperature_K"].min() and b["temperature_K"].max() <= T_hi
    for k, name in (("damping_per_s", "damping_factor"), ("mass_kg", "mass_factor")):
        lo, hi = DYNAMICS_PRIOR[name]
        f = b[k] / getattr(preset, k)
        assert lo * 0.999 <= f.min() < lo * 1.2 and hi / 1.2 < f.max() <= hi * 1.001
        assert abs(np.mean(f < np.sqrt(lo * hi)) - 0.5) < 0.05


def test_dynamics_config_round_trips_and_gets_its_own_cache_file(tmp_path):
    from stickslip.simulators.randomised import with_dynamics

    cfg = with_dynamics(RandomisedConfig(n=10, seed=1))
    assert RandomisedConfig.from_json(cfg.to_json()) == cfg
    assert cache_path(cfg, tmp_path) != cache_path(RandomisedConfig(n=10, seed=1), tmp_path)


def test_log_fraction_draws_soft_contacts_evenly_in_their_logarithm():
    uniform, _ = draw_randomised(RandomisedConfig(n=4000, seed=5))
    log, _ = draw_randomised(RandomisedConfig(n=4000, seed=5, log_fraction=1.0))
    lo, hi = RandomisedConfig().ranges.K_N_m
    # a uniform draw leaves few soft contacts; log-uniform gives each decade its share
    # (less what the eta window cuts off at the box's corners)
    assert (uniform["K_N_m"] < 5).mean() < 0.1
    assert (log["K_N_m"] < 5).mean() > 0.3
    for t in (uniform, log):
        assert np.all((t["K_N_m"] >= lo) & (t["K_N_m"] <= hi))
        assert np.all((t["eta"] >= 1.2 * 0.999) & (t["eta"] <= 42.0 * 1.001))
    # the log-drawn values are not the uniform ones transformed: a stream of their own
    assert np.corrcoef(np.log(uniform["K_N_m"]), np.log(log["K_N_m"]))[0, 1] < 0.1


def test_log_fraction_mixes_the_two_draws_and_keeps_the_digest_of_older_sets():
    half, _ = draw_randomised(RandomisedConfig(n=4000, seed=5, log_fraction=0.5))
    assert 0.15 < (half["K_N_m"] < 5).mean() < 0.3
    # a config without the field serialises as before, so older sets keep their file
    cfg = RandomisedConfig(n=10, seed=1)
    assert "log_fraction" not in json.loads(cfg.to_json())
    mixed = RandomisedConfig(n=10, seed=1, log_fraction=0.5)
    assert RandomisedConfig.from_json(mixed.to_json()) == mixed
    assert cache_path(mixed, "w") != cache_path(cfg, "w")
