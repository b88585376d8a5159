"""The Bouc-Wen benchmark system (Noel and Schoukens, 2016) as a block, for identify().

    m y'' + c y' + k y + z = u,
    z' = alpha y' - (beta gamma) |y'| |z|^(nu - 1) z - (beta delta) y' |z|^nu,   nu = 1

Only the products beta*gamma and beta*delta enter the equations, so those are
the parameters (``beta_gamma``, ``beta_delta``). The block integrates the
continuous equations with ``substeps`` RK4 steps per sample, the force
interpolated linearly between samples (first-order hold). The state is
``(y, y', z, u_prev)`` and the output is the displacement ``y`` (m), so
``Series(BoucWenOscillator(), dt=1/750)`` is identified by :func:`identify` like
any other model.
"""

from __future__ import annotations

import casadi as ca

from physics import AbstractBlock, Parameter, rk_step

#: The benchmark's true values (m, c, k, alpha, beta*gamma, beta*delta).
PUBLISHED = {"mass_kg": 2.0, "damping_Ns_per_m": 10.0, "stiffness_N_per_m": 5e4,
             "alpha_N_per_m": 5e4, "beta_gamma": 800.0, "beta_delta": -1100.0}
RATE_HZ = 750.0


def _abs(x, eps=1e-9):
    return ca.sqrt(x * x + eps * eps)


class BoucWenOscillator(AbstractBlock):
    """Mass-spring-damper with a Bouc-Wen restoring force (nu = 1); see the module doc."""

    name = "boucwen_oscillator"
    parameters = (
        Parameter("mass_kg", 1.0, 1e-3, 1e3, "kg", "moving mass"),
        Parameter("damping_Ns_per_m", 1.0, 0.0, 1e4, "N s/m", "viscous damping"),
        Parameter("stiffness_N_per_m", 1e4, 0.0, 1e7, "N/m", "linear stiffness"),
        Parameter("alpha_N_per_m", 1e4, 0.0, 1e7, "N/m", "hysteretic stiffness"),
        Parameter("beta_gamma", 0.0, -1e6, 1e6, "1/m", "Bouc-Wen beta * gamma"),
        Parameter("beta_delta", 0.0, -1e6, 1e6, "1/m", "Bouc-Wen beta * delta"),
    )

    def __init__(self, substeps: int = 4, **values):
        self._init_parameters(values)
        self.substeps = int(substeps)

    @property
    def state_names(self):
        return ("y_m", "v_m_per_s", "z_N", "u_prev_N")

    @staticmethod
    def _rhs(s, u, p):
        y, v, z = s[0], s[1], s[2]
        m, c, k, alpha, bg, bd = (p[i] for i in range(6))
        acc = (u - c * v - k * y - z) / m
        dz = alpha * v - bg * _abs(v) * z - bd * v * _abs(z)
        return ca.vertcat(v, acc, dz)

    def step(self, x, u, p, dt):
        s, u0 = x[0:3], x[3]
        h = dt / self.substeps
        force = lambda t: u0 + (u - u0) * (t / dt)  # noqa: E731  first-order hold
        for i in range(self.substeps):
            s = rk_step(lambda t, si: self._rhs(si, force(t), p), i * h, s, h)
        return ca.vertcat(s, u), s[0]

    def steady_state(self, u0, p):
        return ca.vertcat(0, 0, 0, u0)  # at rest (the benchmark starts from rest, u = 0)
