"""The line-model file: an ensemble of whole-line CNNs with everything inference needs.

Layout (plain types and tensors, read with ``torch.load(weights_only=True)``)::

    format              "stickslip-line-model-1"
    stickslip_version   version of the package that trained it
    spec                LineSpec as a dict (reference lattice, pixel, scales, crop)
    channels            CNN channels
    members             list of state_dicts, one per ensemble member
    y_mean, y_std       target normalisation (training set)
    scale               calibration of the predictive spread: per target, or per class
                        of line and target
    exponent            calibrated std = scale * raw std ** exponent, shaped as scale
                        (absent: 1)
    shape               quantiles of the calibrated |error| / std at SHAPE_LEVELS, per
                        target (absent: Gaussian intervals)
    spread_classes      SpreadClasses as a dict (absent: one scale row for all lines)
    offset_prior        OffsetPrior as a dict: the offsets the single-line <F> interval
                        carries (absent: none)
    compression_prior   CompressionPrior as a dict: the compressions it carries (absent:
                        none)
    friction_factor     (2, k) levels and factors on the model's own <F> half-width in
                        that interval (absent: 1)
    evidence            (n_targets, 1 + n_evidence) coefficients of the std's factor
                        exp(b0 + b . e) on what the line shows (absent: 1)
    evidence_range      (2, n_evidence) the calibration lines' range of the evidence,
                        to which a line's is clipped
    location            (n_targets, 1 + n_inputs) coefficients of the median error
                        taken off the members' mean, c0 + c . u (absent: none)
    location_range      (2, n_targets, n_inputs) the calibration lines' range of u
    train_config        LineTrainConfig as a dict
    dataset             description and fingerprint of the training data
    metrics             validation metrics recorded at training time
    n_expert            expert inputs of each member (0, or absent: none)
    spread_hidden       width of the members' own spread head (0, or absent: none)
    expert              the window-model payload the members read (absent: none)
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
import torch

from stickslip._version import __version__
from stickslip.atomic import atomic_path
from stickslip.estimators.line.ensemble import (
    CALIBRATION_STATE,
    TARGETS,
    LineCNN,
    LineEnsemble,
    LineSpec,
    SpreadClasses,
    n_conditions,
)
from stickslip.estimators.offsets import CompressionPrior, OffsetPrior
from stickslip.estimators.window.modelfile import (
    ModelFileError,
    _major,
    _plain,
    from_payload,
    load_bundled,
    read_payload,
)

FORMAT = "stickslip-line-model-1"
BUNDLED = "line_model.pt"


def _state_payload(state: dict[str, np.ndarray | None]) -> dict[str, torch.Tensor]:
    """A spread calibration's fields as stored (:data:`CALIBRATION_STATE`); one left
    out is absent: a plain scale, Gaussian intervals, no factor on the <F> model part."""
    return {k: torch.as_tensor(np.asarray(v, np.float64)) for k, v in state.items()
            if v is not None}  # fmt: skip


def _state_from(stored: dict[str, Any]) -> dict[str, np.ndarray | None]:
    """The fields :func:`_state_payload` stored (``scale`` required: KeyError)."""
    return {k: stored[k].numpy() if k in stored or k == "scale" else None
            for k in CALIBRATION_STATE}  # fmt: skip


def save_line_model(ens: LineEnsemble, path: str | os.PathLike, channels: tuple[int, ...],
                    train_config: dict, dataset: dict, metrics: dict) -> Path:  # fmt: skip
    """Write the ensemble and its provenance atomically; returns the path."""
    payload: dict[str, Any] = {
        "format": FORMAT,
        "stickslip_version": __version__,
        "spec": ens.spec.to_dict(),
        "channels": list(channels),
        "members": [{k: v.detach().cpu() for k, v in m.state_dict().items()}
                    for m in ens.members],  # fmt: skip
        "y_mean": torch.as_tensor(np.asarray(ens.y_mean, np.float64)),
        "y_std": torch.as_tensor(np.asarray(ens.y_std, np.float64)),
        **_state_payload(ens.calibration_state()),
        "train_config": _plain(train_config),
        "dataset": _plain(dataset),
        "metrics": _plain(metrics),
    }
    payload["spread_hidden"] = ens.members[0].spread_hidden
    if ens.contact_calibrations:
        payload["contact_calibrations"] = {name: _state_payload(state) for name, state
                                           in ens.contact_calibrations.items()}  # fmt: skip
    if ens.classes is not None:
        payload["spread_classes"] = _plain(ens.classes.to_dict())
    if ens.offset is not None:
        payload["offset_prior"] = _plain(ens.offset.to_dict())
    if ens.compression is not None:
        payload["compression_prior"] = _plain(ens.compression.to_dict())
    if ens.expert is not None:
        payload["n_expert"] = ens.members[0].n_expert
        payload["expert"] = ens.expert.to_payload()
    path = Path(path)
    with atomic_path(path) as tmp:
        torch.save(payload, tmp)
    return path


def line_from_payload(payload: Any, name: str) -> LineEnsemble:
    """Rebuild a :class:`LineEnsemble` from a loaded payload, checking its format."""
    made_by = str(payload.get("stickslip_version", "unknown"))
    if payload.get("format") != FORMAT or _major(made_by) != _major(__version__):
        raise ModelFileError(
            f"{name}: model format '{payload.get('format')}' from stickslip {made_by} cannot "
            f"be read by stickslip {__version__} ({FORMAT})"
        )
    try:
        spec = LineSpec(**payload["spec"])
        classes = None
        if "spread_classes" in payload:
            classes = SpreadClasses.from_dict(payload["spread_classes"])
        expert = None
        if "expert" in payload:
            expert = from_payload(payload["expert"], f"{name} (expert)")
        members = []
        for sd in payload["members"]:
            net = LineCNN(channels=tuple(payload["channels"]), n_targets=len(TARGETS),
                          n_cond=n_conditions(spec), n_expert=int(payload.get("n_expert", 0)),
                          spread_hidden=int(payload.get("spread_hidden", 0)))  # fmt: skip
            net.load_state_dict(sd)
            net.eval()
            members.append(net)
        return LineEnsemble(
            members=members,
            spec=spec,
            y_mean=payload["y_mean"].numpy(),
            y_std=payload["y_std"].numpy(),
            expert=expert,
            classes=classes,
            **_state_from(payload),
            offset=(OffsetPrior.from_dict(payload["offset_prior"])
                    if "offset_prior" in payload else None),  # fmt: skip
            compression=(CompressionPrior.from_dict(payload["compression_prior"])
                         if "compression_prior" in payload else None),  # fmt: skip
            contact_calibrations={name: _state_from(state) for name, state
                                  in payload.get("contact_calibrations", {}).items()},
        )
    except (KeyError, TypeError, ValueError, RuntimeError, AttributeError) as e:
        reason = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise ModelFileError(f"{name}: damaged model file ({reason})") from None


def line_metadata(path: str | os.PathLike) -> dict:
    """Training config, data description and metrics stored in a line-model file."""
    p = torch.load(path, map_location="cpu", weights_only=True)
    return {k: p.get(k) for k in ("train_config", "dataset", "metrics", "stickslip_version")}


def load_line_model(path: str | os.PathLike | None = None) -> LineEnsemble:
    """Load a line-model file, or the bundled one when ``path`` is None.

    Raises
    ------
    ModelFileError
        One line: missing, corrupt, not a line model, or from an incompatible version.
    """
    if path is None:
        return load_bundled(BUNDLED, load_line_model)
    p = Path(path)
    return line_from_payload(read_payload(p), str(p))
