"""Mini-batch training of a torch module on windows: Adam, MSE, seeded, optional early stopping."""

from __future__ import annotations

import copy
import sys
import time
from dataclasses import dataclass

import numpy as np
import torch
from numpy.typing import NDArray

from physics.data import DataError

from ._settings import TrainingSettings

__all__ = ["TrainingSettings", "TrainingHistory", "train", "resolve_device"]


@dataclass(frozen=True)
class TrainingHistory:
    """What happened in training; losses are MSE in scaled units."""

    train_loss: tuple[float, ...]
    val_loss: tuple[float, ...]
    best_epoch: int
    stopped_early: bool
    seconds: float
    n_train: int
    n_val: int

    @property
    def epochs_run(self) -> int:
        return len(self.train_loss)

    def to_dict(self) -> dict:
        return {"train_loss": list(self.train_loss), "val_loss": list(self.val_loss), "best_epoch": self.best_epoch,
                "stopped_early": self.stopped_early, "seconds": self.seconds, "n_train": self.n_train,
                "n_val": self.n_val}

    @classmethod
    def from_dict(cls, d: dict) -> TrainingHistory:
        return cls(tuple(d["train_loss"]), tuple(d["val_loss"]), int(d["best_epoch"]), bool(d["stopped_early"]),
                   float(d["seconds"]), int(d["n_train"]), int(d["n_val"]))


def _progress_enabled(progress: bool | None) -> bool:
    return bool(sys.stderr.isatty()) if progress is None else bool(progress)


def resolve_device(device: str) -> torch.device:
    """The torch device a :class:`TrainingSettings` ``device`` names: ``"auto"`` is CUDA where torch sees
    a GPU, else the CPU; CUDA where torch sees none is refused, saying what to give instead."""
    if device == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if device.startswith("cuda"):
        count = torch.cuda.device_count() if torch.cuda.is_available() else 0
        index = int(device[5:]) if ":" in device else 0
        if index >= count:
            raise DataError(f"device {device!r}: torch sees {count} CUDA device(s) (torch {torch.__version__}, "
                            f"CUDA build {torch.version.cuda or 'none'}). Give --device cpu, or auto to use a GPU "
                            "only where there is one.")
    return torch.device(device)


def train(module: torch.nn.Module, x: NDArray[np.float32], y: NDArray[np.float32],
          settings: TrainingSettings, desc: str = "train") -> TrainingHistory:
    """Train ``module`` in place on windows ``x`` (N, ...) and targets ``y`` (N, n_out).

    The caller seeds torch before building the module (initial weights); the
    shuffling and the validation split come from ``numpy.random.default_rng(seed)``,
    so two calls with the same seed, data and thread count give identical weights.
    On ``settings.device`` (a GPU) the windows and the module move there for the training, and the
    module comes back to the CPU at the end.
    """
    if x.shape[0] != y.shape[0] or x.shape[0] < 2:
        raise DataError(f"training needs at least 2 windows with one target each; got {x.shape[0]} and {y.shape[0]}.")
    device = resolve_device(settings.device)
    if device.type == "cpu":
        return _train(module, x, y, settings, desc, device)
    try:
        module.to(device)
        return _train(module, x, y, settings, desc, device)
    finally:
        module.to("cpu")


def _train(module, x, y, settings: TrainingSettings, desc: str, device: torch.device) -> TrainingHistory:
    from tqdm.auto import tqdm

    rng = np.random.default_rng(settings.seed)
    val_idx, train_idx = validation_split(rng, x.shape[0], settings.validation)
    n_val = val_idx.size
    xt, yt = (torch.from_numpy(np.ascontiguousarray(a)).to(device) for a in (x, y))
    train_at, val_at = (torch.from_numpy(i).to(device) for i in (train_idx, val_idx))
    x_train, y_train = xt[train_at], yt[train_at]
    x_val, y_val = xt[val_at], yt[val_at]

    optimizer = torch.optim.Adam(module.parameters(), lr=settings.lr)
    loss_fn = torch.nn.MSELoss()
    train_losses: list[float] = []
    val_losses: list[float] = []
    best, best_epoch, best_state, stale = float("inf"), 0, None, 0
    start = time.perf_counter()
    # a terminal gets a bar; a log (progress asked for, stderr not a terminal) a line per tenth of the epochs
    lines = bool(settings.progress) and not sys.stderr.isatty()
    bar = tqdm(range(settings.epochs), desc=desc, disable=lines or not _progress_enabled(settings.progress),
               leave=False, dynamic_ncols=True)
    every = max(1, settings.epochs // 10)
    stopped = False
    for epoch in bar:
        module.train()
        perm = torch.from_numpy(rng.permutation(len(train_idx))).to(device)
        total = 0.0
        for i in range(0, len(perm), settings.batch_size):
            idx = perm[i:i + settings.batch_size]
            optimizer.zero_grad()
            loss = loss_fn(module(x_train[idx]), y_train[idx])
            loss.backward()
            optimizer.step()
            total += float(loss.detach()) * len(idx)
        train_losses.append(total / len(perm))
        postfix = {"loss": f"{train_losses[-1]:.3g}"}
        if n_val:
            val_losses.append(_evaluate(module, loss_fn, x_val, y_val))
            postfix["val"] = f"{val_losses[-1]:.3g}"
            if val_losses[-1] < best:
                best, best_epoch, stale = val_losses[-1], epoch, 0
                best_state = copy.deepcopy(module.state_dict())
            else:
                stale += 1
        bar.set_postfix(postfix)
        if lines and ((epoch + 1) % every == 0 or epoch + 1 == settings.epochs):
            print(f"{desc}: epoch {epoch + 1}/{settings.epochs}, " + ", ".join(f"{k} {v}" for k, v in postfix.items())
                  + f" ({time.perf_counter() - start:.0f} s)", file=sys.stderr, flush=True)
        if settings.patience is not None and stale >= settings.patience:
            stopped = True
            break
    bar.close()
    if best_state is not None:
        module.load_state_dict(best_state)
    else:
        best_epoch = len(train_losses) - 1
    module.eval()
    return TrainingHistory(tuple(train_losses), tuple(val_losses), best_epoch, stopped,
                           time.perf_counter() - start, len(train_idx), n_val)


def validation_split(rng: np.random.Generator, n: int, validation: float) -> tuple[NDArray, NDArray]:
    """``(validation indices, training indices in order)`` of ``n`` windows: a ``validation`` share drawn
    by ``rng`` (none: no draw, so the shuffling that follows is the same as without validation)."""
    n_val = int(round(validation * n))
    order = rng.permutation(n) if n_val else np.arange(n)
    return order[:n_val], np.sort(order[n_val:])


@torch.no_grad()
def _evaluate(module, loss_fn, x, y, chunk: int = 4096) -> float:
    module.eval()
    total = sum(float(loss_fn(module(x[i:i + chunk]), y[i:i + chunk])) * len(x[i:i + chunk])
                for i in range(0, len(x), chunk))
    return total / len(x)
