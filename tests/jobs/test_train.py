"""Training data: labelled traces mapped onto the reference, mixing fractions, and the
bundled recipe's data (cached, streamed from disk)."""

from __future__ import annotations

import numpy as np
import pytest

from stickslip.conditions import GRAPHITE
from stickslip.jobs.train import (
    BundledRecipe,
    TrainingData,
    TrainingDataError,
    bundled_line_data,
    labelled_dataset,
    mix_in,
)
from stickslip.simulators import PhysicalSettings, simulate
from stickslip.traces.dataset import Dataset, Rows, load_dataset
from stickslip.traces.trace import Trace


@pytest.fixture(scope="module")
def mos2():
    r = simulate([2.0, 3.0], [15.0, 20.0], PhysicalSettings(lattice_nm=0.316), seed=5)
    return [Trace(r.x_nm, r.force_nN[i], f"m{i}", "m.csv", {"lattice_nm": 0.316})
            for i in range(2)]  # fmt: skip


def test_labelled_traces_are_mapped_with_their_labels(mos2):
    labels = {"m0": {"U0_eV": 2.0, "K_N_m": 15.0, "F_mean_nN": 1.0}, "m1": {"U0_eV": 3.0}}
    notes = []
    d = labelled_dataset(mos2, labels, GRAPHITE, pixels=400, echo=notes.append)
    s = 0.316 / GRAPHITE.lattice_nm
    # m1 has no K: left out, and said so
    assert d.n == 1 and notes and "1 labelled-set trace" in notes[0]
    assert d.params["U0_eV"][0] == pytest.approx(2.0 / s)
    assert d.params["K_N_m"][0] == pytest.approx(15.0 * s)
    # eta is invariant under the mapping
    assert d.params["eta"][0] == pytest.approx(52.26 * 2.0 / 15.0 * GRAPHITE.lattice_nm**2
                                               / 0.316**2 * 0.246**2 / 0.246**2, rel=1e-3)
    assert d.force_nN.shape == (1, 400)
    np.testing.assert_allclose(np.diff(d.x_nm), GRAPHITE.pixel_nm)
    with pytest.raises(TrainingDataError):
        labelled_dataset(mos2, {}, GRAPHITE)


def test_mixing_reaches_the_asked_fraction():
    def ds(n, value):
        return Dataset(np.full((n, 8), value, np.float32), np.arange(8.0),
                       {"U0_eV": np.full(n, value), "K_N_m": np.ones(n)}, {"config": "{}"})

    mixed = mix_in(TrainingData(ds(990, 0.0)), ds(3, 1.0), 0.01)
    real = np.count_nonzero(mixed.data.params["U0_eV"] == 1.0)
    assert mixed.data.n == 1000 and real == 10
    with pytest.raises(TrainingDataError):
        mix_in(TrainingData(ds(10, 0.0)), ds(3, 1.0), 1.5)


@pytest.mark.slow
def test_bundled_recipe_data_stays_on_disk_and_records_its_parts(tmp_path):
    recipe = BundledRecipe(n=6, seeds=(11, 12), typical=4, paper=4, paper_seed=5)
    training = bundled_line_data(tmp_path, recipe, progress=False)
    d = training.data
    assert d.n == 6 + 6 + 4 + 4 and isinstance(d.force_nN, Rows)  # streamed, not loaded
    assert len(training.parts) == 4 and all(p["fingerprint"] for p in training.parts)
    from stickslip.simulators.randomised import RandomisedConfig, cache_path

    # the recipe randomises the dynamics: the set's file carries its config's digest
    config = recipe.prior(RandomisedConfig(n=6, seed=11))
    assert config.log_fraction == recipe.log_fraction
    first = load_dataset(cache_path(config, tmp_path))
    assert np.ptp(first.params["temperature_K"]) > 0
    np.testing.assert_array_equal(d.force_nN[:6], first.force_nN)
    # a second call reuses the cached sets
    again = bundled_line_data(tmp_path, recipe, progress=False)
    assert [p["fingerprint"] for p in again.parts] == [p["fingerprint"] for p in training.parts]


def test_bundled_recipe_prior_carries_its_draw_of_barriers():
    from stickslip.simulators.randomised import RandomisedConfig

    base = RandomisedConfig(n=6, seed=11)
    assert BundledRecipe().prior(base).log_fraction == 0.0  # the bundled model's: uniform
    assert BundledRecipe(log_fraction=0.5).prior(base).log_fraction == 0.5
    # the dynamics are randomised either way
    assert BundledRecipe(log_fraction=0.5).prior(base).damping_factor != base.damping_factor
