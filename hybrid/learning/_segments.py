"""The segment-training loop of models whose state is simulated, not windowed.

Trajectories are cut into segments of ``L`` samples (the last one ending at the
trajectory's end). Each epoch first runs every trajectory whole, without gradients,
with the current parameters (``prepare``), so that each segment can start from the
state that run reached there; then Adam steps on shuffled batches of segments
(``loss``). Used by the hybrid's joint fine-tuning and by the neural-ODE hybrid.
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np
import torch
from tqdm.auto import tqdm

from ._training import _progress_enabled

__all__ = ["segment_length", "train_on_segments"]


def segment_length(wanted: int, trajectories) -> int:
    """``wanted``, shortened to the shortest trajectory."""
    return int(min(wanted, min(t.n for t in trajectories)))


def train_on_segments(groups: list[dict], trajectories, length: int, *, epochs: int, batch_size: int, seed: int,
                      prepare: Callable[[], Any], loss: Callable[[Any, list[tuple[int, int]]], torch.Tensor],
                      desc: str = "segments", progress: bool | None = False) -> list[float]:
    """Adam on ``groups`` (torch parameter groups with their rates); returns the mean loss of each epoch.

    ``prepare()`` is called under ``no_grad`` at the start of each epoch and returns what
    ``loss(prepared, batch)`` needs; a batch is a list of ``(trajectory index, start)``.
    """
    segments = [(i, s) for i, t in enumerate(trajectories)
                for s in sorted(set(range(0, t.n - length + 1, length)) | {t.n - length})]
    opt = torch.optim.Adam(groups)
    rng = np.random.default_rng(seed)
    losses: list[float] = []
    bar = tqdm(range(epochs), desc=desc, disable=not _progress_enabled(progress), leave=False)
    for _ in bar:
        with torch.no_grad():
            prepared = prepare()
        total, counted, perm = 0.0, 0, rng.permutation(len(segments))
        for b in range(0, len(segments), batch_size):
            batch = [segments[j] for j in perm[b:b + batch_size]]
            value = loss(prepared, batch)
            if not torch.isfinite(value):  # a segment the state blew up on: no step, the weights stay finite
                continue
            opt.zero_grad()
            value.backward()
            grads = [w.grad for g in opt.param_groups for w in g["params"] if w.grad is not None]
            if not all(bool(torch.isfinite(gr).all()) for gr in grads):  # a finite loss, non-finite slope
                continue
            opt.step()
            total, counted = total + float(value.detach()) * len(batch), counted + len(batch)
        if not counted:
            bar.close()
            raise FloatingPointError(
                f"{desc}: every batch's loss was non-finite in epoch {len(losses) + 1} (the simulated state "
                "blew up); lower the learning rates, or use a physics that is stable at the data's rate.")
        losses.append(total / counted)
        bar.set_postfix(loss=f"{losses[-1]:.3g}")
    bar.close()
    return losses
