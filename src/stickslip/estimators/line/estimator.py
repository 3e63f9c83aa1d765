"""The whole-line CNN ensemble behind the one estimator interface."""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import replace
from importlib import resources
from typing import Any

import numpy as np

from stickslip.conditions import Conditions
from stickslip.estimators import domain
from stickslip.estimators.base import TraceEstimator
from stickslip.estimators.classical.estimator import (
    K_REFUSED,
    QUALITY,
    STATUS,
    estimate_array,
)
from stickslip.estimators.domain import ETA_EDGE, EmbeddingReference
from stickslip.estimators.evidence import EVIDENCE_COLUMNS, LOCAL_COLUMN
from stickslip.estimators.line.ensemble import (
    ANY_CONTACT,
    LineEnsemble,
    LinePrediction,
    predict_raw_lines,
)
from stickslip.estimators.mapping import refusal
from stickslip.estimators.table import BOUNDS, OK, TARGETS
from stickslip.traces.trace import Trace

#: The bundled model's embedding reference (``benchmarks/domain.py --write-reference``).
DOMAIN_REFERENCE = "line_domain.npz"


def fingerprint(ens: LineEnsemble) -> str:
    """A digest of the members' weights: names the model an embedding reference is for."""
    h = hashlib.sha256()
    for m in ens.members:
        for name, tensor in sorted(m.state_dict().items()):
            h.update(name.encode())
            h.update(tensor.detach().cpu().numpy().tobytes())
    return h.hexdigest()[:16]


def bundled_reference() -> EmbeddingReference | None:
    """The embedding reference shipped with the package (None if it is missing)."""
    path = resources.files("stickslip") / "resources" / DOMAIN_REFERENCE
    if not path.is_file():
        return None
    with resources.as_file(path) as p:
        return EmbeddingReference.load(p)


def pooled_features(ens: LineEnsemble, x_nm: Sequence[np.ndarray],
                    force_nN: Sequence[np.ndarray], lattice_nm: np.ndarray,
                    velocity_nm_per_s: np.ndarray, temperature_K: np.ndarray | None = None
                    ) -> tuple[LinePrediction, np.ndarray]:  # fmt: skip
    """:func:`predict_raw_lines`, and what each member's head read for each line (the
    pooled CNN features, conditioning and expert inputs), (members, N, D), taken from
    the same forward pass."""
    pred = predict_raw_lines(ens, list(x_nm), list(force_nN), lattice_nm, velocity_nm_per_s,
                             features=True, temperature_K=temperature_K)  # fmt: skip
    return pred, pred.features


class LineEstimator(TraceEstimator):
    """The default estimator: a whole-line CNN ensemble with calibrated intervals.

    Per trace: ``F_mean_nN, U0_eV, K_N_m, eta``, ``*_std`` (the std of the Gaussian, or
    log-normal, with the same 68 % interval), the central 68 % / 95 % intervals, and what
    the line shows of visible effects (:data:`EVIDENCE_COLUMNS`) and of a local anomaly
    (:data:`LOCAL_COLUMN`), read by the per-map pooling to find lines unlike the rest of
    their map. The lattice and the velocity of each trace enter the mapping and the
    network's conditioning, and so does its temperature for a model trained over a range
    of them (a note says when a trace's temperature lies outside what the model was
    trained at).
    """

    kind = "line"
    intervals = True
    name = "line-cnn"
    eta_edge = ETA_EDGE  # trained on eta >= 1.2: smooth lines land at the edge
    #: the contact the user states (:data:`~stickslip.estimators.line.ensemble.CONTACTS`):
    #: which of the model's calibrations sizes the intervals
    contact = ANY_CONTACT
    #: the user states that the lateral force's zero carries no offset (a zero taken
    #: from a friction loop or a calibration): the single-line <F> interval is then the
    #: model's own calibrated one, without the offset term that one line cannot tell
    #: from friction (:mod:`stickslip.estimators.offsets`)
    zero_offset = False

    def __init__(self, ensemble: LineEnsemble, source: str = "bundled",
                 embedding_reference: EmbeddingReference | None = None) -> None:  # fmt: skip
        """``embedding_reference``: where the model's pooled features lie on training-like
        lines (default: the bundled one, used only if it was made for this model)."""
        self.ensemble = ensemble
        self.source = source
        self.reference = ensemble.spec.reference
        ref = embedding_reference or bundled_reference()
        self.embedding_reference = ref if ref is not None and ref.fingerprint == fingerprint(
            ensemble) else None  # fmt: skip

    def describe(self) -> str:
        stated = "" if self.contact == ANY_CONTACT else f", stated contact: {self.contact}"
        stated += ", stated zero without offset" if self.zero_offset else ""
        return (f"whole-line CNN ensemble of {len(self.ensemble.members)} with calibrated "
                f"68/95 % intervals ({self.source}{stated})")  # fmt: skip

    def estimate(self, traces: Sequence[Trace], conditions: Sequence[Conditions]
                 ) -> tuple[list[dict[str, Any] | str], list[str]]:  # fmt: skip
        spec = self.ensemble.spec
        out: list[dict[str, Any] | str] = [
            refusal(t.x_nm, c.lattice_nm, self.reference, spec.min_pixels) or ""
            for t, c in zip(traces, conditions, strict=True)
        ]
        ok = [i for i, r in enumerate(out) if r == ""]
        notes = []
        T = sorted({c.temperature_K for c in conditions})
        if not all(spec.trained_at(x) for x in T):
            listed = ", ".join(f"{x:g}" for x in T)
            lo, hi = spec.temperature_range_K or (spec.temperature_K, spec.temperature_K)
            trained = f"{lo:g} K" if lo == hi else f"{lo:.0f}-{hi:.0f} K"
            notes.append(f"model trained at T = {trained}, traces at {listed} K: "
                         "estimates are extrapolated")  # fmt: skip
        if not ok:
            return out, notes
        args = ([traces[i].x_nm for i in ok], [traces[i].force_nN for i in ok],
                np.array([conditions[i].lattice_nm for i in ok]),
                np.array([conditions[i].velocity_nm_per_s for i in ok]),
                np.array([conditions[i].temperature_K for i in ok]))  # fmt: skip
        ens = self.ensemble.for_contact(self.contact)
        if self.zero_offset:  # the model's own <F> error: no offset term, and no factor
            ens = replace(ens, offset=None, friction_factor=None)  # fitted for the sum
        ref = self.embedding_reference if self.domain_verdict else None
        if ref is None:
            pred, dist = predict_raw_lines(ens, *args[:4], temperature_K=args[4]), None
            probe = None
            if self.domain_verdict:
                notes.append("no embedding reference for this model: the domain verdict "
                             "reads the traces and the estimates only")  # fmt: skip
        else:
            pred, feats = pooled_features(ens, *args)
            dist = ref.distance(feats)
            probe = ref.probe.ratio(feats) if ref.probe is not None else None
        for j, i in enumerate(ok):
            row: dict[str, Any] = {k: float(pred.values[k][j]) for k in TARGETS}
            row.update({f"{k}_std": float(pred.std[k][j]) for k in TARGETS})
            for b in BOUNDS:
                row.update({f"{k}_{b}": float(getattr(pred, b)[k][j]) for k in TARGETS})
            if pred.F_model_std is not None and (ens.offset is not None
                                                 or ens.compression is not None):
                row["F_model_std_nN"] = float(pred.F_model_std[j])
            if dist is not None:
                row["domain_embedding"] = float(dist[j])
            if probe is not None:
                row["domain_contacts"] = float(probe[j])
            if self.contact != ANY_CONTACT:  # which calibration sized the intervals
                row["contact"] = self.contact
            if self.zero_offset:
                row["zero_offset"] = True
            row.update(zip(EVIDENCE_COLUMNS, map(float, pred.evidence[j]), strict=True))
            if pred.local_evidence is not None:
                row[LOCAL_COLUMN] = float(pred.local_evidence[j])
            out[i] = row
        if self.domain_verdict:
            self._check_stick_slip(traces, conditions, out)
        return out, notes

    def _check_stick_slip(self, traces: Sequence[Trace], conditions: Sequence[Conditions],
                          rows: list[dict[str, Any] | str]) -> None:  # fmt: skip
        """Rows whose eta is below :data:`~stickslip.estimators.domain.ETA_CONFIRM` get
        the classical estimator's refusal of their line in ``stick_slip_check`` (the
        verdict's stick-slip check; the slips inverted without the thermal correction);
        lines it answers or refuses only for their K (``sticks disagree``), and other
        rows, get nothing."""
        # read at call time: the verdict's ratio uses the same module value
        low = [i for i, r in enumerate(rows)
               if isinstance(r, dict) and r["eta"] < domain.ETA_CONFIRM]  # fmt: skip
        if not low:
            return
        # the classical kernel alone: its quality flag is all the check needs. It inverts
        # at T = 0 (F_max at the mean peak): the thermal fixed point took about a quarter
        # of the check's time.
        # The thermal correction raises F_max, and with it eta, so the eta found here is
        # the lower one: it errs towards "smooth sliding". On the verdict's smooth, clean
        # and family sets of seeds 1 and 2 (1,200 lines) it set the thermal inversion's
        # flag on all but one (there "sticks disagree" instead of "inconsistent slopes").
        # (at T = 0 the scan velocity enters nothing: only the thermal model reads it)
        table = estimate_array([traces[i].x_nm for i in low], [traces[i].force_nN for i in low],
                               np.array([conditions[i].lattice_nm for i in low]),
                               temperature_K=0.0)  # fmt: skip
        for i, status in zip(low, table[:, STATUS].astype(int), strict=True):
            # sticks that fit no one spring refuse K, but the slips are stick-slip
            if QUALITY[status] != OK and status not in K_REFUSED:
                rows[i]["stick_slip_check"] = QUALITY[status]  # type: ignore[index]
