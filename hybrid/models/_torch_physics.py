"""A physics ``Series`` run in torch: its CasADi graph translated once (``physics.torch_expression``),
its parameters torch parameters initialised from the fit.

Used by the hybrid models that fine-tune the physics jointly with a network
(:class:`HybridModel` with ``fine_tune=True``, :class:`NeuralODEHybrid`); the
equations stay written once, in the physics blocks.
"""

from __future__ import annotations

import copy
from typing import Any

import numpy as np
import torch
from torch import Tensor, nn

from physics import Series, torch_expression

__all__ = ["TorchPhysics"]


class TorchPhysics(nn.Module):
    """The parameters of ``series`` as ``p = p0 + mask * scale * delta`` (``delta`` trainable, 0 at start).

    ``scale = max(|p0|, 1e-2 f)`` puts every parameter on a relative footing, so one
    Adam learning rate (``1e-3``: 0.1 % per step) suits a gain of 11 deg/mm and a play
    of 0.2 mm alike; ``f`` is the parameter's typical magnitude for the data's signal scales
    ``(s_u, s_y)`` (``identification.data_scales``, through ``Series.signal_scales``; 1 when not given), as in identification, so a gain
    of 1e-7 m/V is not moved by 1e-5 per step. Only the parameters the blocks fit by default
    (``fit_mask``) move; values are clamped to the blocks' bounds in the data's units (the
    declared bounds times ``f``). Everything is float64.
    """

    def __init__(self, series: Series, trainable: bool = True, signal_scales: tuple[float, float] | None = None):
        super().__init__()
        self.series = copy.deepcopy(series)
        p0 = torch.as_tensor(series.params, dtype=torch.float64)
        factors = np.ones(series.n_p) if signal_scales is None else series.signal_scales(*signal_scales)[0]
        f = torch.as_tensor(np.asarray(factors, dtype=float), dtype=torch.float64)
        self.register_buffer("p0", p0)
        self.register_buffer("scale", torch.maximum(p0.abs(), 1e-2 * f))
        mask = torch.as_tensor(series.fit_mask if trainable else np.zeros(series.n_p, bool), dtype=torch.float64)
        self.register_buffer("mask", mask)
        # a fitted value may sit outside the unit-scale bounds (a 600 V play): never clamp it there
        self.register_buffer("lower", torch.minimum(torch.as_tensor(series.lower_bounds, dtype=torch.float64) * f, p0))
        self.register_buffer("upper", torch.maximum(torch.as_tensor(series.upper_bounds, dtype=torch.float64) * f, p0))
        self.delta = nn.Parameter(torch.zeros_like(p0), requires_grad=trainable)
        self._step = None
        self._ode = None

    def params(self) -> Tensor:
        return torch.clamp(self.p0 + self.mask * self.scale * self.delta, self.lower, self.upper)

    def to_series(self) -> Series:
        """A copy of the physics model with the current (fine-tuned) parameters."""
        out = copy.deepcopy(self.series)
        out.params = self.params().detach().numpy()
        return out

    # ------------------------------------------------------------ discrete
    def step(self, x: Tensor, u: Tensor) -> tuple[Tensor, Tensor]:
        """``(x (B, n_x), u (B,)) -> (x_next (B, n_x), y (B,))``."""
        if self._step is None:
            self._step = torch_expression(self.series.step_function())
        x_next, y = self._step(x, u[..., None], self.params())
        return x_next, y[..., 0]

    def rollout(self, x0: Tensor, u: Tensor) -> tuple[Tensor, Tensor]:
        """Outputs (B, L) and the states *after* each sample (B, L, n_x) for inputs ``u`` (B, L)."""
        x, ys, xs = x0, [], []
        for k in range(u.shape[1]):
            x, y = self.step(x, u[:, k])
            ys.append(y)
            xs.append(x)
        return torch.stack(ys, 1), torch.stack(xs, 1)

    # ---------------------------------------------------------- continuous
    def ode(self, xc: Tensor, u: Tensor, udot: Tensor) -> tuple[Tensor, Tensor]:
        """``(xc (B, n), u (B,), udot (B,)) -> (xc_dot (B, n), y (B,))`` of ``Series.ode_function``."""
        if self._ode is None:
            self._ode = torch_expression(self.series.ode_function())
        xdot, y = self._ode(xc, u[..., None], udot[..., None], self.params())
        return xdot, y[..., 0]
