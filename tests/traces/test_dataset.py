"""In-memory datasets: joining several into one."""

import json

import numpy as np
import pytest

from stickslip.traces.dataset import Dataset, DatasetError, concat_datasets


def _ds(n: int, offset: float, x=None) -> Dataset:
    x = np.arange(5.0) if x is None else x
    return Dataset(np.full((n, x.size), offset), x, {"U0_eV": np.arange(n) + offset},
                   {"config": json.dumps({"seed": int(offset)})})  # fmt: skip


def test_concat_keeps_row_order_and_records_every_config():
    d = concat_datasets([_ds(2, 1.0), _ds(3, 7.0)])
    assert d.n == 5 and d.attrs["n"] == 5
    assert d.force_nN[:, 0].tolist() == [1, 1, 7, 7, 7]
    assert d.params["U0_eV"].tolist() == [1, 2, 7, 8, 9]
    assert [json.loads(c)["seed"] for c in json.loads(d.config_json)] == [1, 7]


def test_concat_refuses_different_grids():
    with pytest.raises(DatasetError):
        concat_datasets([_ds(2, 1.0), _ds(2, 1.0, x=np.arange(6.0))])


def test_concat_on_named_columns_drops_the_others_and_needs_them_everywhere():
    a, b = _ds(2, 1.0), _ds(1, 7.0)
    b.params["mass_kg"] = np.ones(1)
    with pytest.raises(DatasetError):
        concat_datasets([a, b])
    d = concat_datasets([a, b], columns=["U0_eV"])
    assert sorted(d.params) == ["U0_eV"] and d.params["U0_eV"].tolist() == [1, 2, 7]
    with pytest.raises(DatasetError):
        concat_datasets([a, b], columns=["U0_eV", "mass_kg"])
