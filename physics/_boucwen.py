"""Bouc-Wen rate-independent hysteresis."""

from __future__ import annotations

import casadi as ca

from ._block import AbstractBlock, Parameter, smooth_abs


class BoucWen(AbstractBlock):
    """Bouc-Wen hysteresis ``y = u - z`` with

    ``dz = A du - beta |du| |z|^(n-1) z - gamma du |z|^n``.

    ``z`` is the motion lost to friction: with ``A > 0`` it grows while the input
    rises, so the rising branch lies below the falling one, as a tendon-driven
    catheter's tip angle lags its tendon (``A < 0`` turns the loop the other way).
    The output keeps moving with the input (and the block stays invertible) while
    ``dz/du < 1``; for ``n = 1`` that is ``2 A beta / (beta + gamma) < 1``
    (``A = 1, beta = gamma`` is the limit: a flat zone after each reversal).

    The law is rate independent, so each step integrates ``dz/du`` along the
    straight input segment from ``u_{k-1}`` to ``u_k`` (``substeps`` RK4 steps in
    the path parameter). The loop saturates at ``|z| = (A / (beta + gamma))^(1/n)``
    (input units). The absolute values are smoothed (``sqrt(x^2 + eps^2)``, eps
    1e-6 input units) so that gradients exist everywhere.

    The state is ``(z_{k-1}, u_{k-1})``. ``n`` is held fixed when identifying
    unless asked for: with ``n`` free the problem is poorly conditioned.
    """

    name = "boucwen"
    parameters = (
        Parameter("A", 0.5, -100.0, 100.0, "-", "initial slope of z after a reversal"),
        Parameter("beta", 1.0, 0.0, 1e3, "1/unit^n", "loop shape"),
        Parameter("gamma", 0.5, -1e3, 1e3, "1/unit^n", "loop shape"),
        Parameter("n", 1.0, 1.0, 10.0, "-", "sharpness of the transition", fit=False),
    )

    def __init__(self, A=None, beta=None, gamma=None, n=None, substeps: int = 2):
        self._init_parameters({"A": A, "beta": beta, "gamma": gamma, "n": n})
        self.substeps = int(substeps)

    @property
    def state_names(self):
        return ("z", "u_prev")

    @staticmethod
    def _rate(z, h, p):
        A, beta, gamma, n = p[0], p[1], p[2], p[3]
        zz = z * z + 1e-12
        return A * h - beta * smooth_abs(h) * z * zz ** ((n - 1) / 2) - gamma * h * zz ** (n / 2)

    def _advance(self, z, h, p):
        ds = 1.0 / self.substeps
        for _ in range(self.substeps):
            k1 = self._rate(z, h, p)
            k2 = self._rate(z + ds / 2 * k1, h, p)
            k3 = self._rate(z + ds / 2 * k2, h, p)
            k4 = self._rate(z + ds * k3, h, p)
            z = z + ds / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        return z

    continuous_states = ("z",)

    def derivative(self, xc, u, udot, p):
        zdot = self._rate(xc[0], udot, p)
        return zdot, u - xc[0], udot - zdot

    def step(self, x, u, p, dt):
        z = self._advance(x[0], u - x[1], p)
        return ca.vertcat(z, u), u - z

    def steady_state(self, u0, p):
        return ca.vertcat(0, u0)

    def inverse_guess(self, x, y, p):
        return y + x[0]
