"""Joint fine-tuning of a forward hybrid: physics parameters and residual network trained together.

The physics runs in torch (``TorchPhysics``: the CasADi step translated by
``physics.torch_expression``), so the loss is differentiated through the
physics output and states that the network is fed. Trajectories are cut into
segments of ``segment_len`` samples; each segment starts from the state of a
full (gradient-free) run with the current parameters, recomputed every epoch,
and the network's history before the segment comes from that run too.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from hybrid.learning._segments import segment_length, train_on_segments
from identification import data_scales
from physics.data import DataError, Settings

from ._torch_physics import TorchPhysics

__all__ = ["FineTuneSettings", "fine_tune"]


@dataclass(frozen=True)
class FineTuneSettings(Settings):
    """The joint stage of a forward :class:`HybridModel` (``fine_tune=FineTuneSettings(...)``).

    After the network is trained on the frozen physics, both are trained together: the physics
    parameters become torch parameters initialised from the fit and the physics runs in torch
    (``physics.torch_expression`` of its step), on segments of ``segment_len`` samples started from
    the states of a full run. The network's learning rate, batch size, seed and progress are the
    hybrid's ``training``'s.

    Parameters
    ----------
    epochs : int, default 10
        Passes of the joint stage.
    physics_lr : float, default 1e-3
        Adam rate of the relative parameter change (1e-3 is 0.1 % per step).
    residual_penalty : float, default 0.1
        Weight of ``mean(r^2)`` in the loss, so the physics, not the network, explains what the
        physics can.
    segment_len : int, default 100
        Samples per segment.
    """

    epochs: int = 10
    physics_lr: float = 1e-3
    residual_penalty: float = 0.1
    segment_len: int = 100

    def __post_init__(self) -> None:
        for name in ("epochs", "segment_len"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
                raise DataError(f"The {name!r} fine-tune setting must be an integer >= 1. Got {value!r}.")
        lr = self.physics_lr
        if isinstance(lr, bool) or not (isinstance(lr, (int, float)) and lr >= 0):
            raise DataError(f"The 'physics_lr' fine-tune setting must be a number >= 0 (0: the physics stays). "
                            f"Got {lr!r}.")
        if isinstance(self.residual_penalty, bool) or not (isinstance(self.residual_penalty, (int, float))
                                                           and self.residual_penalty >= 0):
            raise DataError(f"The 'residual_penalty' fine-tune setting must be a number >= 0. "
                            f"Got {self.residual_penalty!r}.")


def _scaler(s):
    lo = torch.tensor(np.asarray(s.min_, dtype=float).ravel())
    return lo, torch.tensor(np.asarray(s.max_, dtype=float).ravel()) - lo


def fine_tune(model, trajs) -> list[float]:
    """Train ``model.physics_`` parameters and ``model.residual_.module_`` jointly (the stage
    ``model.fine_tune`` sets); returns the epoch losses."""
    tune, training = model.fine_tune, model.training
    learned = model.residual_
    module, net = learned.module_, learned.network_
    tp = TorchPhysics(model.physics_, signal_scales=data_scales(trajs))
    H = net.history
    L = segment_length(tune.segment_len, trajs)
    in_lo, in_span = _scaler(learned.input_scaler_)
    out_lo, out_span = _scaler(learned.output_scaler_)
    pad = getattr(net, "flag", getattr(net, "pad", "edge"))
    names = model.feature_names_
    state_idx = {n: model.physics_.state_names.index(n[6:]) for n in names if n.startswith("state:")}
    extras = [{n: torch.tensor(np.asarray(t.extra[n], dtype=float)) for n in names
               if n not in ("u", "physics") and n not in state_idx} for t in trajs]
    us = [torch.tensor(np.asarray(t.u, dtype=float)) for t in trajs]
    ys = [torch.tensor(np.asarray(t.y, dtype=float)) for t in trajs]

    def features(i, u, out, xs, sl):
        cols = []
        for n in names:
            cols.append(u if n == "u" else out if n == "physics" else xs[..., state_idx[n]] if n in state_idx
                        else extras[i][n][sl])
        return (torch.stack(cols, -1) - in_lo) / in_span

    def prepare():  # full runs with the current parameters: segment starts and history
        series = tp.to_series()
        starts, history = [], []
        for i, t in enumerate(trajs):
            x0 = torch.as_tensor(series.steady_state(float(t.u[0])))[None]
            out, xs = tp.rollout(x0, us[i][None])
            starts.append(torch.cat([x0, xs[0, :-1]]))
            f = features(i, us[i], out[0], xs[0], slice(None))
            head = f[:1].expand(H - 1, -1) if pad == "edge" else f.new_full((H - 1, f.shape[1]), float(pad))
            history.append(torch.cat([head, f]))
        module.train()
        return starts, history

    def loss(prepared, batch):
        starts, history = prepared
        x0 = torch.stack([starts[i][s] for i, s in batch])
        u = torch.stack([us[i][s:s + L] for i, s in batch])
        out, xs = tp.rollout(x0, u)
        f = torch.stack([features(i, u[k], out[k], xs[k], slice(s, s + L)) for k, (i, s) in enumerate(batch)])
        hist = torch.stack([history[i][s:s + H - 1] for i, s in batch])
        full = torch.cat([hist, f], 1)
        windows = full.unfold(1, H, 1).permute(0, 1, 3, 2).reshape(-1, H, full.shape[-1])
        r = module(windows.float()).double().reshape(len(batch), L) * out_span + out_lo
        y = torch.stack([ys[i][s:s + L] for i, s in batch])
        return (((out + r - y) / out_span) ** 2).mean() + tune.residual_penalty * ((r / out_span) ** 2).mean()

    torch.manual_seed(training.seed)
    groups = [{"params": module.parameters(), "lr": training.lr}, {"params": [tp.delta], "lr": tune.physics_lr}]
    losses = train_on_segments(groups, trajs, L, epochs=tune.epochs, batch_size=training.batch_size,
                               seed=training.seed, prepare=prepare, loss=loss, desc="fine-tune",
                               progress=training.progress)
    module.eval()
    model.physics_ = tp.to_series()
    return losses
