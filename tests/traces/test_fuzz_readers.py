"""Fuzzing: mutated real files and random bytes give traces or one-line TraceReadErrors.

Nothing else may escape :func:`collect_traces`, and nothing may hang (each example
runs under a SIGALRM watchdog). Every reason is a sentence, and the traces that do read
give, through the classical estimator and the default line estimator, rows that are
``ok`` with finite numbers or refused with a sentence: the property of
``benchmarks/fuzz_inputs.py`` (its generator and checks, loaded from there), on
:data:`N_FAST` inputs by default and on 10,000 under ``-m slow``.
"""

from __future__ import annotations

import importlib.util
import io
import sys
import tempfile
from pathlib import Path

import h5py
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from stickslip.traces import Trace, TraceReadError, collect_traces

ROOT = Path(__file__).resolve().parents[2]
RAMP = ROOT.parent / "shared" / "data" / "bruker-friction-ramp"

SUFFIXES = [".spm", ".000", ".nid", ".ibw", ".gwy", ".mdt", ".jpk", ".csv", ".txt", ".npy", ".h5",
            ".mat"]
N_FAST = 1200  # inputs of the default run (~20 s on 2 cores); the full run: -m slow


def _bench():
    """benchmarks/fuzz_inputs.py as a module (the one generator and set of checks)."""
    spec = importlib.util.spec_from_file_location("fuzz_inputs", ROOT / "benchmarks"
                                                  / "fuzz_inputs.py")  # fmt: skip
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


FUZZ = _bench()
WATCHDOG_S = 10


def _npy() -> bytes:
    buf = io.BytesIO()
    np.save(buf, np.column_stack([np.arange(32) * 0.1, np.sin(np.arange(32))]))
    return buf.getvalue()


def _h5() -> bytes:
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "s.h5"
        with h5py.File(p, "w") as f:
            f["x_nm"] = np.arange(32) * 0.1
            f["force_nN"] = np.ones((2, 32))
        return p.read_bytes()


def _gwy() -> bytes:
    objects = pytest.importorskip("gwyfile.objects")
    c = objects.GwyContainer()
    for i, title in enumerate(["Friction Forward", "Friction Backward"]):
        c[f"/{i}/data"] = objects.GwyDataField(
            np.ones((4, 32)) * i, xreal=1e-8, yreal=1e-8,
            si_unit_z=objects.GwySIUnit(unitstr="V"))
        c[f"/{i}/data/title"] = title
    buf = io.BytesIO()
    c.tofile(buf)
    return buf.getvalue()


def _seeds() -> dict[str, bytes]:
    seeds = {
        ".csv": b"x_nm,force_nN\n" + b"".join(b"%d,%d\n" % (i, i % 7) for i in range(32)),
        ".npy": _npy(),
        ".h5": _h5(),
        ".gwy": _gwy(),
    }
    if RAMP.is_dir():
        seeds[".spm"] = (RAMP / "si.0_00150.spm").read_bytes()
        seeds[".000"] = (RAMP / "si.0_00143.spm").read_bytes()
        seeds[".txt"] = (RAMP / "exampleFrictionProfileFull.txt").read_bytes()
    return seeds


SEEDS = _seeds()


@st.composite
def mutated(draw) -> tuple[str, bytes]:
    suffix = draw(st.sampled_from(SUFFIXES))
    seed = SEEDS.get(suffix)
    kind = draw(st.sampled_from(["random", "truncate", "flip", "splice"] if seed else ["random"]))
    if kind == "random":
        return suffix, draw(st.binary(max_size=4096))
    assert seed is not None
    if kind == "truncate":
        return suffix, seed[: draw(st.integers(0, len(seed)))]
    data = bytearray(seed)
    if kind == "flip":
        for _ in range(draw(st.integers(1, 20))):
            i = draw(st.integers(0, len(data) - 1))
            data[i] = draw(st.integers(0, 255))
        return suffix, bytes(data)
    i = draw(st.integers(0, len(data)))
    return suffix, bytes(data[:i]) + draw(st.binary(max_size=256)) + bytes(data[i:])


def _check(files: list[tuple[str, bytes]]) -> None:
    with tempfile.TemporaryDirectory() as d:
        paths = []
        for k, (suffix, content) in enumerate(files):
            p = Path(d) / f"f{k}{suffix}"
            p.write_bytes(content)
            paths.append(p)
        with FUZZ.watchdog(WATCHDOG_S):
            traces, errors = collect_traces(paths)
        assert all(isinstance(t, Trace) for t in traces)
        for e in errors:
            assert isinstance(e, TraceReadError)
            assert "\n" not in str(e) and str(e).startswith(e.path)
            assert FUZZ.is_sentence(e.reason), e.reason
        # every file yields traces or exactly one error
        assert len({e.path for e in errors}) == len(errors) <= len(paths)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(mutated(), min_size=1, max_size=3))
def test_mutated_files_give_only_clean_errors(files):
    _check(files)


def test_seeds_themselves_read():
    """The unmutated seeds are valid (so the fuzzing starts from real, readable files)."""
    for suffix in (".csv", ".npy", ".h5", ".gwy", ".spm", ".txt"):
        if suffix not in SEEDS:
            continue
        with tempfile.TemporaryDirectory() as d:
            p = Path(d) / f"seed{suffix}"
            p.write_bytes(SEEDS[suffix])
            traces, errors = collect_traces([p])
            assert traces and not errors, (suffix, errors)


@pytest.mark.parametrize(("text", "ok"), [
    ("the file is empty", True), ("too noisy", True),
    ("KeyError: 'DataSet'", False), ("UnicodeDecodeError", False),
    ("cannot read (KeyError: 'DataSet')", False), ("", False), (None, False),
])
def test_is_sentence(text, ok):
    assert FUZZ.is_sentence(text) is ok


def test_generated_inputs_are_reproducible():
    a = list(FUZZ.generate(40, seed=3))
    assert a == list(FUZZ.generate(40, seed=3)) and a != list(FUZZ.generate(40, seed=4))
    assert len({Path(n).suffix for n, _ in a}) >= 8  # the formats in turn


def _assert_clean(counts) -> None:
    assert counts.failures() == 0, counts.problems
    assert counts.warnings == 0, counts.problems
    # the run exercised both sides of the property
    assert counts.read and counts.read_errors and counts.rows_ok and counts.rows_refused


def test_fuzzed_inputs_give_finite_answers_or_sentences():
    """N_FAST generated files: read, estimated (classical and line) where they read."""
    counts = FUZZ.run(N_FAST, seed=41)
    assert counts.inputs == N_FAST
    _assert_clean(counts)


@pytest.mark.slow
def test_fuzzed_inputs_ten_thousand():
    """The issue's target: 10,000 inputs, no crash, no non-finite ok row, sentences only."""
    counts = FUZZ.run(10_000, seed=41)
    assert counts.inputs == 10_000
    _assert_clean(counts)
