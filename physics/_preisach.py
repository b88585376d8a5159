"""Discretised Preisach hysteresis: a triangle of relays with non-negative weights."""

from __future__ import annotations

import casadi as ca
import numpy as np

from ._block import AbstractBlock, Parameter
from ._traits import BlockTraits


#: Threshold range (input units) of a Preisach block not yet fitted (the catheter's mm).
DEFAULT_RANGE = (0.0, 6.0)


class Preisach(AbstractBlock):
    """Classical Preisach model on a grid of ``levels`` thresholds in [lower, upper].

    Relay ``(i, j)`` (``j <= i``) switches on when the input reaches
    ``alpha_i`` and off when it falls to ``beta_j``; ``alpha_i = beta_i`` are
    the cell centres of the grid. The output is
    ``lower + (upper - lower) * sum(w * r)`` with weights ``w >= 0`` summing to 1
    (a linear equality constraint, see :meth:`constraints`), so the block maps
    ``[lower, upper]`` onto itself and a following ``linear`` block stays
    identifiable. The output is linear in the weights given the relay states,
    which depend on the input path only: fitting the weights is a
    non-negative least-squares / QP problem.

    The relays are not differentiable in the input, so the inverse is a
    symbolic bisection (the output is non-decreasing in the input).

    ``lower``/``upper`` (input units): ``None`` (the default) is the fitted data's input
    range, set when the block is fitted (:meth:`for_range`), so the spec fits data of any scale
    and offset; [0, 6] until then. Give both to hold them.
    """

    name = "preisach"
    smooth_in_input = False
    continuous_states = None
    effect = "hysteresis"
    rank = 3
    selectable = False  # Bouc-Wen and GPI stand for hysteresis in the selection

    def __init__(self, levels: int = 10, lower: float | None = None, upper: float | None = None, weights=None):
        if int(levels) != levels or levels < 2:
            raise ValueError(f"Preisach levels must be a whole number >= 2. Got {levels} instead.")
        if (lower is None) != (upper is None):
            raise ValueError("Preisach needs both lower and upper (input units), or neither (the "
                             f"fitted data's range). Got lower={lower}, upper={upper}.")
        self._from_data = lower is None
        lower, upper = (DEFAULT_RANGE if lower is None else (lower, upper))
        if not upper > lower:
            raise ValueError(f"Preisach needs upper > lower. Got lower={lower}, upper={upper}.")
        self.levels, self.lower, self.upper = int(levels), float(lower), float(upper)
        centres = lower + (np.arange(levels) + 0.5) * (upper - lower) / levels
        pairs = [(i, j) for i in range(levels) for j in range(i + 1)]
        self.alpha = np.array([centres[i] for i, _ in pairs])
        self.beta = np.array([centres[j] for _, j in pairs])
        m = len(pairs)
        self.traits = BlockTraits.of(Preisach, parameters=tuple(
            Parameter(f"w_{i}_{j}", 1.0 / m, 0.0, 1.0, "-", "relay weight") for i, j in pairs))
        values = {} if weights is None else dict(zip((p.name for p in self.parameters), weights))
        self._init_parameters(values)

    @property
    def state_names(self):
        return tuple(f"relay_{p.name[2:]}" for p in self.parameters)

    @property
    def state_scaling(self):
        return (0.0,) * len(self.parameters)  # relays are 0 or 1

    def _relays(self, x, u):
        alpha, beta = ca.DM(self.alpha), ca.DM(self.beta)
        on = ca.if_else(u >= alpha, 1, 0)
        off = ca.if_else(u <= beta, 1, 0)
        # on has priority; otherwise off; otherwise keep
        return on + (1 - on) * (1 - off) * x

    def _output(self, r, p):
        return self.lower + (self.upper - self.lower) * ca.dot(p, r)

    def step(self, x, u, p, dt):
        r = self._relays(x, u)
        return r, self._output(r, p)

    def steady_state(self, u0, p):
        # reached from negative saturation by rising to u0 (u0 a number, SX, MX or DM)
        return ca.if_else(ca.DM(self.alpha) <= u0, 1, 0)

    def weight_regressors(self, u: np.ndarray, dt: float) -> np.ndarray:
        """(n, m) relay states after each sample from the rest state at ``u[0]``: the output
        is ``lower + (upper - lower) * R @ w`` with ``w >= 0`` summing to one, linear in ``w``."""
        x, v = ca.SX.sym("x", self.n_x), ca.SX.sym("u")
        relays = ca.Function("relays", [x, v], [self._relays(x, v)])  # the weights do not move the relays
        xs = relays.mapaccum("relays", u.size)(self.steady_state(float(u[0]), None), ca.DM(u[None, :]))
        return np.asarray(xs, dtype=float).T

    @property
    def output_range(self) -> tuple[float, float]:
        return self.lower, self.upper

    def get_settings(self):
        if self._from_data:
            return {"levels": self.levels, "lower": None, "upper": None}
        return {"levels": self.levels, "lower": self.lower, "upper": self.upper}

    def for_range(self, lo, hi):
        if not self._from_data or not hi > lo:
            return self
        return self.with_settings(lower=float(lo), upper=float(hi))

    def describe(self, dt):
        return ""

    def constraints(self, p):
        """Linear equality constraints on the weights: ``sum(w) == 1``."""
        return [(ca.sum1(p), 1.0, 1.0)]

    def inverse_output(self, x, y, p, dt, iterations: int = 48):
        lo, hi = self.lower, self.upper
        tol = 1e-9 * (self.upper - self.lower)  # staircase levels tie up to rounding
        for _ in range(iterations):
            mid = (lo + hi) / 2
            above = self._output(self._relays(x, mid), p) >= y - tol
            lo, hi = ca.if_else(above, lo, mid), ca.if_else(above, mid, hi)
        return hi

    def __repr__(self):
        if self._from_data:
            return f"Preisach(levels={self.levels})"
        return f"Preisach(levels={self.levels}, lower={self.lower}, upper={self.upper})"
