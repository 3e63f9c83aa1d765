"""Network architectures, built from a plain ``arch`` dict stored in the model file.

``arch = {"name": "mlp", "hidden": [256, 128]}`` is the reference paper's MLP: two
hidden layers with ReLU and a linear head, one output per target. Other architectures
(sequence encoders, uncertainty heads) register a builder in :data:`ARCHITECTURES`
with the same signature ``builder(n_inputs, n_outputs, **options) -> torch.nn.Module``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from torch import nn

PAPER_MLP: dict[str, Any] = {"name": "mlp", "hidden": [256, 128]}


def build_mlp(n_inputs: int, n_outputs: int, hidden: Sequence[int] = (256, 128)) -> nn.Module:
    """Multilayer perceptron: ``Linear -> ReLU`` per hidden layer, then a linear head."""
    layers: list[nn.Module] = []
    width = n_inputs
    for h in hidden:
        layers += [nn.Linear(width, int(h)), nn.ReLU()]
        width = int(h)
    layers.append(nn.Linear(width, n_outputs))
    return nn.Sequential(*layers)


ARCHITECTURES: dict[str, Callable[..., nn.Module]] = {"mlp": build_mlp}


def build_model(arch: dict[str, Any], n_inputs: int, n_outputs: int) -> nn.Module:
    """Instantiate the architecture described by ``arch`` (``name`` plus its options).

    Raises
    ------
    ValueError
        If the name is not registered.
    """
    options = {k: v for k, v in arch.items() if k != "name"}
    name = arch.get("name")
    if name not in ARCHITECTURES:
        raise ValueError(f"unknown architecture '{name}' (have: {', '.join(ARCHITECTURES)})")
    return ARCHITECTURES[name](n_inputs, n_outputs, **options)


def count_parameters(model: nn.Module) -> int:
    """Number of trainable parameters."""
    return sum(p.numel() for p in model.parameters() if p.requires_grad)


__all__ = ["ARCHITECTURES", "PAPER_MLP", "build_mlp", "build_model", "count_parameters"]
