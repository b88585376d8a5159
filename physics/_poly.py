"""Static polynomial nonlinearity."""

from __future__ import annotations

from ._block import AbstractBlock, Parameter
import casadi as ca


class Poly(AbstractBlock):
    """``y = u + c2 (u - center)^2 + c3 (u - center)^3``; memoryless.

    The constant and linear terms are left to ``linear`` so that the pair is
    identifiable. ``center`` (input units) is structural: put it mid-range.
    """

    name = "poly"
    parameters = (
        Parameter("c2", 0.0, -100.0, 100.0, "1/unit", "quadratic coefficient"),
        Parameter("c3", 0.0, -100.0, 100.0, "1/unit^2", "cubic coefficient"),
    )

    def __init__(self, c2: float | None = None, c3: float | None = None, center: float = 3.0):
        self._init_parameters({"c2": c2, "c3": c3})
        self.center = float(center)

    def derivative(self, xc, u, udot, p):
        d = u - self.center
        return ca.DM.zeros(0, 1), u + p[0] * d**2 + p[1] * d**3, udot * (1 + 2 * p[0] * d + 3 * p[1] * d**2)

    def step(self, x, u, p, dt):
        d = u - self.center
        return ca.DM.zeros(0, 1), u + p[0] * d**2 + p[1] * d**3
