"""``stickslip train / infer / evaluate / demo``: outputs, bad inputs, exit codes."""

from __future__ import annotations

import csv

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from stickslip.cli.main import app
from stickslip.conditions import GRAPHITE
from stickslip.simulators import PRESETS, SweepConfig, run_sweep, simulate
from stickslip.traces.trace import write_trace_csv


def _run(args):
    return CliRunner().invoke(app, [str(a) for a in args])


def _errors(result) -> list[str]:
    return [ln for ln in result.stderr.splitlines() if ln.startswith("stickslip: error:")]


@pytest.fixture(scope="module")
def traces(tmp_path_factory):
    d = tmp_path_factory.mktemp("traces")
    res = simulate([1.0, 3.0], [10.0, 20.0], seed=7)
    for i, f in enumerate(res.force_nN):
        write_trace_csv(d / f"good{i}.csv", res.x_nm, f)
    return d


def test_infer_reports_bad_files_and_processes_the_rest(traces, tmp_path):
    (tmp_path / "garbage.csv").write_text("hello,world\nfoo,bar\n")
    write_trace_csv(tmp_path / "short.csv", np.arange(30) * 0.0215, np.ones(30))
    out = tmp_path / "res.csv"
    r = _run(["infer", traces / "good0.csv", tmp_path / "garbage.csv", tmp_path / "missing.csv",
              tmp_path / "short.csv", traces / "good1.csv", "--out", out, "--plots",
              tmp_path / "plots"])  # fmt: skip
    assert r.exit_code == 1, r.output
    errs = _errors(r)
    assert len(errs) == 3 and "Traceback" not in r.output
    assert any("garbage.csv" in e for e in errs) and any("missing.csv" in e for e in errs)
    assert any("short" in e and "too short" in e for e in errs)
    every = list(csv.DictReader(out.open()))
    # one row per input: estimates for the good ones, the reason for the others
    assert {row["trace"]: row["quality"] for row in every if row["quality"] != "ok"}.keys() == {
        "short", "garbage", "missing"}
    assert all(row["U0_eV"] == "" for row in every if row["quality"] != "ok")
    rows = [row for row in every if row["quality"] == "ok"]
    assert [row["trace"] for row in rows] == ["good0", "good1"]
    for col in ("F_mean_nN", "U0_eV", "K_N_m", "eta", "U0_eV_std", "K_N_m_std", "U0_eV_lo95"):
        assert col in rows[0]
    # the line model's rows carry no window-model columns (they would be empty)
    assert "n_windows" not in rows[0] and "F_mean_net" not in rows[0]
    assert abs(float(rows[0]["U0_eV"]) - 1.0) < 0.3 and abs(float(rows[1]["K_N_m"]) - 20) < 4
    assert len(list((tmp_path / "plots").glob("*.png"))) == 2


def test_infer_shows_the_verdict_and_why_a_row_is_out_of_domain(traces, tmp_path):
    # white noise and a reversed sawtooth beside a PT trace: the terminal table marks
    # each row, one line per out-of-domain trace says why, and the count says how many;
    # out of domain is no failure (exit 0), the rows keep their (widened) numbers
    x = np.arange(512) * 0.0215
    write_trace_csv(tmp_path / "noise.csv", x, np.random.default_rng(0).normal(0, 1, x.size))
    write_trace_csv(tmp_path / "reversed.csv", x, 2 - 2 * ((x / 0.6) % 1) ** 0.2)
    out = tmp_path / "res.csv"
    r = _run(["infer", traces / "good0.csv", tmp_path / "noise.csv", tmp_path / "reversed.csv",
              "--out", out, "--no-classical"])  # fmt: skip
    assert r.exit_code == 0, r.output
    table = {ln.split()[0]: ln.split() for ln in r.stdout.splitlines()}
    assert "domain" in table["trace"]
    assert table["good0"][-1] == "in"
    assert table["noise"][-1] == "OUT" and table["reversed"][-1] == "OUT"
    why = [ln for ln in r.stderr.splitlines() if ln.startswith("out of domain: ")]
    assert len(why) == 2
    assert "noise: " in why[0] and "no stick-slip" in why[0]
    # a sudden rise then a slow, bending fall: the sawtooth the wrong way round
    assert "reversed: sawtooth reversed" in why[1]
    assert "3 ok (2 out of domain: intervals widened), 0 flagged" in r.stderr
    rows = {row["trace"]: row for row in csv.DictReader(out.open())}
    assert rows["noise"]["in_domain"] == "False" and rows["noise"]["U0_eV"] != ""


def test_infer_empty_argument_is_reported_not_read_as_the_current_folder(
    traces, tmp_path, monkeypatch
):
    monkeypatch.chdir(traces)  # "" must not read good0/good1 again from here
    out = tmp_path / "res.csv"
    r = _run(["infer", "good0.csv", "", "--out", out])
    assert r.exit_code == 1, r.output
    assert _errors(r) == ["stickslip: error: '': empty path"]
    rows = list(csv.DictReader(out.open()))
    assert [row["trace"] for row in rows if row["quality"] == "ok"] == ["good0"]
    assert [row["quality"] for row in rows if row["quality"] != "ok"] == ["empty path"]


def test_infer_bad_model_files_give_one_line(traces, tmp_path):
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"garbage" * 50)
    old = tmp_path / "old.pt"
    torch.save({"format": "stickslip-model-0", "stickslip_version": "0.0.1"}, old)
    for model in (bad, old, tmp_path / "none.pt"):
        r = _run(["infer", traces, "--model", model, "--out", tmp_path / "r.csv"])
        assert r.exit_code == 2 and len(_errors(r)) == 1 and "Traceback" not in r.output
        assert str(model) in _errors(r)[0]
    assert not (tmp_path / "r.csv").exists()


@pytest.mark.parametrize("kind", ["window", "line"])
def test_infer_on_another_lattice(tmp_path, kind):
    from importlib.resources import files

    ph = PRESETS["mos2"]
    res = simulate([2.0], [15.0], ph, seed=3)
    write_trace_csv(tmp_path / "mos2.csv", res.x_nm, res.force_nN[0])
    # the window model is given explicitly; the default is the bundled line model
    model = ["--model", files("stickslip") / "resources" / "default_model.pt"]
    r = _run(["infer", tmp_path / "mos2.csv", "--lattice", 0.316, "--velocity", 30,
              "--out", tmp_path / "r.csv", "--no-classical",
              *(model if kind == "window" else [])])  # fmt: skip
    assert r.exit_code == 0, r.output
    # the window model maps the lattice but not thermal activation, and says so; the
    # line model is conditioned on lattice and velocity
    assert ("thermal activation is not mapped" in r.stderr) == (kind == "window")
    row = next(csv.DictReader((tmp_path / "r.csv").open()))
    assert abs(float(row["U0_eV"]) - 2.0) < 0.4 and abs(float(row["K_N_m"]) - 15.0) < 3


def test_train_and_evaluate_small(tmp_path):
    data = tmp_path / "s.h5"
    run_sweep(SweepConfig(n=40, seed=9), data, progress=False)
    model = tmp_path / "m.pt"
    r = _run(["train", "--kind", "window", "--data", data, "--features", "raw", "--epochs", 2,
              "--window", 32, "--out", model])  # fmt: skip
    assert r.exit_code == 0, r.output
    assert model.exists() and model.with_suffix(".loss.png").exists()
    assert "validation (" in r.stderr and "relative RMSE U0" in r.stderr
    r = _run(["evaluate", "--model", model, "--data", data, "--out", tmp_path / "ev"])
    assert r.exit_code == 0, r.output
    for name in ("metrics.json", "metrics.csv", "predictions.csv", "parity.png"):
        assert (tmp_path / "ev" / name).exists()
    r = _run(["train", "--data", tmp_path / "nope.h5", "--out", model])
    assert r.exit_code == 2 and len(_errors(r)) == 1
    r = _run(["train", "--kind", "window", "--data", data, "--features", "fft", "--out", model])
    assert r.exit_code == 2 and "raw or pi" in r.stderr


@pytest.mark.parametrize(("args", "expected"), [
    (["--recipe", "bundled"], "recipe"),
    (["--recipe", "bundled", "--coarse", 0.0], 0.0),
    (["--data", "{data}"], 0.0),
    (["--data", "{data}", "--coarse", 0.25], 0.25),
])  # fmt: skip
def test_train_line_re_pixelates_as_the_bundled_recipe_does(args, expected, tmp_path,
                                                             monkeypatch):  # fmt: skip
    """Old: ``stickslip train --recipe bundled`` trained without the coarse pixels the
    bundled model's script draws, so it did not reproduce the bundled model."""
    import stickslip.jobs.train as tr

    data = tmp_path / "s.h5"
    run_sweep(SweepConfig(n=6, seed=9), data, progress=False)
    seen = {}
    monkeypatch.setattr(tr, "bundled_line_data",
                        lambda *a, **k: tr.read_training_data([data], None, GRAPHITE))
    monkeypatch.setattr(tr, "expert_model", lambda *a, **k: None)
    monkeypatch.setattr(tr, "train_line", lambda training, out, cfg, *a, **k: seen.update(cfg=cfg))
    monkeypatch.setattr(tr, "line_validation", lambda report: "validation")
    r = _run(["train", *[str(a).format(data=data) for a in args], "--out", tmp_path / "m.pt"])
    assert r.exit_code == 0, r.output
    want = tr.BundledRecipe().coarse_fraction if expected == "recipe" else expected
    assert seen["cfg"].coarse_fraction == want
    r = _run(["train", "--data", data, "--coarse", 1.5, "--out", tmp_path / "m.pt"])
    assert r.exit_code == 2 and "--coarse" in _errors(r)[0]


def test_demo_runs(tmp_path):
    r = _run(["demo", "--out", tmp_path / "demo"])
    assert r.exit_code == 0, r.output
    assert "graphene_clean_single_slip" in r.stdout and "mos2" in r.stdout
    rows = list(csv.DictReader((tmp_path / "demo" / "results.csv").open()))
    assert len(rows) == 6
    assert len(list((tmp_path / "demo" / "plots").glob("*.png"))) == 6


def test_demo_into_a_file_is_one_usage_error(tmp_path):
    f = tmp_path / "results.csv"
    f.write_text("keep me\n")
    r = _run(["demo", "--out", f])
    assert r.exit_code == 2 and "Traceback" not in r.output
    (e,) = _errors(r)
    assert "is a file" in e and f.read_text() == "keep me\n"


def test_plots_into_a_file_is_one_usage_error_before_the_work(traces, tmp_path):
    f = tmp_path / "plots"
    f.write_text("keep me\n")
    r = _run(["infer", traces / "good0.csv", "--out", tmp_path / "r.csv", "--plots", f])
    assert r.exit_code == 2 and "Traceback" not in r.output
    (e,) = _errors(r)
    assert "--plots" in e and not (tmp_path / "r.csv").exists()


def test_a_missing_path_is_not_found_whatever_its_name(traces, tmp_path):
    # a mistyped folder has no suffix: it is missing, not of an unknown format
    r = _run(["infer", tmp_path / "scans_typo", traces / "good0.csv", "--out", tmp_path / "r.csv"])
    assert r.exit_code == 1
    (e,) = _errors(r)
    assert "scans_typo: file not found" in e
    (tmp_path / "notes.xyz").write_text("1,2\n")
    r = _run(["infer", tmp_path / "notes.xyz", "--out", tmp_path / "r2.csv"])
    assert "unknown file format '.xyz'" in _errors(r)[0]
    assert ".csv" in _errors(r)[0] and ".spm" in _errors(r)[0]  # what it does read


def test_a_folder_without_readable_files_is_named(traces, tmp_path):
    # before: it vanished without a word ("no input could be read"), or silently beside
    # good inputs
    empty = tmp_path / "scans"
    empty.mkdir()
    (empty / "notes.docx").write_text("x")
    out = tmp_path / "r.csv"
    r = _run(["infer", empty, traces / "good0.csv", "--out", out])
    assert r.exit_code == 1
    (e,) = _errors(r)
    assert "scans: the folder holds no file of a readable format" in e
    rows = list(csv.DictReader(out.open()))
    assert [row["quality"] for row in rows if row["trace"] == "good0"] == ["ok"]
    r = _run(["inspect", empty])
    assert r.exit_code == 1 and "holds no file of a readable format" in r.stderr


def test_infer_reader_options_are_checked(traces, tmp_path):
    r = _run(["infer", traces, "--loads", "1,2", "--out", tmp_path / "r.csv"])
    assert r.exit_code == 2 and "lines-per-load" in r.stderr
    r = _run(["infer", traces, "--lattice", -1, "--out", tmp_path / "r.csv"])
    assert r.exit_code == 2 and len(_errors(r)) == 1
