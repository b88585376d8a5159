"""Backlash (tendon slack): a play operator of width ``width``."""

from __future__ import annotations

import casadi as ca

from ._block import AbstractBlock, Parameter


def _smax(a, b, s):
    return 0.5 * (a + b + ca.sqrt((a - b) ** 2 + s * s))


def _smin(a, b, s):
    return 0.5 * (a + b - ca.sqrt((a - b) ** 2 + s * s))


class Backlash(AbstractBlock):
    """Play operator: the output stays put until the input has moved ``width``.

    ``y_k = max(u_k - width/2, min(u_k + width/2, y_{k-1}))``

    ``smoothing`` (input units) > 0 replaces max/min by their smooth versions
    ``(a + b +- sqrt((a - b)^2 + s^2)) / 2`` for gradient-based fitting; each
    differs from the sharp one by at most ``s/2`` per step, and the test suite
    bounds the error of whole paths. ``smoothing=0`` is the sharp operator.
    The state is ``y_{k-1}``.
    """

    name = "backlash"
    parameters = (
        Parameter("width", 0.3, 0.0, 100.0, "input unit", "total play (dead band)"),
    )

    def __init__(self, width: float | None = None, smoothing: float = 0.01):
        self._init_parameters({"width": width})
        if smoothing < 0:
            raise ValueError(f"Backlash smoothing must be >= 0. Got {smoothing} instead.")
        self.smoothing = float(smoothing)
        if self.smoothing == 0.0:
            self.smooth_in_input = False

    @property
    def state_names(self):
        return ("position",)

    def step(self, x, u, p, dt):
        half = p[0] / 2
        s = self.smoothing
        if s > 0:
            y = _smax(u - half, _smin(u + half, x[0], s), s)
        else:
            y = ca.fmax(u - half, ca.fmin(u + half, x[0]))
        return y, y

    def steady_state(self, u0, p):
        return ca.vertcat(u0)

    def inverse_output(self, x, y, p, dt):
        # Exact for the sharp operator; inside the dead band any input in
        # [y - width/2, y + width/2] keeps the output: the centre is returned.
        half = p[0] / 2
        tol = 1e-12
        return ca.if_else(y > x[0] + tol, y + half, ca.if_else(y < x[0] - tol, y - half, x[0]))
