"""The Python API: what the command line does, as functions (``import stickslip``).

>>> import stickslip
>>> traces, errors = stickslip.read_traces(["scan.spm"], calibration_nN_per_V=12.5)
>>> table = stickslip.predict(traces, model=None)          # the bundled line model
>>> df = table.to_frame()                                  # a pandas DataFrame
>>> stickslip.predict(traces, model="classical").to_frame()
>>> res = stickslip.simulate([1.0, 3.0], [10.0, 20.0], stickslip.PhysicalSettings())
>>> ev = stickslip.evaluate(["labelled/"], truth="truth.csv", model="classical")
>>> stickslip.train(["sweep.h5"], "model.pt", kind="line", epochs=5)
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from stickslip.conditions import GRAPHITE
from stickslip.estimators.base import Estimator
from stickslip.estimators.line.ensemble import ANY_CONTACT
from stickslip.estimators.line.training import LineTrainConfig
from stickslip.estimators.load import load_estimator, state_contact, state_zero_offset
from stickslip.estimators.table import ResultTable
from stickslip.estimators.window.training import TrainConfig
from stickslip.jobs import evaluate as ev
from stickslip.jobs import infer as inf
from stickslip.jobs import train as tr
from stickslip.traces.formats.maps import reader_options
from stickslip.traces.trace import Trace, TraceReadError

PathLike = str | os.PathLike


def read_traces(paths: Sequence[PathLike], calibration_nN_per_V: float | None = None,
                lines_per_load: int | None = None, loads: Sequence[float] | None = None
                ) -> tuple[list[Trace], list[TraceReadError]]:  # fmt: skip
    """Every trace in files and folders of any supported format, and one error per
    input that cannot be read (never raises on a bad file)."""
    opts = reader_options(calibration_nN_per_V, lines_per_load,
                          list(loads) if loads is not None else None)  # fmt: skip
    return inf.read_inputs(paths, opts)


def _traces(inputs: Sequence[Trace] | Sequence[PathLike]
            ) -> tuple[list[Trace], list[TraceReadError]]:  # fmt: skip
    items = list(inputs)
    if items and all(isinstance(t, Trace) for t in items):
        return items, []  # type: ignore[return-value]
    return read_traces(items)  # type: ignore[arg-type]


def predict(inputs: Sequence[Trace] | Sequence[PathLike],
            model: Estimator | PathLike | None = None, *, lattice_nm: float | None = None,
            velocity_nm_per_s: float | None = None, temperature_K: float | None = None,
            classical: bool = False, check: bool = False,
            contact: str = ANY_CONTACT, zero_offset: bool = False) -> ResultTable:  # fmt: skip
    """Estimates for traces (or the files holding them): one row per trace, and per
    unreadable input; ``.to_frame()`` gives a DataFrame.

    ``model``: an :class:`Estimator`, a model file, ``"classical"``, ``"window"``, or
    None for the bundled whole-line model. ``contact``: ``"ideal"`` where the tip is one
    asperity on a crystal without modulation or defects along the line (the line model's
    calibration for such contacts; :data:`~stickslip.estimators.line.ensemble.CONTACTS`).
    ``zero_offset``: the lateral force's zero carries no offset (the line model's lone
    lines then get its own <F> interval, without the offset term).
    """
    est = model if isinstance(model, Estimator) else load_estimator(model)
    est = state_zero_offset(state_contact(est, contact), zero_offset)
    traces, errors = _traces(inputs)
    return inf.infer(est, traces, errors, lattice_nm=lattice_nm,
                     velocity_nm_per_s=velocity_nm_per_s, temperature_K=temperature_K,
                     classical=classical, check=check).table  # fmt: skip


def evaluate(inputs: Sequence[Trace] | Sequence[PathLike],
             model: Estimator | PathLike | None = None, truth: PathLike | None = None,
             out: PathLike | None = None, **conditions: float | None) -> ev.Evaluation:  # fmt: skip
    """Score an estimator on labelled traces (``truth``: a table) or a sweep (truths
    inside); with ``out``, write metrics.json, predictions, plots there."""
    est = model if isinstance(model, Estimator) else load_estimator(model)
    traces, errors = _traces(inputs)
    result = inf.infer(est, traces, errors, classical=False, **conditions)
    labels = (ev.truth_from_table(truth) if truth is not None
              else ev.truth_from_traces(result.table, result.traces))  # fmt: skip
    evaluation = ev.evaluate(result.table, labels)
    if out is not None:
        ev.write_evaluation(evaluation, out, {"estimator": est.name})
    return evaluation


def train(data: Sequence[PathLike], out: PathLike, kind: str = "line",
          labels: PathLike | None = None, mix: Sequence[PathLike] = (),
          mix_labels: PathLike | None = None, mix_fraction: float = 0.01,
          features: str = "pi", expert: str = "none", progress: bool = False,
          **options: Any) -> Path:  # fmt: skip
    """Train an estimator (``kind="line"`` or ``"window"``) and save it to ``out``.

    ``data``: sweeps (.h5, .zarr) and/or trace files with a ``labels`` table;
    ``mix``: labelled real traces added as ``mix_fraction`` of the training lines;
    ``options``: fields of :class:`LineTrainConfig` or :class:`TrainConfig`
    (``epochs``, ``members``, ``seed`` ...).
    """
    if kind not in tr.KINDS:
        raise ValueError(f"kind must be one of {', '.join(tr.KINDS)}")
    training = tr.read_training_data(data, labels, GRAPHITE)
    if mix:
        real = tr.read_training_data(mix, mix_labels, GRAPHITE).data
        training = tr.mix_in(training, real, mix_fraction, int(options.get("seed", 0)))
    if kind == "line":
        tr.train_line(training, out, LineTrainConfig(**options),
                      tr.expert_model(expert, "build/line-train"), expert, progress)  # fmt: skip
    else:
        tr.train_window(training, out, features, TrainConfig(**options), progress=progress)
    return Path(out)
