"""The bundled line model on freshly simulated traces unlike its training set."""

import numpy as np
import pytest

from stickslip.diagnostics.calibration import coverage
from stickslip.estimators.line.ensemble import predict_raw_lines
from stickslip.estimators.line.modelfile import load_line_model
from stickslip.simulators import simulate
from stickslip.simulators.bench import BenchConfig, make_bench
from stickslip.simulators.config import ParameterRange
from stickslip.simulators.sampling import sample_parameters
from stickslip.traces.dataset import load_dataset


@pytest.fixture(scope="module")
def model():
    return load_line_model(None)


@pytest.mark.slow  # 45 bench traces: about two minutes (test_clean_paper_traces is the fast one)
def test_bench_like_traces(model, tmp_path_factory):
    # lab effects, three lattices, 30 nm/s; seed disjoint from training and the bench
    path = make_bench(BenchConfig(n_per_material=15, seed=777),
                      tmp_path_factory.mktemp("b") / "b.h5", progress=False)  # fmt: skip
    d = load_dataset(path)
    p = d.params
    pred = predict_raw_lines(model, [d.x_nm] * d.n, list(d.force_nN.astype(float)),
                             p["lattice_nm"], p["velocity_nm_per_s"])  # fmt: skip
    rel = {k: np.sqrt(np.mean((pred.values[k] / p[k] - 1) ** 2)) for k in ("U0_eV", "K_N_m")}
    # bench (360 traces of benchmarks/families.py): 5.4-6.4 %, 5.1-6.8 %, <F> 0.026-0.032
    # nN; these 45: 6.1 %, 5.2 %, 0.030 nN (the model of 6,300 trajectories before it:
    # 6.8 %, 6.0 %, 0.041 nN; the one before the effect families: 5.7 %, 3.1 %, 0.021 nN).
    # The bounds: the robustness issue's lab-like targets (U0 7 %, K 12 %, <F> 0.05 nN)
    # with room for 45 traces on U0
    assert rel["U0_eV"] < 0.09 and rel["K_N_m"] < 0.09, rel
    assert np.sqrt(np.mean((pred.values["F_mean_nN"] - p["F_mean_nN"]) ** 2)) < 0.05
    for k in ("U0_eV", "K_N_m"):
        assert coverage(p[k], pred.lo95[k], pred.hi95[k]) >= 0.85


def test_clean_paper_traces(model):
    U0, K = sample_parameters(ParameterRange(eta=(1.5, 40.0)), 40, seed=99, lattice_nm=0.246)
    r = simulate(U0, K, seed=99)
    n = U0.size
    pred = predict_raw_lines(model, [r.x_nm] * n, list(r.force_nN), np.full(n, 0.246),
                             np.full(n, 60.0))  # fmt: skip
    # these 40: 0.0126 eV, K 1.86 % (0.237 N/m); the same members without the location
    # calibration, which takes off the K that noise adds and so moves noiseless lines a
    # little: 1.79 % (0.198 N/m). The model of 6,300 trajectories before it: 0.0138 eV,
    # 1.55 %; the model before the effect families: 0.0095 eV and 1.16 %. The learning
    # issue's figure is 0.0145 eV; the model trained with one beta for means and
    # variances got 0.017 here, the one before it 0.028. K's absolute RMSE is set by the
    # stiffest contacts (50 N/m: 1 % is 0.5 N/m); the paper's is 0.84 N/m.
    assert model.expert is not None
    assert np.sqrt(np.mean((pred.values["U0_eV"] - U0) ** 2)) < 0.0145
    assert np.sqrt(np.mean((pred.values["K_N_m"] / K - 1) ** 2)) < 0.02
    assert np.sqrt(np.mean((pred.values["K_N_m"] - K) ** 2)) < 0.3
    assert coverage(U0, pred.lo95["U0_eV"], pred.hi95["U0_eV"]) >= 0.9
