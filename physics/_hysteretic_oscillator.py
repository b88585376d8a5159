"""A hysteretic oscillator: a mass on a spring whose restoring force carries Bouc-Wen hysteresis."""

from __future__ import annotations

import itertools

import casadi as ca
import numpy as np

from ._block import AbstractBlock, Parameter, smooth_abs
from ._resonance import RESONANCE_GRID_SHARES, RESONANCE_GRID_ZETAS, spring_step, transition

#: Hysteretic stiffness ratios ``A`` and loop half-widths (shares of the input's scale) tried as starts.
OSCILLATOR_A = (0.3, 1.0)
OSCILLATOR_SATURATIONS = (0.05, 0.5)
#: Smoothing of |x| for an input of unit scale (``eps=None``), as for the Bouc-Wen block.
EPS = 1e-6
#: Largest exponent of ``z``'s growth over one step (a loop with ``beta + s gamma sgn z < 0`` grows).
MAX_GROWTH = 50.0
#: Below this ``|y|`` the relaxation ``(e^y - 1) / y`` uses its series.
_SERIES = 1e-4


def _log1p_ratio(y):
    """``ln(1 + y) / y``, smooth through ``y = 0``."""
    return ca.if_else(ca.fabs(y) > _SERIES, ca.log1p(y) / ca.if_else(ca.fabs(y) > _SERIES, y, 1.0),
                      1 - y / 2 + y * y / 3)


def _relax(y):
    """``(e^y - 1) / y``, smooth through ``y = 0``."""
    return ca.if_else(ca.fabs(y) > _SERIES, (ca.exp(y) - 1) / ca.if_else(ca.fabs(y) > _SERIES, y, 1.0),
                      1 + y / 2 + y * y / 6)


class HystereticOscillator(AbstractBlock):
    """Second-order dynamics with the hysteresis inside the loop: the Bouc-Wen oscillator.

    ``x'' + 2 zeta w x' + w^2 (x + z) = w^2 u`` (``w = 2 pi f_n``), ``y = x``, with the hysteretic
    restoring force (in input units) ``z' = A x' - beta |x'| z - gamma x' |z|``.

    A moving mass whose spring dissipates: a bolted or friction joint, a piezo stage's flexure,
    a magnetostrictive or shape-memory rod under inertia, the Bouc-Wen benchmark (Noel and
    Schoukens, 2016; force in, displacement out). Unlike ``resonance+boucwen`` in series, the
    hysteresis depends on the *output's* path and acts back on the dynamics: the damping and the
    resonance frequency change with amplitude. At rest ``x + z = u``: a static gain of one after
    a large motion (``z`` saturates at ``A / (beta + gamma)`` when that is positive) and of
    ``1 / (1 + A)`` just after a reversal, so a following ``linear`` sets the output's units;
    the small-motion resonance is at ``f_n sqrt(1 + A)``. ``A = 0`` is the ``resonance`` block.

    Each sample is split into ``substeps`` steps, the input linear between samples. Over a step
    the mass-spring-damper is solved exactly (:func:`physics._resonance.transition`, with the
    force ``u - z`` linear in time) and ``z`` exactly along the position's path (for ``n = 1``
    and a fixed direction ``dz/d|x| = s A - b z`` relaxes exponentially, ``b = beta + s gamma
    sgn z``); the two meet in one linearised implicit solve for the position's step. No
    frequency, damping or loop is too fast for the sample rate: the scheme stays stable where
    an explicit Runge-Kutta step would not (a loop that saturates within a step, a mode above
    the Nyquist frequency), and with ``A = 0`` it is the ``resonance`` block exactly. The
    absolute values are smoothed (``sqrt(x^2 + eps^2)``; ``eps`` None is 1e-6 of the input's
    order of magnitude, set when the block is fitted, ``eps w`` for the velocity of the ODE
    form). The state is ``(x, x', z, u_prev)``; at rest at ``u0`` it is ``(u0, 0, 0, u0)``
    (no hysteretic force).

    ``Series.inverse`` inverts the block quasi-statically (``u = y + z``, the force advanced along
    the wanted path, inertia neglected), as for ``resonance``; ``hybrid.control.ModelInverse``
    follows the dynamics exactly.

    Examples
    --------
    >>> import numpy as np
    >>> from physics import HystereticOscillator, Series
    >>> block = HystereticOscillator(natural_frequency_hz=5.0, damping_ratio=0.05, A=1.0, beta=2.0, gamma=0.0)
    >>> t = np.arange(0, 4, 0.002)
    >>> y = Series(block, dt=0.002).simulate(np.sin(2 * np.pi * 0.5 * t))
    >>> bool(0.4 < y.max() < 0.9)   # the hysteretic force holds part of the input back
    True
    """

    name = "hysteretic_oscillator"
    effect = "resonance"
    closes_minor_loops = False  # minor loops drift (the Bouc-Wen law's known ratchet)
    aliases = ("boucwen_oscillator", "bouc_wen_oscillator", "hysteretic_resonance")
    parameters = (
        Parameter("natural_frequency_hz", 10.0, 1e-3, 1e5, "Hz", "undamped natural frequency of the linear spring"),
        Parameter("damping_ratio", 0.5, 1e-3, 10.0, "-", "viscous damping ratio of the linear spring"),
        Parameter("A", 0.5, 0.0, 100.0, "-", "hysteretic stiffness after a reversal, per linear stiffness"),
        Parameter("beta", 1.0, 0.0, 1e3, "1/unit", "loop shape", scaling=(-1, 0)),
        Parameter("gamma", 0.5, -1e3, 1e3, "1/unit", "loop shape", scaling=(-1, 0)),
    )
    rank = 0
    refines = ("resonance",)  # tried in place of a resonance that rings
    holds_effects = ("backlash", "hysteresis")  # its Bouc-Wen term holds a loop
    starts = 3
    #: With no hysteretic stiffness and a mode far above any sample rate it passes its input through.
    identity = {"natural_frequency_hz": 1e5, "damping_ratio": 1.0, "A": 0.0}
    takes_loop_width = True
    signature = None  # not named by discovery; select_physics tries it against whole held-out runs

    def __init__(self, natural_frequency_hz=None, damping_ratio=None, A=None, beta=None, gamma=None,
                 substeps: int = 8, eps: float | None = None):
        self._init_parameters({"natural_frequency_hz": natural_frequency_hz, "damping_ratio": damping_ratio,
                               "A": A, "beta": beta, "gamma": gamma})
        if int(substeps) != substeps or substeps < 1:
            raise ValueError(f"HystereticOscillator substeps must be a whole number >= 1. Got {substeps} instead.")
        if eps is not None and not eps > 0:
            raise ValueError(f"HystereticOscillator eps must be > 0 (or None). Got {eps} instead.")
        self.substeps = int(substeps)
        self.eps = None if eps is None else float(eps)

    def for_scale(self, s_in):
        return self if self.eps is not None else self.with_settings(eps=EPS * s_in)

    @property
    def state_names(self):
        return ("position", "velocity", "z", "u_prev")

    def _eps(self):
        return EPS if self.eps is None else self.eps

    def _rhs(self, s, u, p):
        x, v, z = s[0], s[1], s[2]
        w = 2 * np.pi * p[0]
        eps = self._eps()
        zdot = p[2] * v - p[3] * smooth_abs(v, eps * w) * z - p[4] * v * smooth_abs(z, eps)
        return ca.vertcat(v, w * w * (u - x - z) - 2 * p[1] * w * v, zdot)

    def _advance_z(self, z, dx, p):
        """``z`` after the position moves by ``dx``, and ``dz/dx`` at the start.

        Along a fixed direction ``s`` and a fixed sign of ``z``, ``dz/d|x| = s A - b z`` is linear
        and relaxes exponentially (``b = beta + s gamma sgn z``); a ``z`` behind the motion
        (``s z < 0``) crosses zero after ``d0 = ln(1 + |z| b / A) / b`` and goes on with the other
        ``b``. Exact for a monotone path.
        """
        a, beta, gamma = p[2], p[3], p[4]
        d = smooth_abs(dx, self._eps())
        s = dx / d

        def run(z0, b, dist):
            decay = ca.fmin(-b * dist, MAX_GROWTH)
            return z0 * ca.exp(decay) + s * a * dist * _relax(decay)

        behind, b_back, b_on = s * z < 0, beta - gamma, beta + gamma
        a_safe = ca.fmax(a, 1e-12)  # A = 0: z only decays, never crosses (d0 -> infinity)
        y = ca.fabs(z) * b_back / a_safe
        d0 = ca.fabs(z) / a_safe * _log1p_ratio(ca.fmax(y, -1 + 1e-9))
        crosses = ca.logic_and(y > -1, d > d0)
        z1 = ca.if_else(behind, ca.if_else(crosses, run(0 * z, b_on, d - d0), run(z, b_back, d)), run(z, b_on, d))
        return z1, a - s * ca.if_else(behind, b_back, b_on) * z

    def step(self, x, u, p, dt):
        h = dt / self.substeps
        held = transition(p, h)
        pos, vel, z, u0 = x[0], x[1], x[2], x[3]
        for i in range(self.substeps):
            ua, ub = u0 + (u - u0) * (i / self.substeps), u0 + (u - u0) * ((i + 1) / self.substeps)
            # which way the position moves (the mechanical step with z held) sets z's tangent
            # stiffness k; the step is then exact for z = z0 + k (x - x0): a spring of 1 + k
            pos_h, _ = spring_step(held, pos, vel, ua - z, ub - z)
            _, k = self._advance_z(z, pos_h - pos, p)
            pos_n, vel = self._linearised(p, h, pos, vel, z, k, ua, ub)
            z, pos = self._advance_z(z, pos_n - pos, p)[0], pos_n
        return ca.vertcat(pos, vel, z, u), pos

    @staticmethod
    def _linearised(p, h, pos, vel, z, k, ua, ub):
        """Position and velocity after ``h`` for ``z = z0 + k (x - x0)``: a spring of ``1 + k``."""
        stiff = ca.fmax(1 + k, 1e-3)
        root = ca.sqrt(stiff)
        return spring_step(transition(ca.vertcat(p[0] * root, p[1] / root), h), pos, vel,
                           (ua - z + k * pos) / stiff, (ub - z + k * pos) / stiff)

    def steady_state(self, u0, p):
        return ca.vertcat(u0, 0 * u0, 0 * u0, u0)

    continuous_states = ("position", "velocity", "z")

    def derivative(self, xc, u, udot, p):
        return self._rhs(xc, u, p), xc[0], xc[1]

    def initial_grid(self, data, values, free):
        if not any(free.values()) or not data.dt:
            return []
        fs = 1.0 / data.dt
        freqs = [s * fs for s in RESONANCE_GRID_SHARES] if free["natural_frequency_hz"] \
            else [values["natural_frequency_hz"]]
        zetas = RESONANCE_GRID_ZETAS if free["damping_ratio"] else (values["damping_ratio"],)
        amps = OSCILLATOR_A if free["A"] else (values["A"],)
        shape = free["beta"] and free["gamma"]
        sats = [s * data.input_scale for s in OSCILLATOR_SATURATIONS] if shape else [None]
        out = []
        for f, zeta, a, sat in itertools.product(freqs, zetas, amps, sats):
            point = {"natural_frequency_hz": float(f), "damping_ratio": float(zeta), "A": float(a)}
            if sat is not None:
                point.update(beta=float(a / (2 * sat)), gamma=float(a / (2 * sat)))
            out.append(point)
        return out

    def describe(self, dt):
        small = self.natural_frequency_hz * np.sqrt(1 + self.A)
        loop = self.beta + self.gamma
        sat = f"loop half-width {self.A / loop:.3g} (input units)" if loop > 1e-12 else "no saturation"
        return (f"natural frequency {self.natural_frequency_hz:.3g} Hz ({small:.3g} Hz at small motion), "
                f"damping ratio {self.damping_ratio:.3g}, hysteretic stiffness A {self.A:.3g}, {sat}")

    def inverse_output(self, x, y, p, dt):
        # Quasi-static (see the class doc): the force advanced along the wanted step of the position.
        z, _ = self._advance_z(x[2], y - x[0], p)
        return y + z
