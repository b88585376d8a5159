"""Static linear map, e.g. tendon displacement (mm) to tip angle (deg)."""

from __future__ import annotations

import casadi as ca

from ._block import AbstractBlock, Parameter


class LinearMap(AbstractBlock):
    """``y = gain * u + offset``; memoryless.

    Defaults are those of a single-tendon catheter: about 30 deg at rest and
    10.8 deg per mm of tendon displacement.
    """

    name = "linear"
    parameters = (
        Parameter("gain", 10.8, -1e4, 1e4, "output unit / input unit", "slope", scaling=(-1, 1)),
        Parameter("offset", 30.0, -1e4, 1e4, "output unit", "output at zero input", scaling=(0, 1)),
    )
    rank = 5
    affine_output = ("gain", "offset")

    def __init__(self, gain: float | None = None, offset: float | None = None):
        self._init_parameters({"gain": gain, "offset": offset})

    def output_scale(self, s_in, s_y):
        return s_y  # the map to the measured output's units

    def step(self, x, u, p, dt):
        return ca.DM.zeros(0, 1), p[0] * u + p[1]

    def derivative(self, xc, u, udot, p):
        return ca.DM.zeros(0, 1), p[0] * u + p[1], p[0] * udot

    def inverse_output(self, x, y, p, dt):
        return (y - p[1]) / p[0]
