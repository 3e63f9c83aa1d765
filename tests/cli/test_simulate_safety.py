"""`stickslip simulate` never loses work: partial files, Ctrl-C, unwritable --out (issue 21)."""

from __future__ import annotations

import shlex
import signal
import subprocess
import sys
import time

import h5py
import pytest
from typer.testing import CliRunner

from stickslip.cli.main import app
from stickslip.simulators import PhysicalSettings, SweepConfig, run_sweep
from stickslip.simulators import sweep as sweep_mod
from stickslip.traces.dataset import read_done

runner = CliRunner()
FAST = ["--velocity", "600", "--length", "1", "--pixels", "32", "--no-progress"]
PHYSICS = PhysicalSettings(velocity_nm_per_s=600.0, length_nm=1.0, pixels=32)


def _partial_with_rows(tmp_path, monkeypatch):
    """A sweep interrupted after its first write: <out>.partial holds finished rows."""
    out = tmp_path / "s.h5"
    real = sweep_mod.write_rows
    calls = {"n": 0}

    def flaky(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 2:
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(sweep_mod, "write_rows", flaky)
    with pytest.raises(KeyboardInterrupt):  # the settings `simulate --n 24 FAST` makes
        run_sweep(SweepConfig(physics=PHYSICS, n=24), out, chunk=8, progress=False)
    monkeypatch.setattr(sweep_mod, "write_rows", real)
    part = sweep_mod.partial_path(out)
    assert read_done(part).sum() == 8
    return out, part


def test_existing_partial_is_kept_without_resume_or_overwrite(tmp_path, monkeypatch):
    out, part = _partial_with_rows(tmp_path, monkeypatch)
    stamp = part.stat().st_mtime_ns
    r = runner.invoke(app, ["simulate", "--n", "24", "--chunk", "8", *FAST, "--out", str(out)])
    assert r.exit_code == 2, r.output
    err = r.stderr.strip().splitlines()
    assert len(err) == 1 and "--resume" in err[0] and "--overwrite" in err[0], err
    assert str(part) in err[0]
    assert part.stat().st_mtime_ns == stamp and read_done(part).sum() == 8
    assert not out.exists()
    # --overwrite starts again; --resume and --overwrite together are refused
    r = runner.invoke(app, ["simulate", "--n", "24", *FAST, "--out", str(out), "--resume",
                            "--overwrite"])  # fmt: skip
    assert r.exit_code == 2 and len(r.stderr.strip().splitlines()) == 1
    r = runner.invoke(app, ["simulate", "--n", "24", *FAST, "--out", str(out), "--overwrite"])
    assert r.exit_code == 0, r.output
    assert out.exists() and not part.exists()


def test_resume_continues_the_kept_partial(tmp_path, monkeypatch):
    out, part = _partial_with_rows(tmp_path, monkeypatch)
    seen = []
    real = sweep_mod.simulate_job
    monkeypatch.setattr(sweep_mod, "simulate_job", lambda job: seen.append(job.rows) or real(job))
    r = runner.invoke(app, ["simulate", "--n", "24", "--chunk", "8", *FAST, "--out", str(out),
                            "--resume"])  # fmt: skip
    assert r.exit_code == 0, r.output
    assert sum(rows.size for rows in seen) == 16  # only the missing rows were simulated


@pytest.mark.parametrize("single", [True, False], ids=["trace", "sweep"])
@pytest.mark.parametrize("where", ["missing folder", "directory"])
def test_unwritable_out_fails_before_the_run(tmp_path, monkeypatch, single, where):
    def no_run(*args, **kwargs):
        raise AssertionError("simulated although --out cannot be written")

    monkeypatch.setattr("stickslip.simulators.simulate", no_run)
    monkeypatch.setattr(sweep_mod, "simulate_job", no_run, raising=False)
    monkeypatch.setattr(sweep_mod, "simulate", no_run, raising=False)
    if where == "directory":
        out = tmp_path / ("t.csv" if single else "s.h5")
        out.mkdir()
    else:
        out = tmp_path / "no" / "such" / ("t.csv" if single else "s.h5")
    args = ["--u0", "1", "--k", "10"] if single else ["--n", "4"]
    r = runner.invoke(app, ["simulate", *args, *FAST, "--out", str(out)])
    assert r.exit_code != 0
    err = r.stderr.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"stickslip: error: {out}: "), r.output
    assert "Traceback" not in r.output
    assert not (tmp_path / "no").exists()
    assert not sweep_mod.partial_path(out).exists()


def _default_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _rows_done(part) -> int:
    """Rows finished in a partial file that another process is writing (0 if unreadable now)."""
    try:
        with h5py.File(part, "r", locking=False) as f:
            return int(f["done"][:].sum())
    except (OSError, KeyError):
        return 0


def test_ctrl_c_stops_soon_keeps_rows_and_prints_resume_command(tmp_path):
    out = tmp_path / "s.h5"
    part = sweep_mod.partial_path(out)
    # 0.5 nm of travel per trajectory: a default call (64 on 2 threads) lasts ~0.1 s, the
    # whole sweep tens of seconds, so that the interrupt lands while it runs
    n = 16384
    args = ["simulate", "--n", str(n), "--seed", "5", "--velocity", "60", "--length", "0.25",
            "--warmup", "0.25", "--pixels", "8", "--no-progress", "--out", str(out)]  # fmt: skip
    code = "from stickslip.cli.main import main; main()"
    # as a foreground terminal starts it: a test run started in the background (``&``)
    # passes SIGINT on ignored, and the child would then never see the Ctrl-C
    proc = subprocess.Popen([sys.executable, "-c", code, *args], stderr=subprocess.PIPE,
                            stdout=subprocess.DEVNULL, text=True,
                            preexec_fn=_default_sigint)  # fmt: skip
    try:
        deadline = time.monotonic() + 180  # numba may compile first
        while _rows_done(part) == 0 and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.05)
        assert proc.poll() is None, "the sweep ended before any row was seen written"
        t0 = time.monotonic()
        proc.send_signal(signal.SIGINT)
        lines, stop_s = [], float("inf")
        for line in proc.stderr:  # the run has stopped when it says so (exit takes longer)
            lines.append(line)
            if "interrupted" in line:
                stop_s = time.monotonic() - t0
        proc.wait(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    stderr = "".join(lines)
    assert proc.returncode == 130, stderr
    assert stop_s < 5.0
    assert "Traceback" not in stderr
    last = stderr.strip().splitlines()[-1]
    done = int(read_done(part).sum())
    assert 0 < done < n
    resume = shlex.join(["stickslip", *args, "--resume"])
    assert last == (f"stickslip: error: interrupted: {done} of {n} trajectories kept in "
                    f"{part}; continue with: {resume}")  # fmt: skip
    assert not out.exists()


@pytest.mark.parametrize(
    "args", [["--u0", "1e9", "--k", "5"], ["--u0", "1", "--k", "5", "--dt", "1"]])
def test_a_step_the_integrator_cannot_take_is_one_usage_error_and_no_file(tmp_path, args):
    # before: a barrier of 1e9 eV warmed up for hours, a step of 1 s wrote a NaN trace
    out = tmp_path / "t.csv"
    r = runner.invoke(app, ["simulate", "--out", str(out), *args])
    assert r.exit_code == 2
    assert "stability limit" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert not out.exists() and list(tmp_path.iterdir()) == []
