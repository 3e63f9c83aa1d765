"""The window MLPs' training set made from the domain-randomised line-model set."""

import numpy as np
import pytest

from stickslip.estimators.line.ensemble import LineSpec, map_line
from stickslip.estimators.window.randomised import randomised_window_set, split_by_group
from stickslip.traces.dataset import Dataset
from stickslip.units import eta_from

N, REPLICAS = 200, 3


@pytest.fixture(scope="module")
def source() -> Dataset:
    """Hand-made stick-slip-like lines (sawtooth of one lattice period) on many lattices."""
    rng = np.random.default_rng(3)
    x = np.arange(512) * 11.0 / 512
    a = rng.uniform(0.235, 0.335, N)
    U0, K = rng.uniform(0.5, 5.0, N), rng.uniform(2.0, 40.0, N)
    fmax = np.pi * U0 * 0.1602176634 / a
    phase = rng.uniform(0, 1, N)
    force = fmax[:, None] * (2 * ((x[None, :] / a[:, None] + phase[:, None]) % 1.0) - 1) + 0.5
    params = {"U0_eV": U0, "K_N_m": K, "eta": eta_from(U0, K, a), "lattice_nm": a,
              "F_mean_nN": force.mean(axis=1), "velocity_nm_per_s": rng.choice([30.0, 90.0], N),
              "temperature_K": np.full(N, 296.0)}  # fmt: skip
    return Dataset(force.astype(np.float32), x, params, {"config": "{}"})


@pytest.fixture(scope="module")
def windows_set(source) -> Dataset:
    return randomised_window_set(source, replicas=REPLICAS, seed=1)


def _offset(row: np.ndarray, line: np.ndarray) -> int | None:
    """Where ``row`` is a crop of ``line`` (float32 tolerance), or None."""
    for k in range(line.size - row.size + 1):
        if np.allclose(row, line[k : k + row.size], rtol=0, atol=1e-4):
            return k
    return None


def test_labels_move_to_the_reference_frame(source, windows_set):
    p, src = windows_set.params, source.params
    assert windows_set.n == REPLICAS * N
    t = p["trajectory"]
    s = src["lattice_nm"][t] / 0.246
    assert np.array_equal(p["U0_eV"], src["U0_eV"][t] / s)
    assert np.array_equal(p["K_N_m"], src["K_N_m"][t] * s)
    assert np.array_equal(p["F_mean_nN"], src["F_mean_nN"][t])
    assert np.array_equal(p["source_lattice_nm"], src["lattice_nm"][t])
    assert np.all(p["lattice_nm"] == 0.246)
    assert np.allclose(p["eta"], src["eta"][t], rtol=1e-12)  # eta is preserved
    # the reference pixel grid, cut to the shortest mapped line (a = 0.335 nm: ~376 px)
    assert windows_set.x_nm[1] == pytest.approx(11.0 / 512)
    short = int(512 * 0.246 / src["lattice_nm"].max())
    assert windows_set.force_nN.shape == (REPLICAS * N, windows_set.x_nm.size)
    assert abs(windows_set.x_nm.size - short) <= 1


def test_replicas_share_a_group_and_never_straddle_the_split(windows_set):
    p = windows_set.params
    assert np.array_equal(np.bincount(p["trajectory"]), np.full(N, REPLICAS))
    assert np.array_equal(np.sort(p["replica"][p["trajectory"] == 7]), np.arange(REPLICAS))
    train, val = split_by_group(p["trajectory"], 0.2, seed=0)
    assert np.intersect1d(train, val).size == 0
    assert np.array_equal(np.sort(np.concatenate([train, val])), np.arange(windows_set.n))
    assert np.intersect1d(p["trajectory"][train], p["trajectory"][val]).size == 0
    assert np.unique(p["trajectory"][val]).size == round(0.2 * N)
    # a different seed gives a different split
    assert not np.array_equal(split_by_group(p["trajectory"], 0.2, seed=1)[1], val)


def test_clean_fraction_and_corruption(source, windows_set):
    p = windows_set.params
    assert abs(p["clean"].mean() - 0.2) < 0.06
    spec = LineSpec()
    for row in range(0, windows_set.n, 5):
        t = p["trajectory"][row]
        mapped = map_line(source.x_nm, source.force_nN[t].astype(float),
                          source.params["lattice_nm"][t], spec)  # fmt: skip
        found = _offset(windows_set.force_nN[row], mapped)
        if p["clean"][row]:
            assert found is not None  # a crop of the mapped clean line
        else:
            assert found is None  # the detector effects changed the forces
    corrupted = ~p["clean"]
    assert corrupted.sum() > 0.7 * windows_set.n
    # replicas of one trajectory carry independent corruption draws
    t = p["trajectory"]
    a = windows_set.force_nN[(t == 3) & corrupted]
    if a.shape[0] >= 2:
        assert not np.allclose(a[0], a[1])


def test_all_clean_and_explicit_length(source):
    ds = randomised_window_set(source, replicas=1, clean_fraction=1.0, pixels=300, seed=2)
    assert ds.force_nN.shape == (N, 300) and ds.params["clean"].all()
    with pytest.raises(ValueError):
        randomised_window_set(source, replicas=1, pixels=600)
    with pytest.raises(ValueError):
        randomised_window_set(source, replicas=0)
