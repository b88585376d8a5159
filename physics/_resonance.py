"""Second-order dynamics (a mass-spring-damper between command and position), discretised exactly."""

from __future__ import annotations

import casadi as ca
import numpy as np

from ._block import AbstractBlock, Parameter

#: Natural frequencies tried as starting points by identification, as shares of the sample rate.
RESONANCE_GRID_SHARES = (0.005, 0.015, 0.04, 0.1, 0.25)
#: Damping ratios tried with each of them.
RESONANCE_GRID_ZETAS = (0.1, 0.4, 1.0)
#: Below this ``|q| dt^2`` (``q = w^2 (zeta^2 - 1)``) the transition uses its Taylor series: the
#: closed forms divide by ``sqrt(|q|)``, which vanishes at critical damping.
_CRITICAL = 1e-6


def transition(p, dt):
    """``(Phi, G0, G1)`` of ``s_k = Phi s_{k-1} + G0 u_{k-1} + G1 (u_k - u_{k-1})``, ``s = (x, x')``.

    The exact solution of ``x'' + 2 zeta w x' + w^2 x = w^2 u`` over one sample for an input that
    is linear between samples (first-order hold). ``p = (natural_frequency_hz, damping_ratio)``,
    symbolic or numeric. ``Phi = e^{A dt} = e^{-a dt} (C I + S (A + a I))`` with ``a = zeta w``,
    ``C = cosh(r dt)`` and ``S = sinh(r dt) / r`` for ``r = sqrt(q)`` (``cos``, ``sin`` for
    ``q < 0``, the series at ``q = 0``); ``G0 = A^-1 (Phi - I) B`` and
    ``G1 = A^-1 (A^-1 (Phi - I) - dt I) B / dt``.
    """
    w = 2 * np.pi * p[0]
    a = p[1] * w
    q = a * a - w * w
    r_over = ca.sqrt(ca.fmax(q, 1e-300))  # overdamped: real exponents -a +- r
    r_under = ca.sqrt(ca.fmax(-q, 1e-300))  # underdamped: -a +- i r
    e1, e2 = ca.exp((r_over - a) * dt), ca.exp(-(r_over + a) * dt)  # e^{-a dt} cosh, sinh without overflow
    decay, qdt = ca.exp(-a * dt), q * dt * dt
    c = ca.if_else(qdt > _CRITICAL, (e1 + e2) / 2,
                   ca.if_else(qdt < -_CRITICAL, decay * ca.cos(r_under * dt),
                              decay * (1 + qdt / 2 + qdt * qdt / 24)))
    s = ca.if_else(qdt > _CRITICAL, (e1 - e2) / (2 * r_over),
                   ca.if_else(qdt < -_CRITICAL, decay * ca.sin(r_under * dt) / r_under,
                              decay * dt * (1 + qdt / 6 + qdt * qdt / 120)))
    phi = [[c + a * s, s], [-w * w * s, c - a * s]]
    # A^-1 = [[-2a, -1], [w^2, 0]] / w^2, B = (0, w^2)
    g0 = [-2 * a * phi[0][1] - (phi[1][1] - 1), w * w * phi[0][1]]
    g1 = [((-2 * a * g0[0] - g0[1]) / (w * w) + dt) / dt, g0[0] / dt]
    return phi, g0, g1


def spring_step(trans, pos, vel, fa, fb):
    """Position and velocity after one step of :func:`transition` ``trans = (Phi, G0, G1)``, from
    ``(pos, vel)`` with the input linear from ``fa`` to ``fb``."""
    phi, g0, g1 = trans
    df = fb - fa
    return (phi[0][0] * pos + phi[0][1] * vel + g0[0] * fa + g1[0] * df,
            phi[1][0] * pos + phi[1][1] * vel + g0[1] * fa + g1[1] * df)


class Resonance(AbstractBlock):
    """Second-order dynamics ``x'' + 2 zeta w x' + w^2 x = w^2 u`` (``w = 2 pi f_n``), ``y = x``.

    A mass on a spring with viscous damping between the command and the position: a piezo
    stack's or a flexure's first mode, a tendon's stretch with the catheter's inertia, the
    linear part of the Bouc-Wen benchmark's oscillator. The static gain is one (a following
    ``linear`` block sets the output's units); below ``damping_ratio`` 1 a step overshoots and
    rings at ``f_n sqrt(1 - zeta^2)``, which a first-order ``lag`` cannot do.

    Discretised exactly for an input that is linear between samples (:func:`transition`: the
    matrix exponential in closed form, any ``f_n dt`` stable), so the only approximation is the
    input's interpolation. The state is ``(x, x', u_prev)``; at rest at ``u0`` it is ``(u0, 0, u0)``.

    ``Series.inverse`` (and an inverse hybrid's physics) inverts the block at its static gain:
    no causal step inverse of a sampled second-order system is stable, so the inverse path is
    the quasi-static one, off by about ``2 zeta f / f_n`` of the motion at frequency ``f``;
    ``hybrid.control.ModelInverse`` follows the resonance exactly.

    Examples
    --------
    >>> import numpy as np
    >>> from physics import Resonance, Series
    >>> step = np.r_[0.0, np.ones(299)]
    >>> y = Series(Resonance(natural_frequency_hz=2.0, damping_ratio=0.1), dt=0.01).simulate(step)
    >>> round(float(y.max()), 2)   # overshoots by exp(-pi zeta / sqrt(1 - zeta^2)) = 0.73
    1.73
    """

    name = "resonance"
    effect = "resonance"
    aliases = ("second_order", "mass_spring_damper", "oscillation")
    #: Critically damped well above any sample rate below 10 kHz: settled within a sample.
    identity = {"natural_frequency_hz": 1e5, "damping_ratio": 1.0}
    parameters = (
        Parameter("natural_frequency_hz", 10.0, 1e-3, 1e5, "Hz", "undamped natural frequency"),
        Parameter("damping_ratio", 0.5, 1e-3, 10.0, "-", "damping ratio (below 1: it rings)"),
    )
    rank = 0
    selection_order = 60
    starts = 3  # a resonance's frequency is a local-minimum hunt, like a lag's time constant
    # Not named by discovery: well below its natural frequency a resonance's residual is
    # ``-(2 zeta / w) dv/dt + ((4 zeta^2 - 1) / w^2) d2v/dt2``, which a lag's or a delay's matches
    # to first order, and on lagging or delayed data the two-parameter block won their family.
    # ``select_physics`` adds it where whole held-out runs say it helps.
    signature = None

    def __init__(self, natural_frequency_hz: float | None = None, damping_ratio: float | None = None):
        self._init_parameters({"natural_frequency_hz": natural_frequency_hz, "damping_ratio": damping_ratio})

    @property
    def state_names(self):
        return ("position", "velocity", "u_prev")

    def step(self, x, u, p, dt):
        pos, vel = spring_step(transition(p, dt), x[0], x[1], x[2], u)
        return ca.vertcat(pos, vel, u), pos

    def steady_state(self, u0, p):
        return ca.vertcat(u0, 0 * u0, u0)

    continuous_states = ("position", "velocity")

    def derivative(self, xc, u, udot, p):
        w = 2 * np.pi * p[0]
        acc = w * w * (u - xc[0]) - 2 * p[1] * w * xc[1]
        return ca.vertcat(xc[1], acc), xc[0], xc[1]

    def initial_grid(self, data, values, free):
        if not (free["natural_frequency_hz"] or free["damping_ratio"]):
            return []
        fs = 1.0 / data.dt if data.dt else None
        freqs = [s * fs for s in RESONANCE_GRID_SHARES] if fs and free["natural_frequency_hz"] \
            else [values["natural_frequency_hz"]]
        zetas = RESONANCE_GRID_ZETAS if free["damping_ratio"] else (values["damping_ratio"],)
        return [{"natural_frequency_hz": float(f), "damping_ratio": float(z)} for f in freqs for z in zetas]

    def describe(self, dt):
        return f"natural frequency {self.natural_frequency_hz:.3g} Hz, damping ratio {self.damping_ratio:.3g}"

    @classmethod
    def shows_effect(cls, values):
        # overdamped, the block is two first-order lags: nothing rings whose damping could change
        return values["damping_ratio"] < 1.0

    def inverse_output(self, x, y, p, dt):
        # The exact step inverse is unstable: the sampled system's zero lies outside the unit
        # circle (near -3.7 for an input linear between samples), so the input that makes the
        # position hit each sample exactly grows without bound. The block is inverted at its
        # static gain instead (quasi-static: exact for paths slow against the resonance);
        # hybrid.control.ModelInverse solves for the input over a window and inverts it exactly.
        return y
