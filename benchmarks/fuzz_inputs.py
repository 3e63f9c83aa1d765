"""Fuzzing the whole input path: whatever the bytes, a number or a sentence, never a crash.

Generates ``--n`` files (default 10,000) from a fixed seed across the formats the
package reads: plain CSV, European CSV (``;`` with decimal commas), headerless and
tab-separated text, ``.npy``, HDF5, MATLAB ``.mat``, Gwyddion, NT-MDT, Nanosurf NID, JPK
(TIFF), Asylum IBW, and Bruker NanoScope (the real files of ../shared/data when they are
there). Each is a seed file mutated one way: random bytes, cut short, bytes overwritten, bytes
inserted, or (text) values replaced by extreme ones (1e30, NaN, ``abc``, an empty
cell), a column scaled by orders of magnitude, lines dropped or repeated.

Every file is read through :func:`stickslip.traces.collect_traces`; the traces read
(at most :data:`TRACES_PER_FILE` per file) go, in batches, through the classical
estimator and the default line estimator. Counted as failures:

- a crash: any exception other than one :class:`~stickslip.traces.TraceReadError` per
  unreadable file (reading or estimating), or a reader running past a watchdog;
- a non-finite ``ok`` row: ``quality == "ok"`` with an estimate, std or interval bound
  that is not a finite number;
- a non-sentence error: a read error or a refusal that is not a sentence
  (:func:`is_sentence`: a few words, no exception class name such as ``KeyError``).

The same generator and checks run in ``tests/traces/test_fuzz_readers.py`` (fewer
inputs by default; the full run under ``-m slow``).

    python benchmarks/fuzz_inputs.py [--n 10000] [--seed 41] [--batch 400]
"""

from __future__ import annotations

import argparse
import io
import os
import platform
import re
import signal
import struct
import tempfile
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
RAMP = SHARED_DATA / "bruker-friction-ramp"
#: Traces of one file passed on to the estimators (a vendor map holds hundreds of lines:
#: its first and last ones are as good a test as all of them, at a fraction of the time).
TRACES_PER_FILE = 4
WATCHDOG_S = 20
_TARGETS = ("F_mean_nN", "U0_eV", "K_N_m", "eta")
_VOLT = {"F_mean_nN": "F_mean_V", "U0_eV": "U0_V_nm", "K_N_m": "K_V_per_nm", "eta": "eta"}
_BOUNDS = ("lo68", "hi68", "lo95", "hi95")
_EXCEPTION_NAME = re.compile(r"^\s*\w*(Error|Exception|Warning|Interrupt)\b|\b[A-Z]\w*(Error|"
                             r"Exception|Warning):")  # fmt: skip


def is_sentence(text: object) -> bool:
    """A reason a person reads: a string of at least two words, no exception class name
    at its start and no ``SomethingError:`` anywhere."""
    return (isinstance(text, str) and len(text.split()) >= 2
            and not _EXCEPTION_NAME.search(text))  # fmt: skip


# ----------------------------------------------------------------------------- seeds


def _sawtooth(n: int = 160) -> tuple[np.ndarray, np.ndarray]:
    """A stick-slip-like line on the paper's pixel: rises of 0.246 nm, then drops."""
    x = np.arange(n) * (11.0 / 512)
    F = 1.5 * ((x / 0.246) % 1.0) + 0.05 * np.sin(7.0 * x)
    return x, F


def _csv(sep: str = ",", decimal: str = ".") -> bytes:
    x, F = _sawtooth()
    rows = [f"{a:.4f}{sep}{b:.4f}".replace(".", decimal) if decimal != "." else
            f"{a:.4f}{sep}{b:.4f}" for a, b in zip(x, F, strict=True)]  # fmt: skip
    return (f"x_nm{sep}force_nN\n" + "\n".join(rows) + "\n").encode()


def _loop_txt() -> bytes:
    x, F = _sawtooth()
    body = "\n".join(f"{a:.5f}\t{f:.5f}\t{f - 1.0:.5f}" for a, f in zip(x, F, strict=True))
    return f"# friction loop\nx_nm\ttrace_nN\tretrace_nN\n{body}\n".encode()


def _npy() -> bytes:
    buf = io.BytesIO()
    np.save(buf, np.column_stack(_sawtooth()))
    return buf.getvalue()


def _h5() -> bytes:
    import h5py

    x, F = _sawtooth()
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "s.h5"
        with h5py.File(p, "w") as f:
            f["x_nm"] = x
            f["force_nN"] = np.stack([F, F + 0.1])
        return p.read_bytes()


def _mat() -> bytes:
    from scipy.io import savemat

    x, F = _sawtooth()
    buf = io.BytesIO()
    savemat(buf, {"x_nm": x, "force_nN": F})
    return buf.getvalue()


def _gwy() -> bytes | None:
    try:
        from gwyfile import objects
    except ImportError:
        return None
    _, F = _sawtooth(64)
    c = objects.GwyContainer()
    for i, title in enumerate(["Friction Forward", "Friction Backward"]):
        c[f"/{i}/data"] = objects.GwyDataField(
            np.tile(F * 0.1 * (1 - 2 * i), (3, 1)), xreal=64 * 11e-9 / 512, yreal=1e-8,
            si_unit_z=objects.GwySIUnit(unitstr="V"))  # fmt: skip
        c[f"/{i}/data/title"] = title
    buf = io.BytesIO()
    c.tofile(buf)
    return buf.getvalue()


def _mdt() -> bytes:
    """A small NT-MDT file with a lateral-force MDA image (the public format description,
    as in tests/traces/test_mdt.py)."""

    def frame(type_code: int, body: bytes) -> bytes:
        return struct.pack("<IHBB6HH", 22 + len(body), type_code, 0, 7, 2024, 5, 6, 7, 8, 9,
                           0) + body  # fmt: skip

    def calibration(unit: str, scale: float, n: int, dtype: int) -> bytes:
        u = unit.encode()
        fields = struct.pack("<IIIQdQddQQiI", 0, 0, len(u), 0, 0.0, 0, 0.0, scale, 0,
                             n - 1 if n else 2**64 - 1, dtype, 0)  # fmt: skip
        return struct.pack("<II", 8 + len(fields) + len(u), len(fields)) + fields + u

    def image(title: bytes, img: np.ndarray) -> bytes:
        ny, nx = img.shape
        head = struct.pack("<II32s4s8I", 76, 0, b"\0" * 32, b"\0" * 4, len(title), 0, 0, 0,
                           0, 0, 0, img.size * 4)  # fmt: skip
        array = struct.pack("<QIII", img.size, 4, 2, 1)
        cals = (calibration("um", 11e-3 / 512, nx, -8) + calibration("um", 0.0005, ny, -8)
                + calibration("V", 1.0, 0, -(4 + 23 * 256)))  # fmt: skip
        return frame(106, head + title + b"\0" * 4 + struct.pack("<I", len(array)) + array
                     + cals + img.astype("<f4").tobytes())  # fmt: skip

    _, F = _sawtooth(64)
    img = np.tile(F * 0.1, (3, 1))
    data = image(b"1F:LF", img) + image(b"1B:LF", -img[:, ::-1])
    return struct.pack("<4sI4sH19s", b"\x01\xb0\x93\xff", len(data), b"\0" * 4, 1,
                       b"\0" * 19) + data  # fmt: skip


def _nid() -> bytes | None:
    """NSFopen's example file, its images cut to 4 lines of 32 pixels."""
    try:
        import NSFopen
    except ImportError:
        return None
    p = Path(NSFopen.__file__).parent / "example" / "Lateral_Force" / "SBS-PMMA.nid"
    if not p.is_file():
        return None
    raw = p.read_bytes()
    head = raw[: raw.find(b"#!") + 2]
    j = head.find(b"[DataSet-0:0]")
    head = head[:j] + head[j:].replace(b"Points=256\r\n", b"Points=32\r\n").replace(
        b"Lines=256\r\n", b"Lines=4\r\n")
    n = head[j:].count(b"SaveBits=32")
    data = np.random.default_rng(3).integers(-2**20, 2**20, n * 32 * 4, dtype="<i4")
    return head + data.tobytes()


def _tiff() -> bytes | None:
    try:
        import tifffile
    except ImportError:
        return None
    buf = io.BytesIO()
    with tifffile.TiffWriter(buf) as tif:
        for _ in range(3):
            tif.write(np.zeros((4, 32), np.float32))
    return buf.getvalue()


def seeds() -> dict[str, bytes]:
    """Seed files by name (the suffix is the format); real files where available."""
    out: dict[str, bytes | None] = {
        "plain.csv": _csv(),
        "euro.csv": _csv(";", ","),
        "tab.txt": _csv("\t"),
        "loop.txt": _loop_txt(),
        "seed.npy": _npy(),
        "seed.h5": _h5(),
        "seed.mat": _mat(),
        "seed.gwy": _gwy(),
        "seed.mdt": _mdt(),
        "seed.nid": _nid(),
        "seed.jpk": _tiff(),
        # an Igor binary wave's first bytes (version 5), no reader-ready file available
        "seed.ibw": struct.pack("<h", 5) + bytes(382),
    }
    if RAMP.is_dir():
        out["ramp.spm"] = (RAMP / "si.0_00150.spm").read_bytes()
        out["ramp.000"] = (RAMP / "si.0_00160.spm").read_bytes()
        out["profile.txt"] = (RAMP / "exampleFrictionProfileFull.txt").read_bytes()
    return {k: v for k, v in out.items() if v is not None}


# ----------------------------------------------------------------------------- mutations

_TEXT = (".csv", ".txt")
_EXTREME = [b"1e30", b"-1e30", b"1e300", b"1e-300", b"nan", b"inf", b"-inf", b"", b"abc",
            b"0", b"1,5", b"1.5.5", b"1e4000", b"--1", b"\xff\xfe", b"0x10", b"1_0"]


def _text_mutation(data: bytes, rng: np.random.Generator) -> bytes:
    lines = data.split(b"\n")
    kind = rng.integers(6)
    body = list(range(1, len(lines) - 1)) or [0]
    if kind == 0:  # extreme values in a few cells
        for _ in range(int(rng.integers(1, 6))):
            i = int(rng.choice(body))
            cells = re.split(rb"([,;\t ])", lines[i])
            k = int(rng.integers(0, len(cells) // 2 + 1)) * 2
            if k < len(cells):
                cells[k] = _EXTREME[int(rng.integers(len(_EXTREME)))]
            lines[i] = b"".join(cells)
    elif kind == 1:  # one column scaled by orders of magnitude (a wrong unit)
        scale = 10.0 ** float(rng.choice([-12, -6, -3, 3, 6, 9, 12, 30, 300]))
        col = int(rng.integers(0, 3))
        for i in body:
            cells = re.split(rb"([,;\t])", lines[i])
            if 2 * col < len(cells):
                try:
                    v = float(cells[2 * col].replace(b",", b"."))
                except ValueError:
                    continue
                cells[2 * col] = repr(v * scale).encode()
            lines[i] = b"".join(cells)
    elif kind == 2:  # lines dropped
        keep = rng.random(len(lines)) > rng.uniform(0.05, 0.95)
        lines = [ln for ln, k in zip(lines, keep, strict=True) if k]
    elif kind == 3:  # a line repeated (x no longer increasing), or the lines reversed
        if rng.random() < 0.5:
            i = int(rng.choice(body))
            lines.insert(i, lines[i])
        else:
            lines = lines[:1] + lines[1:][::-1]
    elif kind == 4:  # the separator or the decimal mark changed
        a, b = [(b",", b";"), (b";", b","), (b".", b","), (b",", b"\t"), (b"\t", b" ")][
            int(rng.integers(5))]
        lines = [ln.replace(a, b) for ln in lines]
    else:  # a constant, flat or huge line
        value = rng.choice([b"0", b"5e3", b"9999.9", b"-1e4"])
        for i in body:
            cells = re.split(rb"([,;\t])", lines[i])
            if len(cells) > 2:
                cells[-1] = value
            lines[i] = b"".join(cells)
    return b"\n".join(lines)


def mutate(data: bytes, suffix: str, rng: np.random.Generator) -> bytes:
    """One mutation of a seed (see the module docstring)."""
    kinds = ["random", "truncate", "flip", "splice"] + (["text"] * 4 if suffix in _TEXT else [])
    kind = kinds[int(rng.integers(len(kinds)))]
    if kind == "random":
        return rng.bytes(int(rng.integers(0, 4096)))
    if kind == "truncate":
        return data[: int(rng.integers(0, len(data) + 1))]
    if kind == "text":
        return _text_mutation(data, rng)
    buf = bytearray(data)
    if kind == "flip" and buf:
        # a few bytes anywhere, or (as often) in the first kilobytes, where headers are
        top = len(buf) if rng.random() < 0.5 else min(len(buf), 4096)
        for _ in range(int(rng.integers(1, 20))):
            buf[int(rng.integers(0, top))] = int(rng.integers(0, 256))
        return bytes(buf)
    i = int(rng.integers(0, len(buf) + 1))
    return bytes(buf[:i]) + rng.bytes(int(rng.integers(1, 256))) + bytes(buf[i:])


def generate(n: int, seed: int) -> Iterator[tuple[str, bytes]]:
    """``n`` (file name, content) pairs, the same for the same ``seed``: each a seed file
    mutated once, the formats in turn (the first of each format: the seed itself)."""
    rng = np.random.default_rng(seed)
    pool = seeds()
    names = sorted(pool)
    for k in range(n):
        name = names[k % len(names)]
        data = pool[name]
        suffix = Path(name).suffix
        yield f"f{k:05d}_{name}", data if k < len(names) else mutate(data, suffix, rng)


# ----------------------------------------------------------------------------- checks


@contextmanager
def watchdog(seconds: int) -> Iterator[None]:
    """Raise TimeoutError in the main thread if the block runs longer than ``seconds``."""

    def _fire(signum, frame):  # pragma: no cover - only on a hang
        raise TimeoutError(f"ran for more than {seconds} s")

    old = signal.signal(signal.SIGALRM, _fire)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


@dataclass
class FuzzCounts:
    """What a fuzz run found; ``problems`` holds one line per failure (the first few)."""

    inputs: int = 0
    read: int = 0
    read_errors: int = 0
    traces_estimated: int = 0
    rows_ok: int = 0
    rows_refused: int = 0
    crashes: int = 0
    nonfinite_ok: int = 0
    non_sentence: int = 0
    warnings: int = 0
    problems: list[str] = field(default_factory=list)

    def failures(self) -> int:
        return self.crashes + self.nonfinite_ok + self.non_sentence

    def note(self, line: str) -> None:
        if len(self.problems) < 50:
            self.problems.append(line)


def _finite(v: object) -> bool:
    return isinstance(v, (int, float, np.integer, np.floating)) and bool(np.isfinite(v))


def check_rows(rows: Sequence[dict], counts: FuzzCounts, intervals: bool) -> None:
    """Every row ``ok`` with finite numbers, or refused (flagged) with a sentence."""
    for row in rows:
        q = row.get("quality")
        if q == "ok":
            counts.rows_ok += 1
            names = [_VOLT[k] for k in _TARGETS] if "U0_V_nm" in row else list(_TARGETS)
            cols = names + [f"{k}_std" for k in names]
            cols += [f"{k}_{b}" for k in names for b in _BOUNDS] if intervals else []
            bad = [c for c in cols if not _finite(row.get(c))]
            if bad:
                counts.nonfinite_ok += 1
                counts.note(f"non-finite ok row {row.get('trace')}: {bad[:4]}")
        else:
            counts.rows_refused += 1
            if not is_sentence(q):
                counts.non_sentence += 1
                counts.note(f"refusal not a sentence {row.get('trace')}: {q!r}")


def _count_warnings(caught: Sequence, where: str, counts: FuzzCounts) -> None:
    """Warnings the library let through (a terminal would show them)."""
    counts.warnings += len(caught)
    for w in caught[:1]:
        counts.note(f"{where}: warning {w.category.__name__}: {w.message}")


def _estimators() -> list:
    from stickslip.estimators.classical.estimator import ClassicalEstimator
    from stickslip.estimators.load import load_estimator

    return [ClassicalEstimator(), load_estimator(None)]


def run(n: int, seed: int = 41, batch: int = 400, estimate: bool = True) -> FuzzCounts:
    """Read ``n`` generated files (:func:`generate`) and estimate what they hold.

    Parameters
    ----------
    n : int
        Number of generated inputs.
    seed : int
        Seed of the generator (fixed: the same inputs every run).
    batch : int
        Traces per estimator call.
    estimate : bool
        Also run the estimators (else reading only).

    Returns
    -------
    FuzzCounts
    """
    import warnings

    from stickslip.traces import TraceReadError, collect_traces

    counts = FuzzCounts()
    estimators = _estimators() if estimate else []
    pending: list = []

    def flush() -> None:
        for est in estimators:
            try:
                with warnings.catch_warnings(record=True) as caught:
                    warnings.simplefilter("always")
                    table = est.predict(pending)
            except Exception as e:  # the property: nothing escapes
                counts.crashes += 1
                counts.note(f"{est.name} crashed on a batch: {type(e).__name__}: {e}")
                continue
            _count_warnings(caught, est.name, counts)
            check_rows(table.rows, counts, est.intervals)
        counts.traces_estimated += len(pending)
        pending.clear()

    with tempfile.TemporaryDirectory() as d:
        for name, content in generate(n, seed):
            counts.inputs += 1
            p = Path(d) / name
            p.write_bytes(content)
            try:
                with watchdog(WATCHDOG_S), warnings.catch_warnings(record=True) as caught:
                    warnings.simplefilter("always")
                    traces, errors = collect_traces([p])
                _count_warnings(caught, name, counts)
            except Exception as e:
                counts.crashes += 1
                counts.note(f"{name}: reading raised {type(e).__name__}: {e}")
                continue
            finally:
                p.unlink()
            if errors:
                counts.read_errors += 1
                e = errors[0]
                ok = (len(errors) == 1 and not traces and isinstance(e, TraceReadError)
                      and "\n" not in str(e) and str(e).startswith(e.path))  # fmt: skip
                if not ok:
                    counts.crashes += 1
                    counts.note(f"{name}: read errors not one clean line: {errors}")
                elif not is_sentence(e.reason):
                    counts.non_sentence += 1
                    counts.note(f"{name}: read error not a sentence: {e.reason!r}")
                continue
            counts.read += 1
            if not estimators:
                continue
            pick = traces if len(traces) <= TRACES_PER_FILE else [*traces[:2], *traces[-2:]]
            pending.extend(pick)
            if len(pending) >= batch:
                flush()
        if pending:
            flush()
    return counts


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    ap.add_argument("--n", type=int, default=10_000, help="generated inputs")
    ap.add_argument("--seed", type=int, default=41)
    ap.add_argument("--batch", type=int, default=400, help="traces per estimator call")
    args = ap.parse_args()
    import stickslip

    t0 = time.perf_counter()
    c = run(args.n, args.seed, args.batch)
    wall = time.perf_counter() - t0
    print(f"stickslip {stickslip.__version__}; seed {args.seed}; formats: "
          + ", ".join(sorted({Path(k).suffix for k in seeds()})))
    print(f"inputs {c.inputs}: read {c.read}, unreadable {c.read_errors}; "
          f"traces estimated {c.traces_estimated} (classical and line): rows ok "
          f"{c.rows_ok}, refused or flagged {c.rows_refused}")
    print(f"crashes {c.crashes}, non-finite ok rows {c.nonfinite_ok}, non-sentence errors "
          f"{c.non_sentence}; warnings let through {c.warnings}")
    for line in c.problems[:20]:
        print("  " + line)
    print(f"wall {wall:.0f} s; machine: {platform.platform()}, "
          f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"python {platform.python_version()}")


if __name__ == "__main__":
    main()
