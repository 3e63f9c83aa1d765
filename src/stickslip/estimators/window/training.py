"""Training: windows of simulated traces -> standardised targets, the paper's recipe.

The split is by trajectory (never by window), 80/20, seeded. Every window of a
trajectory carries that trajectory's labels. Loss: sum over targets of the mean
squared error of the standardised (optionally log-transformed) targets. Adam,
lr 5e-4, batch 300, 50 epochs (reference paper). Normalisation statistics of inputs
and targets come from the training windows only and are saved in the model.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
import torch
from tqdm.auto import tqdm

from stickslip.estimators.split import split_indices
from stickslip.estimators.window.features import FeatureSpec, window_features, windows
from stickslip.estimators.window.modelfile import TrainedModel
from stickslip.estimators.window.models import PAPER_MLP, build_model
from stickslip.traces.dataset import Dataset

TARGETS = ("F_mean_nN", "U0_eV", "K_N_m")


@dataclass
class TrainConfig:
    """Optimisation settings (saved in the model file).

    ``noise_nN`` > 0 augments the training windows with white detector noise, redrawn
    every epoch: each window gets Gaussian noise of its own standard deviation, drawn
    uniformly in ``[0, noise_nN]`` (0: the reference paper's clean training).
    ``keep_best``: keep the weights of the epoch with the lowest validation loss (at a
    constant learning rate the last epoch's weights scatter; the paper's recipe is
    otherwise unchanged). ``log_targets`` lists targets the network predicts as
    logarithms. ``threads``:
    torch threads while training; batches of 300 small vectors gain nothing from more,
    and on a shared machine several OpenMP threads spin against other jobs (measured
    here: 15x slower with 2 threads than with 1 on 2 busy cores).
    """

    epochs: int = 50
    batch_size: int = 300
    lr: float = 5e-4
    seed: int = 0
    val_fraction: float = 0.2
    log_targets: tuple[str, ...] = ()
    noise_nN: float = 0.0
    keep_best: bool = True
    threads: int = 1

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["log_targets"] = list(self.log_targets)
        return d


@dataclass
class History:
    """Losses per epoch (sum over targets of standardised MSE) and wall time."""

    train_loss: list[float] = field(default_factory=list)
    val_loss: list[float] = field(default_factory=list)
    seconds: float = 0.0
    best_epoch: int = 0


def split_by_trajectory(
    n: int, val_fraction: float = 0.2, seed: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """Seeded split of trajectory indices into (train, validation), each sorted
    (:func:`stickslip.estimators.split.split_indices`)."""
    train, val = split_indices(n, val_fraction, np.random.default_rng(seed))
    return np.sort(train), np.sort(val)


def target_matrix(params: dict[str, np.ndarray], log_targets: tuple[str, ...]) -> np.ndarray:
    """Targets ``(N, 3)`` in network space (log where asked)."""
    cols = [np.asarray(params[t], dtype=np.float64) for t in TARGETS]
    cols = [np.log(c) if t in log_targets else c for t, c in zip(TARGETS, cols, strict=True)]
    return np.stack(cols, axis=1)


def window_set(
    force_nN: np.ndarray, y: np.ndarray, spec: FeatureSpec, stride: int
) -> tuple[np.ndarray, np.ndarray]:
    """All windows of the given traces ``(M, p)`` and their trajectories' targets ``(M, 3)``."""
    win = windows(np.asarray(force_nN, dtype=np.float32), spec.window, stride)
    n, w = win.shape[:2]
    return win.reshape(n * w, spec.window), np.repeat(y, w, axis=0)


def noisy(win: np.ndarray, noise_nN: float, rng: np.random.Generator) -> np.ndarray:
    """Windows plus white noise, one standard deviation per window in ``[0, noise_nN]``."""
    if noise_nN <= 0:
        return win
    sigma = rng.uniform(0.0, noise_nN, (win.shape[0], 1)).astype(np.float32)
    return win + sigma * rng.standard_normal(win.shape, dtype=np.float32)


def _stats(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    mean = a.mean(axis=0)
    std = a.std(axis=0)
    return mean, np.where(std > 1e-12, std, 1.0)


def spec_for_dataset(data: Dataset, recipe: str, window: int, stride: int, train_stride: int):
    """Feature spec with the dataset's pixel size, lattice, velocity and temperature."""
    p = data.params
    x = np.asarray(data.x_nm, dtype=float)
    return FeatureSpec(
        recipe=recipe,
        window=window,
        stride=stride,
        train_stride=train_stride,
        pixel_nm=float((x[-1] - x[0]) / (x.size - 1)),
        lattice_nm=float(np.median(p["lattice_nm"])),
        velocity_nm_per_s=float(np.median(p["velocity_nm_per_s"])),
        temperature_K=float(np.median(p["temperature_K"])),
    )


def _epoch_loss(net: torch.nn.Module, x: torch.Tensor, y: torch.Tensor) -> float:
    net.eval()
    with torch.inference_mode():
        total = 0.0
        for s in range(0, x.shape[0], 1 << 15):
            d = net(x[s : s + (1 << 15)]) - y[s : s + (1 << 15)]
            total += float((d**2).sum())
    return total / max(x.shape[0], 1)


def train_model(
    data: Dataset,
    spec: FeatureSpec,
    config: TrainConfig | None = None,
    arch: dict[str, Any] | None = None,
    progress: bool = True,
    train_idx: np.ndarray | None = None,
    val_idx: np.ndarray | None = None,
) -> tuple[TrainedModel, History, np.ndarray]:
    """Train a network on a simulated dataset.

    Parameters
    ----------
    data : Dataset
        Simulated sweep (labels in ``params``).
    spec : FeatureSpec
        Input recipe and window settings.
    config : TrainConfig, optional
        Optimisation settings (default: the reference paper's).
    arch : dict, optional
        Architecture (default: the paper's MLP 256-128).
    progress : bool
        Show a progress bar with the losses.
    train_idx, val_idx : ndarray, optional
        Explicit trajectory split (default: seeded 80/20 split by trajectory).

    Returns
    -------
    model : TrainedModel
    history : History
    val_idx : ndarray
        Validation trajectories (for evaluation on trajectories never trained on).
    """
    cfg = config or TrainConfig()
    threads = torch.get_num_threads()
    torch.set_num_threads(max(1, cfg.threads))
    try:
        return _train(data, spec, cfg, dict(arch or PAPER_MLP), progress, train_idx, val_idx)
    finally:
        torch.set_num_threads(threads)


def _train(
    data: Dataset,
    spec: FeatureSpec,
    cfg: TrainConfig,
    arch: dict[str, Any],
    progress: bool,
    train_idx: np.ndarray | None,
    val_idx: np.ndarray | None,
) -> tuple[TrainedModel, History, np.ndarray]:
    if train_idx is None or val_idx is None:
        train_idx, val_idx = split_by_trajectory(data.n, cfg.val_fraction, cfg.seed)
    y_all = target_matrix(data.params, cfg.log_targets)
    wtr, ytr = window_set(data.force_nN[train_idx], y_all[train_idx], spec, spec.train_stride)
    wva, yva = window_set(data.force_nN[val_idx], y_all[val_idx], spec, spec.stride)
    rng = np.random.default_rng(cfg.seed)
    xtr = window_features(noisy(wtr, cfg.noise_nN, rng), spec)
    x_mean, x_std = _stats(xtr)
    y_mean, y_std = _stats(ytr)
    norm = {"x_mean": x_mean, "x_std": x_std, "y_mean": y_mean, "y_std": y_std}
    norm = {k: v.astype(np.float32) for k, v in norm.items()}

    def tensors(x: np.ndarray, y: np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
        xs = ((x - norm["x_mean"]) / norm["x_std"]).astype(np.float32)
        ys = ((y - y_mean) / y_std).astype(np.float32)
        return torch.from_numpy(xs), torch.from_numpy(ys)

    Xtr, Ytr = tensors(xtr, ytr)
    # validation windows carry the training noise distribution (one fixed draw), so the
    # loss curve and the best-epoch choice measure what the network is trained for
    Xva, Yva = tensors(window_features(noisy(wva, cfg.noise_nN, rng), spec), yva)
    del xtr
    torch.manual_seed(cfg.seed)
    gen = torch.Generator().manual_seed(cfg.seed)
    net = build_model(arch, spec.n_inputs, len(TARGETS))
    opt = torch.optim.Adam(net.parameters(), lr=cfg.lr)
    hist = History()
    t0 = time.perf_counter()
    bar = tqdm(range(cfg.epochs), disable=not progress, desc="train", unit="epoch")
    for epoch in bar:
        if epoch and cfg.noise_nN > 0:  # fresh noise every epoch
            Xtr = tensors(window_features(noisy(wtr, cfg.noise_nN, rng), spec), ytr)[0]
        net.train()
        perm = torch.randperm(Xtr.shape[0], generator=gen)
        total = 0.0
        for s in range(0, Xtr.shape[0], cfg.batch_size):
            b = perm[s : s + cfg.batch_size]
            opt.zero_grad(set_to_none=True)
            # sum over targets of the per-target mean squared error
            loss = ((net(Xtr[b]) - Ytr[b]) ** 2).mean(dim=0).sum()
            loss.backward()
            opt.step()
            total += float(loss.detach()) * b.numel()
        hist.train_loss.append(total / Xtr.shape[0])
        hist.val_loss.append(_epoch_loss(net, Xva, Yva))
        bar.set_postfix(train=f"{hist.train_loss[-1]:.4f}", val=f"{hist.val_loss[-1]:.4f}")
        if cfg.keep_best and hist.val_loss[-1] <= min(hist.val_loss):
            best = {k: v.detach().clone() for k, v in net.state_dict().items()}
            hist.best_epoch = len(hist.val_loss)
    hist.seconds = time.perf_counter() - t0
    if cfg.keep_best:
        net.load_state_dict(best)
    net.eval()
    model = TrainedModel(
        net=net,
        features=spec,
        normalisation=norm,
        targets=list(TARGETS),
        transforms={t: ("log" if t in cfg.log_targets else "linear") for t in TARGETS},
        arch=arch,
        train_config={
            **cfg.to_dict(),
            "n_train_trajectories": int(train_idx.size),
            "n_val_trajectories": int(val_idx.size),
            "n_train_windows": int(Xtr.shape[0]),
            "train_seconds": hist.seconds,
            "best_epoch": hist.best_epoch,
            "train_loss": hist.train_loss,
            "val_loss": hist.val_loss,
        },
        dataset_fingerprint=data.fingerprint(),
    )
    return model, hist, val_idx
