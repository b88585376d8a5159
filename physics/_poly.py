"""Static polynomial nonlinearity."""

from __future__ import annotations

import casadi as ca
import numpy as np

from ._block import AbstractBlock, Parameter
from ._signature import Signature


def _estimate(e):
    c2, c3 = e.coef[0] / (e.gain * e.half**2), e.coef[1] / (e.gain * e.half**3)
    return {"c2": float(c2), "c3": float(c3)}, {"center": e.center}


class Poly(AbstractBlock):
    """``y = u + c2 (u - center)^2 + c3 (u - center)^3``; memoryless.

    The constant and linear terms are left to ``linear`` so that the pair is
    identifiable. ``center`` (input units) is structural: ``None`` (the default) is the middle
    of the fitted data's input range, set when the block is fitted (:meth:`for_range`), so the
    spec fits data of any scale and offset; 0 until then. Give a number to hold it.
    """

    name = "poly"
    identity = {"c2": 0.0, "c3": 0.0}
    parameters = (
        Parameter("c2", 0.0, -100.0, 100.0, "1/unit", "quadratic coefficient", scaling=(-1, 0)),
        Parameter("c3", 0.0, -100.0, 100.0, "1/unit^2", "cubic coefficient", scaling=(-2, 0)),
    )
    effect = "static_nonlinearity"
    aliases = ("nonlinearity",)
    rank = 4
    signature = Signature(
        family="static", terms=("x^2", "x^3"), scale="linear", estimate=_estimate,
        describe=lambda p, s: f"c2 {p['c2']:.3g}, c3 {p['c3']:.3g} about {s['center']:.3g}",
    )

    def __init__(self, c2: float | None = None, c3: float | None = None, center: float | None = None):
        self._init_parameters({"c2": c2, "c3": c3})
        if center is not None and not np.isfinite(center):
            raise ValueError(f"Poly center must be a finite number (input units) or None. Got {center}.")
        self.center = None if center is None else float(center)

    @property
    def _center(self) -> float:
        return 0.0 if self.center is None else self.center

    def for_range(self, lo, hi):
        return self if self.center is not None else self.with_settings(center=0.5 * (lo + hi))

    def derivative(self, xc, u, udot, p):
        d = u - self._center
        return ca.DM.zeros(0, 1), u + p[0] * d**2 + p[1] * d**3, udot * (1 + 2 * p[0] * d + 3 * p[1] * d**2)

    def step(self, x, u, p, dt):
        d = u - self._center
        return ca.DM.zeros(0, 1), u + p[0] * d**2 + p[1] * d**3

    def describe(self, dt):
        return f"c2 {self.c2:.3g}, c3 {self.c3:.3g}"
