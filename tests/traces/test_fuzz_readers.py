"""Fuzzing: mutated real files and random bytes give traces or one-line TraceReadErrors.

Nothing else may escape :func:`collect_traces`, and nothing may hang (each example
runs under a SIGALRM watchdog).
"""

from __future__ import annotations

import io
import signal
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import h5py
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from stickslip.traces import Trace, TraceReadError, collect_traces

RAMP = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "bruker-friction-ramp"

SUFFIXES = [".spm", ".000", ".nid", ".ibw", ".gwy", ".csv", ".txt", ".npy", ".h5"]
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


@contextmanager
def watchdog(seconds: int) -> Iterator[None]:
    def _fire(signum, frame):  # pragma: no cover - only on a hang
        raise TimeoutError(f"reader hung for more than {seconds} s")

    old = signal.signal(signal.SIGALRM, _fire)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


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
        with watchdog(WATCHDOG_S):
            traces, errors = collect_traces(paths)
        assert all(isinstance(t, Trace) for t in traces)
        for e in errors:
            assert isinstance(e, TraceReadError)
            assert "\n" not in str(e) and str(e).startswith(e.path)
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
