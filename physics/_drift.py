"""Slow offset drift of the output."""

from __future__ import annotations

import casadi as ca

from ._block import AbstractBlock, Parameter
from ._signature import Signature


class Drift(AbstractBlock):
    """``y = u + rate * t``: an offset that grows linearly with elapsed time.

    The state is the elapsed time ``t`` (s) since the start of the trajectory.
    """

    name = "drift"
    identity = {"rate": 0.0}
    parameters = (Parameter("rate", 0.0, -100.0, 100.0, "unit/s", "drift per second", scaling=(1, 0)),)
    state_scaling = (0.0,)  # elapsed time
    effect = "drift"
    rank = 6
    selectable = False  # named by discovery on a residual, never tried by the selection
    signature = Signature(
        family="drift", terms=("t",), scale="linear",
        estimate=lambda e: ({"rate": float(e.coef[0])}, {}),
        describe=lambda p, s: f"{p['rate']:.3g} per s",
    )

    def __init__(self, rate: float | None = None):
        self._init_parameters({"rate": rate})

    @property
    def state_names(self):
        return ("elapsed_s",)

    def step(self, x, u, p, dt):
        return x[0] + dt, u + p[0] * x[0]

    continuous_states = ("elapsed_s",)

    def derivative(self, xc, u, udot, p):
        return ca.DM.ones(1, 1), u + p[0] * xc[0], udot + p[0]

    def steady_state(self, u0, p):
        return ca.DM.zeros(1, 1)

    def inverse_output(self, x, y, p, dt):
        return y - p[0] * x[0]

    def describe(self, dt):
        return f"{self.rate:.3g} per s"
