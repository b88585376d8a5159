"""The MPC's problem in the model's own scales: input, states and output mapped to about [0, 1].

A model fitted in metres and radians (1e-6, 1e-4) and one in mm and deg (6, 65) give the
solvers problems of the same size: tolerances, step lengths and Hessian regularisation
then mean the same in any units. The scales are measured once, by running the model on
a sweep across the input bounds; the optimum is unchanged (the cost is divided by a
constant, the variables are affine maps of the physical ones).
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

__all__ = ["Scaling"]

#: Samples of the sweep across the input bounds (up, down, up to the middle) that measures the scales.
SWEEP = 120


@dataclass(frozen=True)
class Scaling:
    """``u = u_lo + u_span v``, ``x = x_mid + x_span xi``, ``y = y_mid + y_span eta``."""

    u_lo: float
    u_span: float
    x_mid: np.ndarray
    x_span: np.ndarray
    y_mid: float
    y_span: float

    @classmethod
    def measure(cls, step: ca.Function, x0: np.ndarray, u_bounds: tuple[float, float], n_d: int,
                rest: tuple[tuple[np.ndarray, float], ...] = ()) -> "Scaling":
        """Scales of ``step``'s state and output on a sweep of the command across ``u_bounds``
        from state ``x0`` (measured inputs held at 0), widened to the ``rest`` points ``(x, y)``
        (the model at rest at each bound: a sweep of a fixed number of samples is short at kHz)."""
        lo, hi = u_bounds
        s = np.linspace(0.0, 1.0, SWEEP // 3)
        u = lo + (hi - lo) * np.r_[s, s[::-1], s[: s.size // 2]]
        xs, ys = step.mapaccum("sweep", u.size)(x0, np.vstack([u[None, :], np.zeros((n_d, u.size))]))
        xs = np.hstack([np.asarray(x0, dtype=float).reshape(-1, 1), np.asarray(xs, dtype=float),
                        *[np.asarray(x, dtype=float).reshape(-1, 1) for x, _ in rest]])
        ys = np.r_[np.asarray(ys, dtype=float).ravel(), [y for _, y in rest]]
        x_mid, x_span = np.zeros(xs.shape[0]), np.ones(xs.shape[0])
        for i, row in enumerate(xs):
            x_mid[i], x_span[i] = _mid_span(row)
        y_mid, y_span = _mid_span(ys)
        return cls(float(lo), float(hi - lo), x_mid, x_span, y_mid, y_span)

    def wrap(self, step: ca.Function) -> ca.Function:
        """``step`` on scaled state, command and output (measured inputs pass unscaled)."""
        S = ca.SX if step.is_a("SXFunction") else ca.MX
        xi, v = S.sym("x", step.size1_in(0)), S.sym("u", step.size1_in(1))
        x = ca.DM(self.x_mid) + ca.DM(self.x_span) * xi
        n_u = step.size1_in(1)
        u = ca.vertcat(self.u_lo + self.u_span * v[0], *([v[1:n_u]] if n_u > 1 else []))
        x_next, y = step(x, u)
        return ca.Function(step.name(), [xi, v], [(x_next - ca.DM(self.x_mid)) / ca.DM(self.x_span),
                                                 (y - self.y_mid) / self.y_span], ["x", "u"], ["x_next", "y"])

    def x(self, x: np.ndarray) -> np.ndarray:
        return (np.asarray(x, dtype=float) - self.x_mid) / self.x_span

    def u(self, u):
        return (np.asarray(u, dtype=float) - self.u_lo) / self.u_span

    def u_back(self, v):
        return self.u_lo + self.u_span * np.asarray(v, dtype=float)

    def y(self, y):
        return (np.asarray(y, dtype=float) - self.y_mid) / self.y_span

    def y_back(self, eta):
        return self.y_mid + self.y_span * np.asarray(eta, dtype=float)


def _mid_span(values: np.ndarray) -> tuple[float, float]:
    """Centre and span of ``values`` (a constant: its own size, else 1; non-finite: 0 and 1)."""
    values = values[np.isfinite(values)]
    if values.size == 0:
        return 0.0, 1.0
    lo, hi = float(values.min()), float(values.max())
    size = max(abs(lo), abs(hi))
    span = hi - lo
    if not span > 1e-9 * size:
        span = size or 1.0
    return 0.5 * (lo + hi), span
