"""`evaluate` on labelled trace files and sweeps; `train --kind line|window` on sweeps and
on a labelled trace folder, with and without mixing."""

from __future__ import annotations

import csv
import json

import pytest
from typer.testing import CliRunner

from stickslip.cli.main import app
from stickslip.estimators.line.modelfile import line_metadata
from stickslip.estimators.load import load_estimator
from stickslip.simulators import PhysicalSettings, SweepConfig, run_sweep, simulate
from stickslip.traces.trace import write_trace_csv

runner = CliRunner()
TRUTH = [(1.0, 10.0), (2.0, 20.0), (3.0, 15.0), (1.5, 30.0), (2.5, 8.0), (4.0, 25.0)]


def _run(args):
    return runner.invoke(app, [str(a) for a in args])


def _errors(r):
    return [ln for ln in r.stderr.splitlines() if ln.startswith("stickslip: error")]


@pytest.fixture(scope="module")
def labelled(tmp_path_factory):
    """Six simulated trace files and a truth table written by hand (one name unmatched)."""
    d = tmp_path_factory.mktemp("labelled")
    U0, K = zip(*TRUTH, strict=True)
    r = simulate(list(U0), list(K), PhysicalSettings(), seed=21)
    (d / "traces").mkdir()
    lines = ["trace,U0_eV,K_N_m,F_mean_nN"]
    for i, (u, k) in enumerate(TRUTH):
        write_trace_csv(d / "traces" / f"line{i}.csv", r.x_nm, r.force_nN[i])
        lines.append(f"line{i},{u},{k},{r.force_nN[i].mean():.6f}")
    lines.append("ghost,1.0,10.0,0.5")
    (d / "truth.csv").write_text("\n".join(lines) + "\n")
    return d


@pytest.mark.parametrize("model", [None, "classical"])
def test_evaluate_on_labelled_trace_files(labelled, tmp_path, model):
    out = tmp_path / "ev"
    args = ["evaluate", labelled / "traces", "--truth", labelled / "truth.csv", "--out", out]
    r = _run(args + (["--model", model] if model else []))
    # the unmatched truth row is one error line, left out and counted; the rest is scored
    assert r.exit_code == 1, r.output
    assert _errors(r) == ["stickslip: error: ghost: no result row with this trace name; "
                          "left out"]  # fmt: skip
    doc = json.loads((out / "metrics.json").read_text())
    for k in ("F_mean_nN", "U0_eV", "K_N_m", "eta"):
        m = doc[k]
        assert m["n"] == 6 and m["answered"] == 6
        assert set(m) >= {"rmse", "rel_rmse", "median_rel", "n", "answered"}
        assert ("coverage95" in m) == (model is None)
    assert doc["U0_eV"]["rel_rmse"] < 0.1 and doc["K_N_m"]["rel_rmse"] < 0.1
    assert doc["info"]["left_out"] == 1
    # the line model's verdict: how many scored rows it put in and out of domain
    if model is None:
        assert doc["domain"]["in_domain"] + doc["domain"]["out_of_domain"] == 6
        assert f"in domain: {doc['domain']['in_domain']} of 6 rows" in r.stdout
    for name in ("predictions.csv", "parity.png", "metrics.csv"):
        assert (out / name).is_file()
    assert (out / "reliability.png").is_file() == (model is None)
    rows = list(csv.DictReader((out / "predictions.csv").open()))
    assert {r["trace"] for r in rows} == {f"line{i}" for i in range(6)}
    assert all(r["true_U0_eV"] for r in rows)


def test_evaluate_duplicate_truth_names_are_left_out(labelled, tmp_path):
    text = (labelled / "truth.csv").read_text().replace("ghost", "line0")
    (tmp_path / "dup.csv").write_text(text)
    r = _run(["evaluate", labelled / "traces", "--truth", tmp_path / "dup.csv", "--model",
              "classical", "--out", tmp_path / "ev"])  # fmt: skip
    assert r.exit_code == 1
    assert any("line0: named twice" in e for e in _errors(r))
    assert json.loads((tmp_path / "ev" / "metrics.json").read_text())["U0_eV"]["n"] == 5


@pytest.mark.parametrize(("make", "words"), [
    (lambda p: None, "truth table not found"),
    (lambda p: p.mkdir(), "is a folder; --truth needs a table file"),
    (lambda p: p.write_bytes(b"\xff\xfe\x00\xd8garbage"), "truth table is not text"),
])  # fmt: skip
def test_evaluate_unreadable_truth_table_is_one_sentence(labelled, tmp_path, make, words):
    truth = tmp_path / "truth.csv"
    make(truth)
    r = _run(["evaluate", labelled / "traces", "--truth", truth, "--model", "classical",
              "--out", tmp_path / "ev"])  # fmt: skip
    assert r.exit_code == 2 and "Errno" not in r.output
    (e,) = _errors(r)
    assert words in e


def test_evaluate_a_sweep_reads_its_truths(tmp_path):
    data = run_sweep(SweepConfig(n=12, seed=31), tmp_path / "s.h5", progress=False)
    r = _run(["evaluate", "--data", data, "--model", "window", "--out", tmp_path / "ev"])
    assert r.exit_code == 0, r.output
    doc = json.loads((tmp_path / "ev" / "metrics.json").read_text())
    assert doc["U0_eV"]["n"] == 12 and doc["U0_eV"]["rel_rmse"] < 0.15


def test_train_line_on_a_small_sweep_then_infer_with_it(tmp_path):
    data = run_sweep(SweepConfig(n=48, seed=32), tmp_path / "s.h5", progress=False)
    model = tmp_path / "line.pt"
    r = _run(["train", "--kind", "line", "--data", data, "--epochs", 2, "--members", 1,
              "--out", model])  # fmt: skip
    assert r.exit_code == 0, r.output
    # the held-out errors the user should see before trusting the model
    (val,) = [ln for ln in r.stderr.splitlines() if ln.startswith("validation (")]
    assert "<F> RMSE" in val and "U0" in val and "K" in val and " %" in val
    est = load_estimator(model)
    assert est.kind == "line" and len(est.ensemble.members) == 1
    r = _run(["infer", data, "--model", model, "--out", tmp_path / "r.csv", "--no-classical"])
    assert r.exit_code == 0, r.output
    rows = list(csv.DictReader((tmp_path / "r.csv").open()))
    assert len(rows) == 48 and all(float(r["U0_eV_hi95"]) > float(r["U0_eV_lo95"]) for r in rows)


def test_train_line_with_families_and_loader_settings_records_them(tmp_path):
    data = run_sweep(SweepConfig(n=24, seed=34), tmp_path / "s.h5", progress=False)
    model = tmp_path / "fam.pt"
    r = _run(["train", "--kind", "line", "--data", data, "--epochs", 1, "--members", 1,
              "--families", 0.25, "--workers", 0, "--shuffle-rows", 16,
              "--out", model])  # fmt: skip
    assert r.exit_code == 0, r.output
    config = line_metadata(model)["train_config"]
    assert config["family_fraction"] == 0.25 and "precursor" in config["families"]
    assert line_metadata(model)["metrics"]["loader"]["num_workers"] == 0
    r = _run(["train", "--kind", "line", "--data", data, "--families", 1.5, "--out", model])
    assert r.exit_code == 2 and "--families" in r.stderr


@pytest.mark.parametrize("kind", ["window", "line"])
def test_train_on_a_labelled_trace_folder(labelled, tmp_path, kind):
    model = tmp_path / "m.pt"
    r = _run(["train", "--kind", kind, "--data", labelled / "traces", "--labels",
              labelled / "truth.csv", "--epochs", 2, "--members", 1, "--out", model])  # fmt: skip
    assert r.exit_code == 0, r.output
    assert load_estimator(model).kind == kind
    r = _run(["train", "--kind", kind, "--data", labelled / "traces", "--out", model])
    assert r.exit_code == 2 and "--labels" in r.stderr


def test_train_mixes_labelled_real_traces_into_simulated_training(labelled, tmp_path):
    data = run_sweep(SweepConfig(n=40, seed=33), tmp_path / "s.h5", progress=False)
    model = tmp_path / "m.pt"
    r = _run(["train", "--kind", "window", "--data", data, "--mix", labelled / "traces",
              "--mix-labels", labelled / "truth.csv", "--mix-fraction", 0.2, "--epochs", 1,
              "--out", model])  # fmt: skip
    assert r.exit_code == 0, r.output
    r = _run(["train", "--kind", "window", "--data", data, "--mix", labelled / "traces",
              "--out", model])  # fmt: skip
    assert r.exit_code == 2 and "--mix-labels" in r.stderr
