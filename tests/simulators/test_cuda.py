"""The CUDA backend (issue 20), checked on numba's CUDA simulator against the CPU kernel.

The simulator must be switched on before numba.cuda is first imported, so the GPU cases
run once in a subprocess (this file run as a script with ``NUMBA_ENABLE_CUDASIM=1``),
which saves the traces; the tests below compare them. The cases are tiny (a few
trajectories, 16 pixels of 0.03 nm at 6e4 nm/s, 0.3 nm warm-up): the simulator runs the
kernel as Python, ~1e4 steps per second.

Backend selection (``auto``, a missing device, the CLI) is tested in this process, where
no device is assumed: ``cuda_available`` is patched to False so the tests hold on a
machine with a GPU too.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

# float32 vs float64 at T = 0: largest pixel difference relative to F_max = pi U0 / a
# (documented in stickslip.simulators.cuda; measured ~2e-6 there)
F32_REL_TOL = 2e-5

U0_T0 = np.array([1.0, 2.0, 3.0])
K_T0 = np.array([10.0, 20.0, 30.0])
N_THERMAL = 8  # trajectories of one (U0, K) at 296 K: the spread is thermal only
U0_TH, K_TH = 1.0, 10.0


def _settings(temperature_K: float):
    from stickslip.simulators import PhysicalSettings

    return PhysicalSettings(
        velocity_nm_per_s=6e4, temperature_K=temperature_K, length_nm=0.48, pixels=16,
        warmup_nm=0.3,
    )  # fmt: skip


def _substrate(n: int):
    """Modulation and two defects inside the recorded stretch of the tip's path."""
    mod = (np.full(n, 0.3), np.full(n, 5.0), np.full(n, 0.7))
    dfx = (
        np.tile([0.45, 0.62], (n, 1)),
        np.tile([0.3, -0.25], (n, 1)),
        np.tile([0.1, 0.15], (n, 1)),
    )
    return mod, dfx


def _run_cases(out: Path) -> None:
    """Everything that needs the (simulated) device; saved to ``out`` (npz)."""
    from stickslip.simulators import SweepConfig, run_sweep, simulate
    from stickslip.simulators.cuda import device_name
    from stickslip.traces.dataset import load_dataset, read_attrs

    r: dict[str, np.ndarray] = {}
    s0, sT = _settings(0.0), _settings(296.0)
    for b in ("cpu", "cuda", "cuda-float32"):
        res = simulate(U0_T0, K_T0, s0, seed=5, backend=b, samples_per_pixel=2)
        r[f"t0_{b}"] = res.force_nN
        r[f"t0_{b}_fine_x"], r[f"t0_{b}_fine_F"] = res.fine_x_nm, res.fine_force_nN
        mod, dfx = _substrate(U0_T0.size)
        r[f"aug_{b}"] = simulate(
            U0_T0, K_T0, s0, seed=5, backend=b, modulation=mod, defects=dfx
        ).force_nN
        u, k = np.full(N_THERMAL, U0_TH), np.full(N_THERMAL, K_TH)
        r[f"th_{b}"] = simulate(u, k, sT, seed=9, backend=b).force_nN
    r["th_cuda_seed10"] = simulate(u, k, sT, seed=10, backend="cuda").force_nN
    tiny = SweepConfig(physics=sT, n=3, seed=1)
    for b in ("cpu", "cuda"):
        path = run_sweep(tiny, out.with_name(f"sweep_{b}.h5"), backend=b, progress=False)
        r[f"sweep_{b}"] = load_dataset(path).force_nN
        r[f"sweep_{b}_config"] = np.array(read_attrs(path)["config"])
    r["device"] = np.array(device_name())
    np.savez(out, **r)


@pytest.fixture(scope="module")
def sim(tmp_path_factory) -> dict[str, np.ndarray]:
    out = tmp_path_factory.mktemp("cudasim") / "cases.npz"
    env = dict(os.environ, NUMBA_ENABLE_CUDASIM="1")
    p = subprocess.run(
        [sys.executable, __file__, str(out)], env=env, capture_output=True, text=True,
        timeout=600,
    )  # fmt: skip
    assert p.returncode == 0, p.stderr[-3000:]
    with np.load(out) as z:
        return {k: z[k] for k in z.files}


def _fmax(U0_eV):
    from stickslip.units import fmax_nN

    return fmax_nN(np.asarray(U0_eV), 0.246)


def test_runs_on_the_simulator(sim):
    assert str(sim["device"]) == "CUDA simulator"


def test_t0_matches_cpu_kernel(sim):
    cpu, gpu = sim["t0_cpu"], sim["t0_cuda"]
    assert cpu.shape == gpu.shape == (3, 16)
    # slips happen in the recorded window, so the comparison covers them
    assert np.all(np.diff(cpu, axis=1).min(axis=1) < -0.3 * _fmax(U0_T0))
    np.testing.assert_allclose(gpu, cpu, rtol=1e-6, atol=1e-6 * _fmax(U0_T0).max())


def test_fine_records_match_cpu(sim):
    for what in ("fine_x", "fine_F"):
        cpu, gpu = sim[f"t0_cpu_{what}"], sim[f"t0_cuda_{what}"]
        assert cpu.shape == gpu.shape == (3, 32)
        np.testing.assert_allclose(gpu, cpu, rtol=1e-6, atol=1e-9)


def _slips(F: np.ndarray, fmax: float) -> tuple[np.ndarray, np.ndarray]:
    """Per trace: number of slips (pixel drop > F_max / 4) and the mean force before them."""
    drop = -np.diff(F, axis=1)
    is_slip = drop > 0.25 * fmax
    count = is_slip.sum(axis=1).astype(float)
    peak = (F[:, :-1] * is_slip).sum(axis=1) / np.maximum(count, 1.0)
    return count, peak


def _agree_within_se(a: np.ndarray, b: np.ndarray) -> None:
    """Means of two samples of per-trace statistics agree within 2 combined standard errors."""
    se = np.hypot(a.std(ddof=1), b.std(ddof=1)) / np.sqrt(a.size)
    assert abs(a.mean() - b.mean()) <= 2 * se + 1e-12, (a.mean(), b.mean(), se)


def test_finite_t_same_seeds_same_statistics(sim):
    cpu, gpu = sim["th_cpu"], sim["th_cuda"]
    fmax = float(_fmax(U0_TH))
    _agree_within_se(gpu.mean(axis=1), cpu.mean(axis=1))
    (n_c, p_c), (n_g, p_g) = _slips(cpu, fmax), _slips(gpu, fmax)
    assert n_c.mean() >= 1.0  # every trace slips: the statistics are about something
    _agree_within_se(n_g, n_c)
    _agree_within_se(p_g, p_c)
    # the same streams: on the simulator (IEEE arithmetic, no fused multiply-add) the
    # traces agree sample by sample; another seed differs by the thermal noise
    assert np.abs(gpu - cpu).max() < 1e-6 * fmax
    assert np.abs(sim["th_cuda_seed10"] - gpu).max() > 1e-2 * fmax


def test_float32_within_documented_tolerance(sim):
    f32, f64 = sim["t0_cuda-float32"], sim["t0_cuda"]
    rel = np.abs(f32 - f64).max(axis=1) / _fmax(U0_T0)
    assert rel.max() < F32_REL_TOL
    aug = np.abs(sim["aug_cuda-float32"] - sim["aug_cuda"]).max(axis=1) / _fmax(U0_T0)
    assert aug.max() < F32_REL_TOL
    th32, th64 = sim["th_cuda-float32"], sim["th_cuda"]
    _agree_within_se(th32.mean(axis=1), th64.mean(axis=1))
    fmax = float(_fmax(U0_TH))
    _agree_within_se(_slips(th32, fmax)[0], _slips(th64, fmax)[0])


def test_augmented_substrate_on_device(sim):
    cpu, gpu, plain = sim["aug_cpu"], sim["aug_cuda"], sim["t0_cuda"]
    np.testing.assert_allclose(gpu, cpu, rtol=1e-6, atol=1e-6 * _fmax(U0_T0).max())
    # the modulation and defects change the trace: the device really evaluates them
    assert np.abs(gpu - plain).max() > 0.05 * _fmax(U0_T0).min()


def test_sweep_records_backend_only_when_not_cpu(sim):
    cfg_cpu = json.loads(str(sim["sweep_cpu_config"]))
    cfg_gpu = json.loads(str(sim["sweep_cuda_config"]))
    assert "backend" not in cfg_cpu  # cpu files keep the JSON they always had
    assert cfg_gpu["backend"] == "cuda"
    np.testing.assert_allclose(sim["sweep_cuda"], sim["sweep_cpu"], rtol=1e-5, atol=1e-6)


# --- backend selection, in this process (no device assumed) ---------------------------


@pytest.fixture
def no_device(monkeypatch):
    from stickslip.simulators import cuda as cuda_mod

    monkeypatch.setattr(cuda_mod, "cuda_available", lambda: False)


def test_auto_falls_back_to_cpu(no_device):
    from stickslip.simulators import PhysicalSettings, simulate
    from stickslip.simulators.backends import resolve_backend

    assert resolve_backend("auto") == "cpu"
    assert resolve_backend("numba") == "cpu"
    s = PhysicalSettings(velocity_nm_per_s=600.0, length_nm=0.2, pixels=8, warmup_nm=0.1)
    a = simulate([1.0, 2.0], [10.0, 20.0], s, seed=3, backend="auto").force_nN
    b = simulate([1.0, 2.0], [10.0, 20.0], s, seed=3, backend="cpu").force_nN
    np.testing.assert_array_equal(a, b)


def test_cuda_without_device_is_a_settings_error(no_device):
    from stickslip.simulators import SettingsError
    from stickslip.simulators.backends import resolve_backend

    for name in ("cuda", "cuda-float32"):
        with pytest.raises(SettingsError, match="no CUDA device"):
            resolve_backend(name)
    with pytest.raises(ValueError, match="unknown backend"):
        resolve_backend("gpu")


def test_cli_backend_cuda_without_device(no_device, tmp_path):
    from typer.testing import CliRunner

    from stickslip.cli.main import app

    runner = CliRunner()
    for args in (["--u0", "1", "--k", "10"], ["--n", "4", "--no-progress"]):
        out = tmp_path / ("t.csv" if "--u0" in args else "s.h5")
        r = runner.invoke(app, ["simulate", *args, "--backend", "cuda", "--out", str(out)])
        assert r.exit_code == 2
        err = r.stderr.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("stickslip: error: ") and "CUDA" in err[0]
        assert not out.exists() and not list(tmp_path.glob("s.h5*"))


def test_sweep_config_json_backend():
    from stickslip.simulators import SweepConfig

    cpu = SweepConfig(n=4)
    assert "backend" not in json.loads(cpu.to_json())
    gpu = SweepConfig(n=4, backend="cuda-float32")
    assert SweepConfig.from_json(gpu.to_json()) == gpu
    assert SweepConfig.from_json(cpu.to_json()) == cpu


def test_import_restores_the_row_stack_that_numba_cuda_needs():
    """numba-cuda 0.30.4 registers np.row_stack, which numpy 2.5 removed (on a device
    with numpy 2.5.2 no kernel ran without the alias); the backend module puts it back."""
    code = (
        "import numpy as np\n"
        "np.__dict__.pop('row_stack', None)\n"
        "import stickslip.simulators.cuda\n"
        "assert np.row_stack is np.vstack\n"
    )
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr[-2000:]


if __name__ == "__main__":
    _run_cases(Path(sys.argv[1]))
