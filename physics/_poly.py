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

    ``lo, hi``: the range the block's own input had on the data it was fitted to, set after the
    fit (:meth:`for_input_range`). Beyond it the cubic, which nothing there constrained, is
    continued along its tangent at the edge (value and slope continuous). ``None``: the cubic
    everywhere.
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
    selection_order = 70
    signature = Signature(
        family="static", terms=("x^2", "x^3"), scale="linear", estimate=_estimate,
        describe=lambda p, s: f"c2 {p['c2']:.3g}, c3 {p['c3']:.3g} about {s['center']:.3g}",
    )

    def __init__(self, c2: float | None = None, c3: float | None = None, center: float | None = None,
                 lo: float | None = None, hi: float | None = None):
        self._init_parameters({"c2": c2, "c3": c3})
        if center is not None and not np.isfinite(center):
            raise ValueError(f"Poly center must be a finite number (input units) or None. Got {center}.")
        if (lo is None) != (hi is None) or (lo is not None and not (np.isfinite(lo) and np.isfinite(hi) and lo <= hi)):
            raise ValueError(f"Poly lo and hi must both be None or finite with lo <= hi. Got {lo}, {hi}.")
        self.center = None if center is None else float(center)
        self.lo, self.hi = (None, None) if lo is None else (float(lo), float(hi))

    @property
    def _center(self) -> float:
        return 0.0 if self.center is None else self.center

    def for_range(self, lo, hi):
        return self if self.center is not None else self.with_settings(center=0.5 * (lo + hi))

    def for_input_range(self, lo, hi):
        return self.with_settings(lo=lo, hi=hi)

    def _map(self, u, p):
        """Output and slope at ``u``: the cubic inside ``[lo, hi]``, its tangent at the edge beyond."""
        inside = u if self.lo is None else ca.fmin(ca.fmax(u, self.lo), self.hi)
        d = inside - self._center
        slope = 1 + 2 * p[0] * d + 3 * p[1] * d**2
        return inside + p[0] * d**2 + p[1] * d**3 + slope * (u - inside), slope

    def derivative(self, xc, u, udot, p):
        y, slope = self._map(u, p)
        return ca.DM.zeros(0, 1), y, udot * slope

    def step(self, x, u, p, dt):
        return ca.DM.zeros(0, 1), self._map(u, p)[0]

    def describe(self, dt):
        return f"c2 {self.c2:.3g}, c3 {self.c3:.3g}"
