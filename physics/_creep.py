"""Creep: an input-driven slow relaxation, a small bank of slow first-order modes of the input."""

from __future__ import annotations

import casadi as ca
import numpy as np

from ._block import AbstractBlock, Parameter
from ._traits import BlockTraits
from ._lag import lag_shapes
from ._signature import Signature

#: Time constants (s) of the default modes: a few seconds to a few minutes, the catheter's creep.
CREEP_TIME_CONSTANTS_S = (2.0, 20.0, 200.0)
#: How the modes start a run: at the first input ("steady") or at ``rest_input`` ("relaxed").
STARTS = ("relaxed", "steady")
#: Largest sum of the gains: the instant gain ``1 - sum(gain)`` stays positive, so the block
#: is invertible and the output rises with the input.
MAX_GAIN_SUM = 0.95
#: Discovery's grid of creep time constants: from this many seconds (slower than an actuator's
#: lag) to this share of the longest run (a mode slower than the data is an offset set by each
#: run's first input, not a creep that can be seen).
CREEP_GRID_FROM_S, CREEP_GRID_SHARE = 1.0, 0.25
#: Modes of a creep block discovery adds, as multiples of the best time constant of the grid: the
#: sum of relaxations that creep is made of is rarely one time constant.
CREEP_MODE_FACTORS = (0.25, 1.0, 4.0)


def _estimate(e):
    gain = float(e.coef[0]) / e.gain  # the shape is m - u of one mode with a gain of one
    # creep draws the output towards where the input has been: a negative gain (an output that
    # runs ahead of its input) is some other effect's residual, not a creep
    if not np.isfinite(gain) or gain < 1e-6:
        return None
    # best at the grid's fast end: the effect is faster than a creep (a lag's business)
    if e.grid["time_constant_s"] <= min(CREEP_GRID_FROM_S, e.grid["slowest_s"]) * (1 + 1e-9):
        return None
    return {"gain": gain}, {"time_constant_s": e.grid["time_constant_s"], "slowest_s": e.grid["slowest_s"]}


def _grid(dt, span, duration):
    hi = max(CREEP_GRID_SHARE * duration, 2 * dt)
    taus = np.unique(np.geomspace(min(CREEP_GRID_FROM_S, hi), hi, 16))
    return [{"time_constant_s": float(t), "slowest_s": float(hi)} for t in taus]


def _build(params, settings, max_step):
    best = settings["time_constant_s"]
    # no mode faster than the grid's start (a fast mode is a lag's business) nor slower than its
    # end (slower, a mode at a steady start is each run's offset), none twice
    lo, hi = min(CREEP_GRID_FROM_S, best), max(settings.get("slowest_s", np.inf), best)
    taus = sorted({float(np.clip(f * best, lo, hi)) for f in CREEP_MODE_FACTORS})
    gains = [0.0] * len(taus)
    gains[taus.index(best)] = float(np.clip(params["gain"], 0.0, 0.9 * MAX_GAIN_SUM))
    # at rest at the first input, as discovery's other blocks start: nothing tells it a rest input
    return Creep(gains=gains, time_constants_s=taus, start="steady", min_gain=0.0)


class Creep(AbstractBlock):
    """Slow relaxation towards a running mean of the input: ``y = u + sum_i gain_i (m_i - u)``.

    Each mode ``m_i`` follows the input with time constant ``T_i`` (``T_i dm_i/dt = u - m_i``,
    discretised exactly for an input linear between samples, as :class:`~physics.Lag`). A
    gain ``> 0`` draws the output towards where the input has been for the last ``T_i``
    seconds: after large cycles the output at a given input sits higher than before them
    (the catheter's creep). At rest the output equals the input, so a following ``linear``
    block keeps the static gain.

    ``start`` says where the modes are at the start of a run: ``"relaxed"`` (default) at
    ``rest_input`` (a tendon never loaded: the catheter starts straight whatever the first
    command), ``"steady"`` at the first input. It is the block's ``steady_state`` rule, so
    simulation, identification, the hybrids' predictions, export (``x0``) and MPC honour it.
    The state is ``(m_1 .. m_K, u_prev)``. ``min_gain`` (default -1) is the gains' lower bound:
    0 keeps every mode a creep (discovery's block), a negative gain lets a mode push the
    output away from the input's history.

    Examples
    --------
    >>> import numpy as np
    >>> from physics import Creep, Series
    >>> y = Series(Creep(gains=[0.5]), dt=0.1).simulate(np.ones(5))  # relaxed: starts at 1 - 0.5
    >>> bool(0.5 <= y[0] < y[-1] < 1.0)
    True
    """

    name = "creep"
    effect = "creep"
    aliases = ("relaxation",)
    rank = 4
    selection_order = 50
    #: One mode ``m - u`` with a free gain, over slow time constants: a share of the output that
    #: follows where the input has been (a lag's shape has a gain of one and is fast).
    signature = Signature(
        family="creep", terms=(), scale="free", signal="static",
        grid=_grid, positive=True, timescale="time_constant_s",
        shapes=lambda v, dt, grid: lag_shapes(v, dt, np.array([g["time_constant_s"] for g in grid])),
        estimate=_estimate, build=_build,
        describe=lambda p, s: f"gain {p['gain']:.3g} over {s['time_constant_s']:.3g} s",
    )

    def __init__(self, gains=None, time_constants_s=CREEP_TIME_CONSTANTS_S, start: str = "relaxed",
                 rest_input: float = 0.0, min_gain: float = -1.0):
        taus = np.atleast_1d(np.asarray(time_constants_s, dtype=float))
        if taus.ndim != 1 or taus.size < 1 or not np.all(np.isfinite(taus) & (taus > 0)):
            raise ValueError(f"Creep time_constants_s must be one or more times > 0 s. Got {time_constants_s} instead.")
        if start not in STARTS:
            raise ValueError(f"Creep start must be one of {list(STARTS)}. Got {start!r} instead.")
        if not np.isfinite(rest_input):
            raise ValueError(f"Creep rest_input must be a finite number. Got {rest_input} instead.")
        if not -1.0 <= min_gain <= 0.0:
            raise ValueError(f"Creep min_gain must be in [-1, 0]. Got {min_gain} instead.")
        self.min_gain = float(min_gain)
        self.time_constants_s = tuple(float(t) for t in taus)
        self.start, self.rest_input = start, float(rest_input)
        parameters = tuple(
            Parameter(f"gain_{i + 1}", 0.0, self.min_gain, MAX_GAIN_SUM, "-",
                      f"share of the output drawn to the input's mean over {t:g} s")
            for i, t in enumerate(self.time_constants_s))
        self.traits = BlockTraits.of(Creep, parameters=parameters, identity={p.name: 0.0 for p in parameters},
                                     continuous_states=tuple(f"mode_{i + 1}" for i in range(taus.size)))
        values = {} if gains is None else dict(zip((p.name for p in self.parameters), np.ravel(gains)))
        self._init_parameters(values)

    @property
    def state_names(self):
        return (*self.continuous_states, "u_prev")

    def _coefficients(self, dt):
        taus = np.array(self.time_constants_s)
        a = np.exp(-dt / taus)
        return a, 1 - (taus / dt) * (1 - a)

    def _modes(self, x, u, dt):
        a, g = self._coefficients(dt)
        k = len(self.time_constants_s)
        return [a[i] * x[i] + (1 - a[i]) * x[k] + g[i] * (u - x[k]) for i in range(k)]

    def step(self, x, u, p, dt):
        modes = self._modes(x, u, dt)
        y = u + sum(p[i] * (m - u) for i, m in enumerate(modes))
        return ca.vertcat(*modes, u), y

    def steady_state(self, u0, p):
        level = u0 if self.start == "steady" else self.rest_input
        return ca.vertcat(*([level] * len(self.time_constants_s)), u0)

    def derivative(self, xc, u, udot, p):
        dots = [(u - xc[i]) / t for i, t in enumerate(self.time_constants_s)]
        y = u + sum(p[i] * (xc[i] - u) for i in range(len(dots)))
        ydot = udot + sum(p[i] * (d - udot) for i, d in enumerate(dots))
        return ca.vertcat(*dots), y, ydot

    def constraints(self, p):
        return [(ca.sum1(p), -np.inf, MAX_GAIN_SUM)]

    def inverse_output(self, x, y, p, dt):
        # y = u (1 + sum c_i (g_i - 1)) + sum c_i A_i, with m_i = A_i + g_i u: linear in u
        a, g = self._coefficients(dt)
        k = len(self.time_constants_s)
        rest = [a[i] * x[i] + (1 - a[i]) * x[k] - g[i] * x[k] for i in range(k)]
        slope = 1 + sum(p[i] * (g[i] - 1) for i in range(k))
        return (y - sum(p[i] * rest[i] for i in range(k))) / slope

    def get_settings(self):
        return {"time_constants_s": list(self.time_constants_s), "start": self.start, "rest_input": self.rest_input,
                "min_gain": self.min_gain}

    def describe(self, dt):
        parts = ", ".join(f"{getattr(self, p.name):.3g} over {t:g} s"
                          for p, t in zip(self.parameters, self.time_constants_s))
        return f"gains {parts} ({self.start} start)"

    def __repr__(self):
        gains = ", ".join(f"{v:.6g}" for v in self.param_values())
        return (f"Creep(gains=[{gains}], time_constants_s={list(self.time_constants_s)}, "
                f"start={self.start!r}, rest_input={self.rest_input:g}, min_gain={self.min_gain:g})")
