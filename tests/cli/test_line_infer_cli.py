"""`stickslip infer` with a whole-line model: intervals, check, panels, bad input."""

import csv

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from stickslip.cli.main import app
from stickslip.estimators.line.ensemble import LineCNN, LineEnsemble, LineSpec
from stickslip.estimators.line.modelfile import save_line_model
from stickslip.simulators import simulate
from stickslip.traces import write_trace_csv

runner = CliRunner()


@pytest.fixture(scope="module")
def line_model(tmp_path_factory):
    torch.manual_seed(0)
    ens = LineEnsemble(members=[LineCNN(), LineCNN()], spec=LineSpec(),
                       y_mean=np.array([0.0, 0.5, 2.0, 1.5]),
                       y_std=np.array([0.05, 0.8, 0.9, 0.9]))  # fmt: skip
    return save_line_model(ens, tmp_path_factory.mktemp("m") / "line.pt", (16, 32, 48, 64),
                           {}, {}, {})  # fmt: skip


def test_infer_line_model_rows_intervals_check_and_bad_files(tmp_path, line_model):
    r = simulate([1.0, 3.0], [10.0, 25.0], seed=2)
    for i in range(2):
        write_trace_csv(tmp_path / f"ok{i}.csv", r.x_nm, r.force_nN[i])
    (tmp_path / "broken.csv").write_text("x_nm,force_nN\n0,1\n1,nan\n")
    out = tmp_path / "res.csv"
    res = runner.invoke(app, ["infer", str(tmp_path / "ok0.csv"), str(tmp_path / "ok1.csv"),
                              str(tmp_path / "broken.csv"), "--model", str(line_model),
                              "--check", "--plots", str(tmp_path / "plots"),
                              "--out", str(out)])  # fmt: skip
    assert res.exit_code == 1, res.output
    err = [ln for ln in res.stderr.splitlines() if "error" in ln]
    assert len(err) == 1 and "broken.csv" in err[0]
    assert "Traceback" not in res.output
    every = list(csv.DictReader(out.open()))
    assert [(row["trace"], row["quality"]) for row in every[2:]] == [
        ("broken", "only 2 samples, at least 16 needed")]
    rows = every[:2]
    assert [row["trace"] for row in rows] == ["ok0", "ok1"]
    for row in rows:
        for k in ("U0_eV", "K_N_m", "eta", "F_mean_nN"):
            lo95, lo68 = float(row[f"{k}_lo95"]), float(row[f"{k}_lo68"])
            hi68, hi95 = float(row[f"{k}_hi68"]), float(row[f"{k}_hi95"])
            assert lo95 < lo68 < float(row[k]) < hi68 < hi95
        assert float(row["gof"]) >= 0 and row["ppc_flag"] in ("0", "1")
        assert row["classical_U0_eV"] != ""
    assert len(list((tmp_path / "plots").glob("*.png"))) == 2


def test_damaged_model_file_is_one_line(tmp_path, line_model):
    bad = tmp_path / "bad.pt"
    bad.write_bytes(line_model.read_bytes()[:300])
    r = simulate([1.0], [10.0], seed=2)
    write_trace_csv(tmp_path / "t.csv", r.x_nm, r.force_nN[0])
    res = runner.invoke(app, ["infer", str(tmp_path / "t.csv"), "--model", str(bad),
                              "--out", str(tmp_path / "o.csv")])  # fmt: skip
    assert res.exit_code == 2
    assert len(res.stderr.strip().splitlines()) == 1 and "bad.pt" in res.stderr


def _half_widths(path) -> dict[str, float]:
    return {r["trace"]: (np.log(float(r["U0_eV_hi95"])) - np.log(float(r["U0_eV_lo95"]))) / 2
            for r in csv.DictReader(open(path))}  # fmt: skip


def test_a_stated_ideal_contact_narrows_u0_where_the_examples_are_quiet(tmp_path, line_model):
    from stickslip.jobs.demo import examples_dir

    ex = str(examples_dir())
    for contact, out in (("any", tmp_path / "any.csv"), ("ideal", tmp_path / "ideal.csv")):
        res = runner.invoke(app, ["infer", ex, "--out", str(out), "--contact", contact])
        assert res.exit_code == 0, res.output
    assert "stated contact: ideal" in res.stderr
    # the table says which calibration sized its intervals
    assert {r.get("contact") for r in csv.DictReader(open(tmp_path / "ideal.csv"))} == {"ideal"}
    assert not any(r.get("contact") for r in csv.DictReader(open(tmp_path / "any.csv")))
    any_, ideal = _half_widths(tmp_path / "any.csv"), _half_widths(tmp_path / "ideal.csv")
    assert set(any_) == set(ideal) and len(any_) == 6
    # the bundled calibration for one asperity on a plain crystal: narrower in every
    # example, and at least halved on the three noise-free graphene lines
    assert all(ideal[k] < any_[k] for k in any_), (any_, ideal)
    clean = [k for k in any_ if k.startswith("graphene_clean")]
    assert len(clean) == 3 and all(ideal[k] < 0.5 * any_[k] for k in clean)
    # a contact no calibration is for, or an estimator without one per contact: one line
    for args, words in ((["--contact", "tip"], "must be one of any, ideal"),
                        (["--contact", "ideal", "--model", "classical"], "classical"),
                        (["--contact", "ideal", "--model", str(line_model)],
                         "no calibration for the contact 'ideal'")):  # fmt: skip
        res = runner.invoke(app, ["infer", ex, "--out", str(tmp_path / "x.csv"), *args])
        assert res.exit_code == 2 and words in res.stderr, res.output
        assert not (tmp_path / "x.csv").exists()


def test_predict_with_a_stated_contact_leaves_the_callers_estimator_alone():
    import stickslip
    from stickslip.estimators.load import load_estimator
    from stickslip.jobs.demo import load_examples

    traces, _ = load_examples()
    est = load_estimator(None)
    stated = stickslip.predict(traces[:2], est, contact="ideal")
    default = stickslip.predict(traces[:2], est)
    assert est.contact == "any"
    assert all(s["U0_eV_hi95"] - s["U0_eV_lo95"] < d["U0_eV_hi95"] - d["U0_eV_lo95"]
               for s, d in zip(stated.rows, default.rows, strict=True))  # fmt: skip


def test_a_stated_zero_without_offset_keeps_friction_covered_and_narrows_it(tmp_path):
    """A lone line's <F> interval carries an offset that one line cannot tell from
    friction; a user who took the zero from a friction loop says so with --zero-offset,
    and the interval becomes the model's own: narrower, still about the friction."""
    r = simulate([0.6, 1.5, 3.0, 4.5], [8.0, 15.0, 25.0, 40.0], seed=11)
    lines = tmp_path / "lines"
    lines.mkdir()
    for i, f in enumerate(r.force_nN):
        write_trace_csv(lines / f"t{i}.csv", r.x_nm, f)
    tables = {}
    for name, args in (("prior", []), ("zero", ["--zero-offset"])):
        out = tmp_path / f"{name}.csv"
        res = runner.invoke(app, ["infer", str(lines), "--out", str(out), *args])
        assert res.exit_code == 0, res.output
        tables[name] = {row["trace"]: row for row in csv.DictReader(open(out))}
    assert "stated zero without offset" in res.stderr
    truth = {f"t{i}": float(f.mean()) for i, f in enumerate(r.force_nN)}
    for key, prior in tables["prior"].items():
        zero = tables["zero"][key]
        assert zero["zero_offset"] == "True" and not prior.get("zero_offset")
        lo, hi = float(zero["F_mean_nN_lo95"]), float(zero["F_mean_nN_hi95"])
        wide = float(prior["F_mean_nN_hi95"]) - float(prior["F_mean_nN_lo95"])
        # the offset term was most of the width on these clean lines
        assert lo <= truth[key] <= hi and hi - lo < 0.5 * wide, (key, lo, hi, wide)
        # the other targets' intervals do not depend on the statement
        assert zero["U0_eV_lo95"] == prior["U0_eV_lo95"]
    res = runner.invoke(app, ["infer", str(lines), "--out", str(tmp_path / "x.csv"),
                              "--zero-offset", "--model", "classical"])  # fmt: skip
    assert res.exit_code == 2 and "--zero-offset" in res.stderr
    assert not (tmp_path / "x.csv").exists()
