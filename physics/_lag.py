"""First-order actuator lag, discretised exactly."""

from __future__ import annotations

import casadi as ca
import numpy as np

from ._block import AbstractBlock, Parameter
from ._signature import Signature

#: Time constants (s) tried as starting points by identification.
LAG_GRID_S = (0.01, 0.03, 0.08, 0.2, 0.5, 1.2)


def lag_shapes(v: np.ndarray, dt: float, taus: np.ndarray) -> np.ndarray:
    """``LF_T(v) - v`` for each time constant: the exact first-order-hold lag of the block."""
    a = np.exp(-dt / taus)
    g = 1 - (taus / dt) * (1 - a)
    x = np.full(taus.size, v[0])
    out = np.empty((v.size, taus.size))
    prev = v[0]
    for k, uk in enumerate(v):
        x = a * x + (1 - a) * prev + g * (uk - prev)
        prev = uk
        out[k] = x
    return out - v[:, None]


class Lag(AbstractBlock):
    """First-order lag ``T dx/dt = u - x`` between command and actuator position.

    Discretised exactly for an input that is linear between samples (first-order
    hold), so the only approximation is the input's interpolation. With
    ``a = exp(-dt/T)`` and ``g = 1 - (T/dt)(1 - a)``::

        x_k = a x_{k-1} + (1 - a) u_{k-1} + g (u_k - u_{k-1}),   y_k = x_k

    The state is ``(x_{k-1}, u_{k-1})``.

    Examples
    --------
    >>> import numpy as np
    >>> from physics import Lag, Series
    >>> y = Series(Lag(time_constant_s=0.1), dt=0.01).simulate(np.ones(200))
    >>> bool(abs(y[-1] - 1.0) < 1e-6)
    True
    """

    name = "lag"
    identity = {"time_constant_s": 1e-4}  # the lower bound: settled within a sample below about 2 kHz
    parameters = (
        Parameter("time_constant_s", 0.12, 1e-4, 10.0, "s", "time constant of the actuator"),
    )
    effect = "actuator_lag"
    rank = 0
    selection_order = 10
    unit_static_gain = True
    starts = 3  # prone to local minima: multi-start by default
    signature = Signature(
        family="rate", terms=("dv/dt", "d2v/dt2"),
        grid=lambda dt, span: [{"time_constant_s": float(g)} for g in np.geomspace(0.25 * dt, 2.0, 48)],
        shapes=lambda v, dt, grid: lag_shapes(v, dt, np.array([g["time_constant_s"] for g in grid])),
        estimate=lambda e: (dict(e.grid), {}),
        describe=lambda p, s: f"time constant {p['time_constant_s']:.3g} s",
    )

    def __init__(self, time_constant_s: float | None = None):
        self._init_parameters({"time_constant_s": time_constant_s})

    @property
    def state_names(self):
        return ("position", "u_prev")

    @staticmethod
    def _coefficients(p, dt):
        a = ca.exp(-dt / p[0])
        g = 1 - (p[0] / dt) * (1 - a)
        return a, g

    def step(self, x, u, p, dt):
        a, g = self._coefficients(p, dt)
        pos = a * x[0] + (1 - a) * x[1] + g * (u - x[1])
        return ca.vertcat(pos, u), pos

    def steady_state(self, u0, p):
        return ca.vertcat(u0, u0)

    continuous_states = ("position",)

    def derivative(self, xc, u, udot, p):
        qdot = (u - xc[0]) / p[0]
        return qdot, xc[0], qdot

    def initial_grid(self, data, values, free):
        return [{"time_constant_s": t} for t in LAG_GRID_S] if free["time_constant_s"] else []

    def describe(self, dt):
        return f"time constant {self.time_constant_s:.3g} s"

    def inverse_output(self, x, y, p, dt):
        a, g = self._coefficients(p, dt)
        return x[1] + (y - a * x[0] - (1 - a) * x[1]) / g
