"""Issue 21 (parts 5 and 6): defects a new user meets on the first day, one test each.

Every test names the old behaviour in its docstring; each fails on it.
"""

from __future__ import annotations

import csv
import json
import time
from pathlib import Path

import numpy as np
import pytest
import tomllib
import torch
from typer.testing import CliRunner

import stickslip.cli.common as common
import stickslip.diagnostics.loads as loads_mod
import stickslip.diagnostics.plots_classical as pc
import stickslip.jobs.infer as inf
import stickslip.traces.readers as readers
from stickslip.cli.main import app
from stickslip.diagnostics.ppc import posterior_predictive_check
from stickslip.estimators.base import TraceEstimator
from stickslip.estimators.classical.estimator import ClassicalEstimator
from stickslip.estimators.classical.slips import analyse_trace
from stickslip.estimators.line.ensemble import LineCNN, LineEnsemble, LineSpec
from stickslip.estimators.line.modelfile import save_line_model
from stickslip.simulators import simulate
from stickslip.traces.formats.common import RETRACE, TRACE, Channel, ScanFile
from stickslip.traces.formats.maps import map_to_traces
from stickslip.traces.readers import collect_traces, read_file
from stickslip.traces.trace import Trace, write_trace_csv

ROOT = Path(__file__).resolve().parents[2]
RAMP = ROOT.parent / "shared" / "data" / "bruker-friction-ramp"
MAP = RAMP / "si.0_00150.spm"  # 32 lines x 32 pixels, trace and retrace, volts
needs_ramp = pytest.mark.skipif(not MAP.is_file(), reason=f"real data missing: {RAMP}")
runner = CliRunner()


def _run(args: list) -> object:
    return runner.invoke(app, [str(a) for a in args])


def _errors(res) -> list[str]:
    return [ln for ln in res.stderr.splitlines() if ln.startswith("stickslip: error")]


def _rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


POOL_U0 = [1.5, 2.5, 1.0, 2.0, 3.0, 2.0, 1.5, 2.5]
POOL_K = [12.0, 20.0, 10.0, 15.0, 20.0, 15.0, 12.0, 18.0]


@pytest.fixture(scope="module")
def pool():
    """Eight clean lines of the paper preset (11 nm, 512 px) in one simulate call (the
    kernel integrates 32 at a time: eight cost what one does), with the simulator's
    default seed 0."""
    return simulate(POOL_U0, POOL_K, seed=0)


class _Lines:
    def __init__(self, x_nm: np.ndarray, force_nN: np.ndarray) -> None:
        self.x_nm, self.force_nN = x_nm, force_nN


@pytest.fixture(scope="module")
def sim(pool):
    """Two clean lines: (1.5 eV, 12 N/m) and (2.5 eV, 20 N/m)."""
    return _Lines(pool.x_nm, pool.force_nN[:2])


@pytest.fixture(scope="module")
def traces_dir(sim, tmp_path_factory):
    d = tmp_path_factory.mktemp("traces")
    for i in range(2):
        write_trace_csv(d / f"t{i}.csv", sim.x_nm, sim.force_nN[i])
    return d


@pytest.fixture(scope="module")
def line_model(tmp_path_factory):
    """A small (untrained) whole-line ensemble: fast, and the same columns as the bundled."""
    torch.manual_seed(0)
    ens = LineEnsemble(members=[LineCNN(), LineCNN()], spec=LineSpec(),
                       y_mean=np.array([0.0, 0.5, 2.0, 1.5]),
                       y_std=np.array([0.05, 0.8, 0.9, 0.9]))  # fmt: skip
    return save_line_model(ens, tmp_path_factory.mktemp("m") / "line.pt", (16, 32, 48, 64),
                           {}, {}, {})  # fmt: skip


def _loop_csv(path: Path, sim, nan_at: int | None = None, scale: float = 1.0) -> Path:
    """A friction loop (x_nm,trace,retrace): map lines named ``<stem>:Friction:...:L000``."""
    t = sim.force_nN[0] * scale
    r = -t[::-1] * 0.9
    if nan_at is not None:
        t = t.copy()
        t[nan_at] = np.nan
    lines = ["x_nm,trace_nN,retrace_nN"]
    lines += [f"{x:.6f},{a:.6f},{b:.6f}" for x, a, b in zip(sim.x_nm, t, r, strict=True)]
    path.write_text("\n".join(lines) + "\n")
    return path


def _no_work(monkeypatch) -> None:
    def boom(*a, **k):
        raise AssertionError("inputs were read before the output path was checked")

    monkeypatch.setattr(inf, "read_inputs", boom)


# --- 1. already fixed by the lead: tests only ------------------------------------------


def test_out_into_missing_folder_or_onto_a_directory_is_one_line_before_work(
        traces_dir, tmp_path, monkeypatch):  # fmt: skip
    """Old: infer read and estimated every trace, then failed writing (a traceback for a
    directory, FileNotFoundError for a missing folder)."""
    _no_work(monkeypatch)
    for out in (tmp_path / "missing" / "r.csv", tmp_path):
        res = _run(["infer", traces_dir, "--model", "classical", "--out", out])
        assert res.exit_code == 2, res.output
        err = _errors(res)
        assert len(err) == 1 and err[0].startswith("stickslip: error: ") and str(out) in err[0]


@pytest.mark.parametrize("args", [
    ["friction-load", "{t}", "--out", "{o}.png"],
    ["friction-load", "{t}", "--out", "{w}/f.png", "--csv", "{o}.csv"],
    ["friction-load", "{t}", "--out", "{w}/f.png", "--fits", "{o}.csv"],
    ["friction-velocity", "{t}", "--out", "{o}.csv", "--plot", "{w}/p.png"],
    ["friction-velocity", "{t}", "--out", "{w}/r.csv", "--plot", "{o}.png"],
    ["infer", "{t}", "--out", "{w}/r.csv", "--report", "{o}.html"],
    ["train", "--recipe", "bundled", "--out", "{o}.pt"],
])  # fmt: skip
def test_every_output_in_a_missing_folder_or_under_a_file_is_one_line_before_work(
        args, traces_dir, tmp_path, monkeypatch):  # fmt: skip
    """Old: friction-load and friction-velocity made a mistyped folder (or failed with
    'cannot write the outputs' after all the work) where infer refused it."""
    import stickslip.diagnostics.load_fits as lf
    import stickslip.jobs.train as tr
    import stickslip.jobs.velocity as jv

    def boom(*a, **k):
        raise AssertionError("work began before the output paths were checked")

    _no_work(monkeypatch)
    for module, name in ((lf, "collect_friction_rows"), (jv, "run_friction_velocity"),
                         (tr, "bundled_line_data")):  # fmt: skip
        monkeypatch.setattr(module, name, boom)
    (tmp_path / "a_file").write_text("keep me\n")
    for bad, why in ((tmp_path / "typo" / "out", "does not exist"),
                     (tmp_path / "a_file" / "out", "is a file, not a folder")):  # fmt: skip
        res = _run([a.format(t=traces_dir, w=tmp_path, o=bad) for a in args])
        assert res.exit_code == 2, res.output
        err = _errors(res)
        assert len(err) == 1 and why in err[0] and str(bad.parent) in err[0], err
    assert not (tmp_path / "typo").exists() and (tmp_path / "a_file").read_text() == "keep me\n"


def test_out_json_is_json_and_out_txt_is_refused_before_work(traces_dir, tmp_path,
                                                             monkeypatch):  # fmt: skip
    """Old: --out was always written as CSV whatever its extension (x.json held CSV)."""
    out = tmp_path / "r.json"
    res = _run(["infer", traces_dir, "--model", "classical", "--out", out])
    assert res.exit_code == 0, res.output
    rows = json.loads(out.read_text())
    assert [r["trace"] for r in rows] == ["t0", "t1"] and rows[0]["U0_eV"] > 0
    _no_work(monkeypatch)
    res = _run(["infer", traces_dir, "--out", tmp_path / "r.txt"])
    assert res.exit_code == 2
    err = _errors(res)
    assert len(err) == 1 and ".csv" in err[0] and ".parquet" in err[0]
    assert not (tmp_path / "r.txt").exists()


def test_parquet_extra_declared_and_parquet_written(traces_dir, tmp_path):
    """Old: no `parquet` extra, so `pip install 'stickslip[parquet]'` (named in the
    error for a missing pyarrow) installed nothing."""
    extras = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"][
        "optional-dependencies"]
    assert any(d.startswith("pyarrow") for d in extras["parquet"])
    pd = pytest.importorskip("pandas")
    pytest.importorskip("pyarrow")
    out = tmp_path / "r.parquet"
    res = _run(["infer", traces_dir, "--model", "classical", "--out", out])
    assert res.exit_code == 0, res.output
    assert list(pd.read_parquet(out)["trace"]) == ["t0", "t1"]


def test_line_model_rows_carry_no_window_columns(traces_dir, tmp_path, line_model):
    """Old: line-model rows had `n_windows` and `F_mean_net` (window-model columns)."""
    out = tmp_path / "r.csv"
    res = _run(["infer", traces_dir, "--model", line_model, "--no-classical", "--out", out])
    assert res.exit_code == 0, res.output
    header = out.read_text().splitlines()[0].split(",")
    assert "U0_eV_lo95" in header
    assert "n_windows" not in header and "F_mean_net" not in header


def test_plot_names_have_no_colons_and_csv_is_lf(sim, tmp_path):
    """Old: panels were named after the trace (`loop:Friction:trace:L000.png`: invalid on
    Windows) and tables were written with CRLF line endings (the csv module's default)."""
    loop = _loop_csv(tmp_path / "loop.csv", sim)
    out = tmp_path / "labels.csv"
    res = _run(["label", loop, "--out", out, "--plots", tmp_path / "plots"])
    assert res.exit_code in (0, 1), res.output
    names = [p.name for p in (tmp_path / "plots").glob("*.png")]
    assert len(names) == 2 and not any(":" in n for n in names)
    assert b"\r\n" not in out.read_bytes()
    assert any(":" in r["trace"] for r in _rows(out))


class _Truth(TraceEstimator):
    """Returns given values: the check then simulates at the truth."""

    name, kind = "truth", "line"

    def __init__(self, U0: float, K: float) -> None:
        self.U0, self.K = U0, K

    def estimate(self, traces, conditions):
        return [{"F_mean_nN": float(t.force_nN.mean()), "U0_eV": self.U0, "K_N_m": self.K,
                 "eta": 1.0} for t in traces], []  # fmt: skip


def test_ppc_overlay_does_not_reuse_the_simulators_seed(sim):
    """Old: the check simulated with seed 0, the simulator's default: a trace simulated
    with seed 0 was compared with its own noise (the replicate equalled the trace)."""
    tr = Trace(x_nm=sim.x_nm, force_nN=sim.force_nN[0], name="sim0")  # seed 0, index 0
    assert inf.ppc_seed("sim0") != 0
    res = inf.infer(_Truth(1.5, 12.0), [tr], classical=False, check=True)
    rep = res.replicates[0]
    n = np.isfinite(rep).sum()
    assert n >= 64
    assert not np.allclose(rep[:n], tr.force_nN[:n])


def test_line_panel_titles_say_95_percent_intervals(traces_dir, line_model, monkeypatch,
                                                    tmp_path):  # fmt: skip
    """Old: the title gave [lo, hi] without saying which interval (68 % or 95 %)."""
    titles: list[str] = []
    monkeypatch.setattr(inf, "plot_overlay", lambda x, f, rep, title, path: titles.append(title))
    from stickslip.estimators.load import load_estimator

    est = load_estimator(str(line_model))
    found, errors = inf.read_inputs([traces_dir])
    result = inf.infer(est, found, errors, classical=False)
    inf.write_panels(result, est, tmp_path / "p")
    assert len(titles) == 2 and all("95 % interval" in t for t in titles)


def test_flagged_trace_plot_draws_no_stick_fit(sim, monkeypatch, tmp_path):
    """Old: `label --plots` drew the stick fits of a trace flagged 'too noisy', as if they
    described it."""
    figs = []
    monkeypatch.setattr(pc, "_save", lambda fig, path: figs.append(fig))
    rng = np.random.default_rng(0)
    f = sim.force_nN[0] + rng.normal(0, 0.5, sim.force_nN.shape[1])
    analysis = analyse_trace(sim.x_nm, f)
    pc.plot_trace_diagnostics(tmp_path / "p.png", sim.x_nm, f, analysis,
                              {"trace": "noisy", "quality": "too noisy"})  # fmt: skip
    labels = [ln.get_label() for ln in figs[0].axes[0].get_lines()]
    assert "stick fits" not in labels
    assert "too noisy" in figs[0].axes[0].get_title()


@needs_ramp
def test_map_lines_failing_alike_give_one_error_line_with_the_count(tmp_path, line_model):
    """Old: one stderr line per refused map line (64 identical lines for one file)."""
    out = tmp_path / "r.csv"
    res = _run(["infer", MAP, "--model", line_model, "--calibration", "10", "--out", out])
    assert res.exit_code == 1
    err = _errors(res)
    assert len(err) == 1 and "64 lines" in err[0] and "si.0_00150" in err[0]
    rows = _rows(out)
    assert len(rows) == 64 and all(r["quality"] not in ("", "ok") for r in rows)


# --- 2. volts are never shown as nN ------------------------------------------------------


def test_label_on_volts_writes_volt_columns_equal_to_the_nN_numbers(sim, tmp_path):
    """Old: a trace in volts (no calibration) was labelled into F_mean_nN, U0_eV, K_N_m:
    volts shown as nN."""
    x, f = sim.x_nm, sim.force_nN[1]
    (tmp_path / "v.csv").write_text(
        "x_nm,force_V\n" + "".join(f"{a:.9g},{b:.9g}\n" for a, b in zip(x, f, strict=True)))
    write_trace_csv(tmp_path / "n.csv", x, f)
    out = tmp_path / "l.csv"
    res = _run(["label", tmp_path / "v.csv", tmp_path / "n.csv", "--temperature", "0",
                "--out", out])  # fmt: skip
    assert res.exit_code == 0, res.output
    volts, newtons = _rows(out)
    assert volts["trace"] == "v" and volts["quality"] == "ok"
    assert volts["F_mean_nN"] == volts["U0_eV"] == volts["K_N_m"] == ""
    assert float(volts["F_mean_V"]) == pytest.approx(float(newtons["F_mean_nN"]))
    assert float(volts["K_V_per_nm"]) == pytest.approx(float(newtons["K_N_m"]), rel=1e-4)
    # U0 = F_max a / pi: in V nm, the eV figure times 0.1602 nN nm / eV
    assert float(volts["U0_V_nm"]) == pytest.approx(0.160218 * float(newtons["U0_eV"]),
                                                    rel=1e-4)  # fmt: skip
    assert float(volts["eta"]) == pytest.approx(float(newtons["eta"]), rel=1e-4)
    assert newtons["F_mean_V"] == ""


def test_label_plot_of_volts_has_a_volt_axis(sim, monkeypatch, tmp_path):
    """Old: `label --plots` on a trace in volts said 'lateral force F (nN)'."""
    figs = []
    monkeypatch.setattr(pc, "_save", lambda fig, path: figs.append(fig))
    tr = Trace(x_nm=sim.x_nm, force_nN=sim.force_nN[0], name="v", meta={"unit": "V",
               "calibrated": False})  # fmt: skip
    result = inf.infer(ClassicalEstimator(), [tr], temperature_K=0.0)
    inf.write_panels(result, ClassicalEstimator(), tmp_path / "p")
    ax = figs[0].axes[0]
    assert "(V)" in ax.get_ylabel() and "nN" not in ax.get_ylabel()
    assert "eV" not in ax.get_title() and "N/m" not in ax.get_title()


@needs_ramp
def test_learned_estimators_refuse_volts_naming_calibration(tmp_path, line_model):
    """Old: the line and window models read volts as nN and gave U0 and K from them."""
    for model in (line_model, "window"):
        out = tmp_path / "r.csv"
        res = _run(["infer", MAP, "--model", model, "--out", out])
        assert res.exit_code == 1
        err = _errors(res)
        assert len(err) == 1 and "--calibration" in err[0] and "64 lines" in err[0], err
        rows = _rows(out)
        assert len(rows) == 64 and all("--calibration" in r["quality"] for r in rows)
        assert all(r.get("U0_eV", "") == "" and r.get("U0_V_nm", "") == "" for r in rows)


@needs_ramp
def test_by_load_report_in_volts_with_line_scatter_and_marked_empty_panels(tmp_path,
                                                                          monkeypatch):  # fmt: skip
    """Old: <out>.by_load.png said nN for volts, its error bars were the lateral offset
    (trace and retrace means differ by twice the offset, about 5.8 V here, while the
    friction is 0.03 V) and its U0/K panels were empty without a word."""
    calls = []
    real = loads_mod.plot_versus_load

    def spy(summary, quantities, out, *a, **k):
        calls.append((list(summary), list(quantities)))
        return real(summary, quantities, out, *a, **k)

    monkeypatch.setattr(loads_mod, "plot_versus_load", spy)
    out = tmp_path / "lab.csv"
    res = _run(["label", MAP, "--lines-per-load", "16", "--loads", "1,2", "--out", out])
    assert res.exit_code in (0, 1), res.output
    summary, quantities = calls[0]
    labels = [lab for _, lab in quantities]
    assert all("nN" not in lab and "eV" not in lab and "N/m" not in lab for lab in labels)
    assert any("(V)" in lab for lab in labels)
    by_load = _rows(tmp_path / "lab.by_load.csv")
    assert [r["load"] for r in by_load] == ["1.0", "2.0"]
    for r in by_load:
        assert abs(float(r["F_mean_V_mean"])) < 0.1
        assert float(r["F_mean_V_std"]) < 0.1  # scatter of the line frictions, not the offset
    png = tmp_path / "lab.by_load.png"
    assert png.stat().st_size > 1000


def test_empty_load_panels_say_why(tmp_path, monkeypatch):
    """Old: a panel with no value in any load group was drawn empty, without a word."""
    from stickslip.diagnostics import plots_load

    figs = []
    import matplotlib.figure

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", lambda self, *a, **k: figs.append(
        self))  # fmt: skip
    summary = [{"load": 1.0, "load_unit": "nN", "n": 4, "F_mean_nN_mean": 1.0,
                "F_mean_nN_std": 0.1, "U0_eV_mean": float("nan"), "U0_eV_std": float("nan")}]
    plots_load.plot_versus_load(summary, [("F_mean_nN", "F"), ("U0_eV", "U0")],
                                tmp_path / "x.png")  # fmt: skip
    texts = [t.get_text() for t in figs[0].axes[1].texts]
    assert any("no estimate" in t for t in texts)


# --- 3. a calibration given by the user wins ---------------------------------------------


@needs_ramp
def test_user_calibration_wins_over_the_files(monkeypatch):
    """Old: a calibration stored in the file silently replaced --calibration."""
    real = readers.SCAN_READERS[".spm"]

    def with_stored(path):
        scan = real(path)
        scan.meta["calibration_nN_per_V"] = 3.0
        return scan

    monkeypatch.setitem(readers.SCAN_READERS, ".spm", with_stored)
    volts = read_file(MAP)  # uncalibrated reference: the stored 3 nN/V applies
    raw = read_file(MAP, calibration_nN_per_V=7.0)
    assert volts[0].meta["calibration_nN_per_V"] == 3.0
    assert volts[0].meta["calibration_source"] == "file"
    assert raw[0].meta["calibration_nN_per_V"] == 7.0
    assert raw[0].meta["calibration_source"] == "flag"
    np.testing.assert_allclose(raw[0].force_nN, volts[0].force_nN * 7.0 / 3.0)


# --- 4. a single NaN pixel does not reject a map ------------------------------------------


def test_single_nan_pixel_is_masked_in_a_friction_loop(sim, tmp_path):
    """Old: one NaN pixel rejected the whole file ('contains NaN or infinite values')."""
    loop = _loop_csv(tmp_path / "loop.csv", sim, nan_at=100)
    out = tmp_path / "l.csv"
    res = _run(["label", loop, "--out", out])
    assert res.exit_code == 0, res.output
    rows = {r["direction"]: r for r in _rows(out)}
    assert rows["trace"]["masked_pixels"] == "1" and rows["trace"]["quality"] == "ok"
    assert rows["retrace"].get("masked_pixels", "") in ("", "0")


def test_mostly_nan_line_is_refused_with_a_reason_and_the_rest_estimated(sim):
    """Old: any NaN in a map made the reader raise: no trace of the file was estimated."""
    img = np.tile(sim.force_nN[1], (3, 1))
    img[0, 40] = np.nan  # one pixel
    img[2, : 400] = np.nan  # most of the line
    scan = ScanFile(path=Path("m.spm"), fmt="test", scan_size_nm=11.0)
    scan.channels = [Channel("Friction", TRACE, "nN", img.shape, img),
                     Channel("Friction", RETRACE, "nN", img.shape, img[:, ::-1] * -1)]
    traces = map_to_traces(scan)
    assert all(np.all(np.isfinite(t.force_nN)) for t in traces)
    by = {(t.meta["line"], t.meta["direction"]): t for t in traces}
    assert by[(0, "trace")].meta["masked_pixels"] == 1
    assert by[(1, "trace")].meta["masked_pixels"] == 0
    table = ClassicalEstimator().predict(traces)
    q = {(r["line"], r["direction"]): r["quality"] for r in table.rows}
    assert q[(0, "trace")] == "ok" and q[(1, "trace")] == "ok"
    assert "NaN" in q[(2, "trace")] and "400 of 512" in q[(2, "trace")]


# --- 5. a profile without an x axis -------------------------------------------------------


def test_profile_without_x_axis_names_the_missing_x_unit(sim, tmp_path, line_model):
    """Old: positions were pixel indices read as nm, so the reason was 'pixel 1 nm does not
    resolve the 0.246 nm lattice' (and label fitted slopes per pixel as per nm)."""
    np.save(tmp_path / "p.npy", sim.force_nN[0])
    (tmp_path / "c.csv").write_text("force_nN\n" + "\n".join(f"{v:.6f}" for v in sim.force_nN[0]))
    for cmd in (["infer", "--model", line_model], ["label"]):
        out = tmp_path / "r.csv"
        res = _run([cmd[0], tmp_path / "p.npy", tmp_path / "c.csv", *cmd[1:], "--out", out])
        assert res.exit_code == 1
        for row in _rows(out):
            assert "pixel index" in row["quality"] and "x_nm" in row["quality"], row
            assert "1 nm" not in row["quality"]
    res = _run(["inspect", tmp_path / "p.npy"])
    assert "pixel index" in res.stdout and "511 nm" not in res.stdout
    (tmp_path / "h.txt").write_text("\n".join(f"{v:.6f}" for v in sim.force_nN[0]))
    res = _run(["label", tmp_path / "h.txt", "--out", out])
    err = _errors(res)
    assert len(err) == 1 and "no header" in err[0] and "x axis" in err[0]


# --- 6. loads are never written as None ---------------------------------------------------


@needs_ramp
def test_loads_and_missing_values_are_empty_cells_never_none_or_nan(tmp_path):
    """Old: the per-load table wrote 'nan' for groups without an estimate, and rows
    without a load wrote 'None'."""
    out = tmp_path / "lab.csv"
    res = _run(["label", MAP, "--calibration", "10", "--lines-per-load", "16", "--loads",
                "1,2", "--out", out])  # fmt: skip
    assert res.exit_code in (0, 1), res.output
    for path in (out, tmp_path / "lab.by_load.csv"):
        text = path.read_text()
        cells = [c for line in text.splitlines() for c in line.split(",")]
        assert "None" not in cells and "nan" not in cells, path
    rows = _rows(out)
    assert {r["load"] for r in rows} == {"1", "2"}


# --- 7. --check: fast, and still meaningful -----------------------------------------------


@pytest.fixture(scope="module")
def clean_and_defective(pool):
    """Three clean lines and three a PT line at the estimate does not describe."""
    U0, K = np.array(POOL_U0[2:]), np.array(POOL_K[2:])
    F = pool.force_nN[2:] + np.random.default_rng(1).normal(0, 0.02, (6, pool.x_nm.size))
    F[3, 200:] += 1.5  # a domain crossing: the friction level jumps mid-line
    F[4, 250:330] = F[4, 250]  # a lost contact: the force stays flat for 1.7 nm
    U0_est, K_est = U0.copy(), K.copy()
    U0_est[5], K_est[5] = 1.4 * U0[5], 0.6 * K[5]  # a wrong estimate
    return pool.x_nm, F, U0_est, K_est


def test_check_flag_separates_clean_from_defective_traces(clean_and_defective):
    """The faster check keeps its verdicts: clean traces at their truth pass; a domain
    crossing, a lost contact and a wrong estimate are flagged. Old: the same verdicts at
    1/20 of the speed, except the 1.7 nm lost contact (gof 1.8 on a similar line: missed)."""
    x, F, U0, K = clean_and_defective
    res = posterior_predictive_check(x, F, U0, K, seed=4)
    assert not res.flagged[:3].any(), res.gof
    assert res.flagged[3:].all(), res.gof
    assert res.gof[3:].min() > 1.5 * res.gof[:3].max()


@pytest.mark.slow
def test_check_runs_at_least_10_traces_per_cpu_second(clean_and_defective):
    """Old: 8 replicates of the full line at dt = 10 ns: about 0.5 traces per CPU second."""
    x, F, U0, K = clean_and_defective
    posterior_predictive_check(x, F[:1], U0[:1], K[:1], seed=1)  # compile
    F20 = np.tile(F[:3], (7, 1))[:20]
    U20, K20 = np.tile(U0[:3], 7)[:20], np.tile(K[:3], 7)[:20]
    t = time.process_time()
    posterior_predictive_check(x, F20, U20, K20, seed=2)
    assert 20 / (time.process_time() - t) >= 10


def test_infer_check_reports_progress_per_batch(sim, monkeypatch):
    """Old: the whole check ran as one batch per trace length: no progress until the end."""
    monkeypatch.setattr(inf, "CHECK_BATCH", 2)
    traces = [Trace(x_nm=sim.x_nm, force_nN=sim.force_nN[i % 2], name=f"t{i}") for i in range(5)]
    seen: list[int] = []
    inf.infer(_Truth(1.5, 12.0), traces, classical=False, check=True, progress=seen.append)
    assert seen == [2, 4, 5]


# --- 8. progress on a terminal, quiet under -q ---------------------------------------------


def test_quiet_prints_nothing_but_errors(traces_dir, tmp_path):
    """Old: -q still printed status lines (and bars) of infer and label on stderr."""
    (tmp_path / "bad.csv").write_text("x_nm,force_nN\n0,1\n")
    for cmd in (["infer", "--model", "classical", "--check"], ["label"]):
        out = tmp_path / "r.csv"
        res = _run(["-q", cmd[0], traces_dir, tmp_path / "bad.csv", *cmd[1:], "--out", out,
                    "--plots", tmp_path / "p"])  # fmt: skip
        assert res.exit_code == 1, res.output
        assert res.stdout == ""
        err = [ln for ln in res.stderr.splitlines() if ln.strip()]
        assert err and all(ln.startswith("stickslip: error: ") for ln in err), err
        assert len(_rows(out)) == 3


def test_progress_bars_on_a_terminal(traces_dir, tmp_path, monkeypatch):
    """Old: infer --check and --plots ran silently for minutes, with no progress bar."""
    monkeypatch.setattr(common, "show_progress", lambda: True)
    res = _run(["infer", traces_dir, "--model", "classical", "--check", "--plots",
                tmp_path / "p", "--out", tmp_path / "r.csv"])  # fmt: skip
    assert res.exit_code == 0, res.output
    assert "check" in res.stderr and "2/2" in res.stderr
    assert "panels" in res.stderr


def test_collect_traces_reports_progress_per_file(traces_dir):
    """Old: reading a folder of files gave no progress."""
    seen: list[int] = []
    traces, _ = collect_traces([traces_dir], progress=seen.append)
    assert len(traces) == 2 and seen == [1, 2]
