"""Loading an estimator by name or file: the model file knows its kind.

``load_estimator(None)`` (or ``"default"``) is the bundled whole-line model, the one
default of every command; ``"classical"`` the classical estimator; ``"window"`` (or
``"paper"``) the bundled paper window MLP; anything else a model file, dispatched on
the ``format`` it stores.
"""

from __future__ import annotations

import copy
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

from stickslip.estimators.base import Estimator
from stickslip.estimators.classical.estimator import ClassicalEstimator
from stickslip.estimators.line.ensemble import ANY_CONTACT, CONTACTS
from stickslip.estimators.line.estimator import LineEstimator
from stickslip.estimators.line.modelfile import FORMAT as LINE_FORMAT
from stickslip.estimators.line.modelfile import line_from_payload, load_line_model
from stickslip.estimators.window.estimator import WindowEstimator
from stickslip.estimators.window.modelfile import FORMAT as WINDOW_FORMAT
from stickslip.estimators.window.modelfile import (
    ModelFileError,
    from_payload,
    load_model,
    read_payload,
)

DEFAULT = "default"
CLASSICAL = "classical"
WINDOW_NAMES = ("window", "paper", "window-pi")
NAMES = (DEFAULT, CLASSICAL, *WINDOW_NAMES)

# the model-file kinds: format string -> (payload -> estimator)
KINDS: dict[str, Callable[[dict[str, Any], str], Estimator]] = {
    LINE_FORMAT: lambda payload, name: LineEstimator(line_from_payload(payload, name), name),
    WINDOW_FORMAT: lambda payload, name: WindowEstimator(from_payload(payload, name), name),
}


def load_estimator(spec: str | os.PathLike | None = None) -> Estimator:
    """An estimator from a name or a model file.

    Parameters
    ----------
    spec : str or path-like, optional
        None or ``"default"``: the bundled whole-line model; ``"classical"``; ``"window"``
        / ``"paper"``: the bundled paper MLP (pi input); else a model file from
        ``stickslip train``, of any kind.

    Raises
    ------
    ModelFileError
        One line: missing, unreadable, or not a stickslip model file.
    """
    name = None if spec is None else str(spec)
    if name in (None, DEFAULT):
        return LineEstimator(load_line_model(None), "bundled")
    if name == CLASSICAL:
        return ClassicalEstimator()
    if name in WINDOW_NAMES and not Path(name).exists():
        return WindowEstimator(load_model(None), "bundled")
    payload = read_payload(Path(name))
    kind = KINDS.get(str(payload.get("format")))
    if kind is None:
        raise ModelFileError(f"{name}: model format '{payload.get('format')}' is not one of "
                             f"{', '.join(KINDS)}")  # fmt: skip
    return kind(payload, name)


def state_zero_offset(estimator: Estimator, zero_offset: bool) -> Estimator:
    """A copy of ``estimator`` told that the lateral force's zero carries no offset
    (:attr:`LineEstimator.zero_offset`; False changes nothing).

    Raises
    ------
    ValueError
        One line: an estimator without an <F> interval that carries an offset term (only
        the line model's does).
    """
    if not zero_offset:
        return estimator
    if not isinstance(estimator, LineEstimator):
        raise ValueError(f"--zero-offset: the {estimator.name} estimator's <F> interval "
                         "carries no offset term to drop; the line model's (the default) "
                         "does")  # fmt: skip
    stated = copy.copy(estimator)  # the caller's estimator keeps its own setting
    stated.zero_offset = True
    return stated


def state_contact(estimator: Estimator, contact: str) -> Estimator:
    """A copy of ``estimator`` told the contact the user states
    (:data:`~stickslip.estimators.line.ensemble.CONTACTS`; ``"any"`` changes nothing).

    Raises
    ------
    ValueError
        One line: an estimator without a calibration per contact (only the line model
        has them), or a contact its model file holds no calibration of.
    """
    if contact not in CONTACTS:
        raise ValueError(f"--contact must be one of {', '.join(CONTACTS)} (got '{contact}')")
    if contact == ANY_CONTACT:
        return estimator
    if not isinstance(estimator, LineEstimator):
        raise ValueError(f"--contact {contact}: the {estimator.name} estimator has one "
                         "calibration for any contact; the line model (the default) has one "
                         "per stated contact")  # fmt: skip
    estimator.ensemble.for_contact(contact)  # raises for a contact the file lacks
    stated = copy.copy(estimator)  # the caller's estimator keeps its own setting
    stated.contact = contact
    return stated
