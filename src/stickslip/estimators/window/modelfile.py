"""The model file: weights plus everything ``infer`` needs, in one torch file.

Layout (a dict of plain types and tensors, so ``torch.load(weights_only=True)`` reads it)::

    format              "stickslip-model-1"
    stickslip_version   version of the package that trained it
    state_dict          network weights
    arch                {"name": "mlp", "hidden": [256, 128]}
    features            FeatureSpec as a dict (recipe, window, strides, pixel, lattice ...)
    normalisation       {"x_mean", "x_std", "y_mean", "y_std"} tensors (training set)
    targets             ["F_mean_nN", "U0_eV", "K_N_m"]
    transforms          per target "linear" or "log" (the network's output space)
    train_config        TrainConfig as a dict
    dataset_fingerprint content hash of the training dataset
    metrics             held-out metrics recorded at training time
"""

from __future__ import annotations

import os
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from stickslip._version import __version__
from stickslip.atomic import atomic_path
from stickslip.estimators.window.features import FeatureError, FeatureSpec
from stickslip.estimators.window.models import build_model

FORMAT = "stickslip-model-1"


class ModelFileError(Exception):
    """A model file that cannot be used; ``str()`` is one line naming the file."""


@dataclass
class TrainedModel:
    """A network with its input recipe, normalisation and provenance."""

    net: torch.nn.Module
    features: FeatureSpec
    normalisation: dict[str, np.ndarray]
    targets: list[str]
    transforms: dict[str, str]
    arch: dict[str, Any]
    train_config: dict[str, Any] = field(default_factory=dict)
    dataset_fingerprint: str = ""
    metrics: dict[str, Any] = field(default_factory=dict)
    stickslip_version: str = __version__

    def to_payload(self) -> dict[str, Any]:
        """The dict written to disk (plain types and tensors only)."""
        return {
            "format": FORMAT,
            "stickslip_version": self.stickslip_version,
            "state_dict": {k: v.detach().cpu() for k, v in self.net.state_dict().items()},
            "arch": dict(self.arch),
            "features": self.features.to_dict(),
            "normalisation": {
                k: torch.as_tensor(np.asarray(v, dtype=np.float32))
                for k, v in self.normalisation.items()
            },
            "targets": list(self.targets),
            "transforms": dict(self.transforms),
            "train_config": dict(self.train_config),
            "dataset_fingerprint": self.dataset_fingerprint,
            "metrics": _plain(self.metrics),
        }


def _plain(obj: Any) -> Any:
    """Nested dicts/lists of numpy scalars -> plain Python (safe for weights_only)."""
    if isinstance(obj, dict):
        return {str(k): _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    return obj


def save_model(model: TrainedModel, path: str | os.PathLike) -> Path:
    """Write the model file atomically; returns its path."""
    path = Path(path)
    with atomic_path(path) as tmp:
        torch.save(model.to_payload(), tmp)
    return path


def _major(version: str) -> str:
    return str(version).split(".")[0]


def from_payload(payload: Any, name: str) -> TrainedModel:
    """Rebuild a :class:`TrainedModel` from a loaded payload, checking its format."""
    if not isinstance(payload, dict) or "format" not in payload:
        raise ModelFileError(f"{name}: not a stickslip model file")
    made_by = payload.get("stickslip_version", "unknown")
    if payload["format"] != FORMAT or _major(made_by) != _major(__version__):
        raise ModelFileError(
            f"{name}: model format '{payload['format']}' from stickslip {made_by} cannot be "
            f"read by stickslip {__version__} ({FORMAT}); retrain it with 'stickslip train'"
        )
    try:
        spec = FeatureSpec.from_dict(payload["features"])
        targets = [str(t) for t in payload["targets"]]
        norm = {k: v.numpy().astype(np.float32) for k, v in payload["normalisation"].items()}
        net = build_model(payload["arch"], spec.n_inputs, len(targets))
        net.load_state_dict(payload["state_dict"])
    except (KeyError, TypeError, ValueError, RuntimeError, AttributeError, FeatureError) as e:
        reason = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise ModelFileError(f"{name}: damaged model file ({reason})") from None
    net.eval()
    return TrainedModel(
        net=net,
        features=spec,
        normalisation=norm,
        targets=targets,
        transforms=dict(payload.get("transforms", {})),
        arch=dict(payload["arch"]),
        train_config=dict(payload.get("train_config", {})),
        dataset_fingerprint=str(payload.get("dataset_fingerprint", "")),
        metrics=dict(payload.get("metrics", {})),
        stickslip_version=str(made_by),
    )


def load_model(path: str | os.PathLike | None = None) -> TrainedModel:
    """Load a model file, or the bundled default model when ``path`` is None.

    Raises
    ------
    ModelFileError
        One line: missing, corrupt, not a model file, or from an incompatible version.
    """
    if path is None:
        return load_bundled(DEFAULT_MODEL_NAME, load_model)
    p = Path(path)
    return from_payload(read_payload(p), str(p))


def load_bundled(name: str, loader: Any) -> Any:
    """``loader(path)`` on the model file ``name`` shipped in ``stickslip/resources``."""
    from importlib.resources import as_file, files

    ref = files("stickslip").joinpath("resources", name)
    if not ref.is_file():
        raise ModelFileError(f"the bundled model {name} is missing from this installation")
    with as_file(ref) as p:
        return loader(p)


def read_payload(path: str | os.PathLike) -> dict[str, Any]:
    """The dict stored in a model file (any kind), or a one-line :class:`ModelFileError`."""
    p = Path(path)
    if not p.is_file():
        raise ModelFileError(f"{p}: model file not found")
    if not zipfile.is_zipfile(p):
        raise ModelFileError(f"{p}: unreadable model file (not a torch archive: damaged or "
                             "not a model)")  # fmt: skip
    try:
        payload = torch.load(p, map_location="cpu", weights_only=True)
    except Exception as e:  # torch raises many types for a damaged file
        reason = str(e).splitlines()[0][:120] if str(e) else type(e).__name__
        raise ModelFileError(f"{p}: unreadable model file ({reason})") from None
    if not isinstance(payload, dict) or "format" not in payload:
        raise ModelFileError(f"{p}: not a stickslip model file")
    return payload


DEFAULT_MODEL_NAME = "default_model.pt"
