"""Model file: round trip, and one-line errors for corrupt or foreign files."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from stickslip.estimators.window.features import FeatureSpec
from stickslip.estimators.window.modelfile import (
    ModelFileError,
    TrainedModel,
    load_model,
    save_model,
)
from stickslip.estimators.window.models import PAPER_MLP, build_model, count_parameters


def _model(recipe: str = "pi") -> TrainedModel:
    spec = FeatureSpec(recipe=recipe, window=16, stride=16)
    torch.manual_seed(0)
    net = build_model(PAPER_MLP, spec.n_inputs, 3)
    rng = np.random.default_rng(0)
    norm = {
        "x_mean": rng.normal(size=spec.n_inputs), "x_std": rng.random(spec.n_inputs) + 0.5,
        "y_mean": np.array([1.0, 0.5, 2.0]), "y_std": np.array([0.3, 0.8, 0.9]),
    }  # fmt: skip
    return TrainedModel(net=net, features=spec, normalisation=norm,
                        targets=["F_mean_nN", "U0_eV", "K_N_m"],
                        transforms={"F_mean_nN": "linear", "U0_eV": "log", "K_N_m": "log"},
                        arch=dict(PAPER_MLP), train_config={"epochs": 3, "log_targets": ["U0_eV"]},
                        dataset_fingerprint="abc",
                        metrics={"val": {"rmse": np.float64(0.1)}})  # fmt: skip


def test_paper_mlp_shape():
    net = build_model(PAPER_MLP, 127, 3)
    assert count_parameters(net) == 127 * 256 + 256 + 256 * 128 + 128 + 128 * 3 + 3
    with pytest.raises(ValueError, match="unknown architecture"):
        build_model({"name": "transformer"}, 10, 3)


def test_round_trip(tmp_path):
    m = _model()
    path = save_model(m, tmp_path / "m.pt")
    back = load_model(path)
    assert back.features == m.features and back.targets == m.targets
    assert back.transforms == m.transforms and back.dataset_fingerprint == "abc"
    assert back.metrics["val"]["rmse"] == pytest.approx(0.1)
    x = torch.randn(4, m.features.n_inputs)
    with torch.inference_mode():
        np.testing.assert_allclose(back.net(x).numpy(), m.net(x).numpy(), rtol=1e-6)
    for k, v in m.normalisation.items():
        np.testing.assert_allclose(back.normalisation[k], v, rtol=1e-6)
    # a plain weights-only load works: no pickled objects inside
    payload = torch.load(path, weights_only=True)
    assert payload["format"] == "stickslip-model-1"


def _one_line(e: pytest.ExceptionInfo) -> str:
    text = str(e.value)
    assert "\n" not in text
    return text


def test_corrupt_and_missing_files(tmp_path):
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"\x00not a torch file" * 10)
    with pytest.raises(ModelFileError) as e:
        load_model(bad)
    assert "unreadable model file" in _one_line(e)
    good = save_model(_model(), tmp_path / "good.pt")
    cut = tmp_path / "cut.pt"
    cut.write_bytes(good.read_bytes()[:2000])
    with pytest.raises(ModelFileError) as e:
        load_model(cut)
    _one_line(e)
    with pytest.raises(ModelFileError, match="not found"):
        load_model(tmp_path / "nope.pt")
    other = tmp_path / "other.pt"
    torch.save({"weights": torch.zeros(3)}, other)
    with pytest.raises(ModelFileError, match="not a stickslip model"):
        load_model(other)


def test_other_version_and_damaged_payload(tmp_path):
    payload = _model().to_payload()
    torch.save({**payload, "format": "stickslip-model-0", "stickslip_version": "0.0.1"},
               tmp_path / "old.pt")  # fmt: skip
    with pytest.raises(ModelFileError) as e:
        load_model(tmp_path / "old.pt")
    assert "retrain" in _one_line(e)
    torch.save({**payload, "stickslip_version": "9.0.0"}, tmp_path / "future.pt")
    with pytest.raises(ModelFileError, match="9.0.0"):
        load_model(tmp_path / "future.pt")
    broken = dict(payload)
    broken["state_dict"] = {k: v[..., :1] for k, v in payload["state_dict"].items()}
    torch.save(broken, tmp_path / "broken.pt")
    with pytest.raises(ModelFileError) as e:
        load_model(tmp_path / "broken.pt")
    assert "damaged" in _one_line(e)
