"""Networks of one architecture trained as one: the seeds of a sweep in one batched pass.

Each network keeps everything it would have alone: its initial weights, its validation split and its
shuffling (``numpy.random.default_rng(seed)``), its Adam state and its early stop. Their weights are
stacked (``torch.func.stack_module_state``) and every mini-batch step runs the architecture once over
all of them (``torch.func.vmap`` of ``functional_call``): a network's mini-batch is its own, its loss
its own mean, and the sum of the losses gives each network its own gradient. Adam acts elementwise,
so each slice moves as it would alone. The result is the one :func:`~hybrid.learning.train` gives
each network alone, to float tolerance (the batched matrix products add in another order).

Where ``vmap`` cannot batch the architecture, the networks train one after another instead, with
the same results.
"""

from __future__ import annotations

import copy
import time
from collections.abc import Sequence
from dataclasses import replace

import numpy as np
import torch
from numpy.typing import NDArray

from physics.data import DataError

from ._settings import TrainingSettings
from ._training import TrainingHistory, resolve_device, train, validation_split

__all__ = ["train_together"]


def train_together(modules: Sequence[torch.nn.Module], x: NDArray[np.float32], y: NDArray[np.float32],
                   settings: Sequence[TrainingSettings], desc: str = "train") -> list[TrainingHistory]:
    """Train ``modules`` (one architecture, each already initialised) in place on the same windows ``x``
    and targets ``y``, each with its ``settings`` (equal but for the seed), in one batched pass.

    Returns each module's :class:`~hybrid.learning.TrainingHistory`, as :func:`~hybrid.learning.train`
    returns it alone (``seconds``: the pass's, shared). The pass shows no progress bar (``desc`` names
    the networks' training where they fall back to one after another).
    """
    modules, settings = list(modules), list(settings)
    if not modules or len(modules) != len(settings):
        raise DataError(f"train_together needs one TrainingSettings per module; got {len(modules)} modules and "
                        f"{len(settings)} settings.")
    if any(replace(s, seed=0) != replace(settings[0], seed=0) for s in settings):
        raise DataError("train_together trains networks whose settings differ only in their seed; train the "
                        "others with train() one after another.")
    shapes = [[(k, tuple(v.shape)) for k, v in m.state_dict().items()] for m in modules]
    if any(type(m) is not type(modules[0]) or s != shapes[0] for m, s in zip(modules, shapes)):
        raise DataError("train_together trains networks of one architecture (the same class and weight shapes).")
    if x.shape[0] != y.shape[0] or x.shape[0] < 2:
        raise DataError(f"training needs at least 2 windows with one target each; got {x.shape[0]} and {y.shape[0]}.")
    if len(modules) == 1 or not _batchable(modules[0], x):
        return [train(m, x, y, s, desc) for m, s in zip(modules, settings)]
    device = resolve_device(settings[0].device)
    try:
        for m in modules:
            m.to(device)
        return _train_together(modules, x, y, settings, device)
    finally:
        for m in modules:
            m.to("cpu")


def _batchable(module: torch.nn.Module, x) -> bool:
    """Whether ``vmap`` runs ``module`` forward and backward over stacked weights (an MLP does; a
    recurrent layer whose kernel has no batching rule does not)."""
    from torch.func import functional_call, stack_module_state, vmap

    twins = [copy.deepcopy(module) for _ in range(2)]
    params, buffers = stack_module_state(twins)
    base = copy.deepcopy(module).to("meta")
    xb = torch.from_numpy(np.ascontiguousarray(x[:2])).expand(2, *x[:2].shape)
    try:
        out = vmap(lambda p, b, v: functional_call(base, (p, b), (v,)))(params, buffers, xb)
        out.sum().backward()
    except Exception:  # no batching rule (a fused recurrent kernel): one after another
        return False
    return True


def _train_together(modules, x, y, settings, device) -> list[TrainingHistory]:
    from torch.func import functional_call, stack_module_state, vmap

    first, m = settings[0], len(modules)
    rngs = [np.random.default_rng(s.seed) for s in settings]
    splits = [validation_split(rng, x.shape[0], first.validation) for rng in rngs]  # each its own, as alone
    val_idx, train_idx = np.stack([v for v, _ in splits]), np.stack([t for _, t in splits])
    n_val, n_train = val_idx.shape[1], train_idx.shape[1]
    xt, yt = (torch.from_numpy(np.ascontiguousarray(a)).to(device) for a in (x, y))
    x_val, y_val = xt[torch.from_numpy(val_idx).to(device)], yt[torch.from_numpy(val_idx).to(device)]
    train_at = torch.from_numpy(train_idx).to(device)

    params, buffers = stack_module_state(modules)  # leaves of shape (m, ...) that require grad
    base = copy.deepcopy(modules[0]).to("meta")
    forward = vmap(lambda p, b, v: functional_call(base, (p, b), (v,)))
    optimizer = torch.optim.Adam(list(params.values()), lr=first.lr)

    train_losses: list[list[float]] = [[] for _ in range(m)]
    val_losses: list[list[float]] = [[] for _ in range(m)]
    best = [float("inf")] * m
    best_epoch, stale, best_state = [0] * m, [0] * m, [None] * m
    stopped = [False] * m
    start = time.perf_counter()
    for epoch in range(first.epochs):
        # a network that stopped early draws on and trains on, unread: its best weights are kept
        perms = torch.from_numpy(np.stack([rng.permutation(n_train) for rng in rngs])).to(device)
        totals = torch.zeros(m, dtype=torch.float64)
        for i in range(0, n_train, first.batch_size):
            idx = torch.gather(train_at, 1, perms[:, i:i + first.batch_size])  # (m, batch): each its own
            optimizer.zero_grad()
            per_model = ((forward(params, buffers, xt[idx]) - yt[idx]) ** 2).mean(dim=tuple(range(1, yt.dim() + 1)))
            per_model.sum().backward()  # the sum: each network's own gradient
            optimizer.step()
            totals += per_model.detach().to("cpu", torch.float64) * idx.shape[1]
        losses = (totals / n_train).tolist()
        vals = _evaluate(forward, params, buffers, x_val, y_val) if n_val else None
        for k in range(m):
            if stopped[k]:
                continue
            train_losses[k].append(losses[k])
            if vals is not None:
                val_losses[k].append(vals[k])
                if vals[k] < best[k]:
                    best[k], best_epoch[k], stale[k] = vals[k], epoch, 0
                    best_state[k] = _slice(params, buffers, k)
                else:
                    stale[k] += 1
            if first.patience is not None and stale[k] >= first.patience:
                stopped[k] = True
                if best_state[k] is None:  # never improved (a NaN loss): alone it keeps the weights it stopped at
                    best_state[k] = _slice(params, buffers, k)
                    best_epoch[k] = len(train_losses[k]) - 1
        if all(stopped):
            break
    seconds = time.perf_counter() - start
    out = []
    for k, module in enumerate(modules):
        state = best_state[k] if best_state[k] is not None else _slice(params, buffers, k)
        module.load_state_dict(state)
        module.eval()
        epoch_of_best = best_epoch[k] if best_state[k] is not None else len(train_losses[k]) - 1
        out.append(TrainingHistory(tuple(train_losses[k]), tuple(val_losses[k]), epoch_of_best, stopped[k],
                                   seconds, n_train, n_val))
    return out


def _slice(params: dict, buffers: dict, k: int) -> dict:
    """Network ``k``'s weights (a state dict of its own)."""
    return {name: v[k].detach().clone() for name, v in {**params, **buffers}.items()}


@torch.no_grad()
def _evaluate(forward, params, buffers, x, y, chunk: int = 4096) -> list[float]:
    """Each network's MSE on its own validation windows ``x[k]`` (summed per chunk as ``train`` does)."""
    dims = tuple(range(1, y.dim()))
    total = torch.zeros(x.shape[0], dtype=torch.float64)
    for i in range(0, x.shape[1], chunk):
        xs, ys = x[:, i:i + chunk], y[:, i:i + chunk]
        per = ((forward(params, buffers, xs) - ys) ** 2).mean(dim=dims)
        total += per.to("cpu", torch.float64) * xs.shape[1]
    return (total / x.shape[1]).tolist()
