"""Blocks composed in signal order into one model."""

from __future__ import annotations

import copy
from functools import cached_property
from typing import Any

import casadi as ca
import numpy as np

from ._block import AbstractBlock
from ._cache import built
from ._errors import PhysicsError
from ._registry import BLOCKS, make_block

#: Rollout functions by (structure, length), oldest first (see ``Series.rollout``).
_ROLLOUTS: dict[tuple, ca.Function] = {}
_ROLLOUT_CACHE_SIZE = 64
#: Steps built (:meth:`Series.step_function`), by structure; the oldest go first.
_STEPS: dict[tuple, ca.Function] = {}


def _check_range(input_range) -> tuple[float, float] | None:
    if input_range is None:
        return None
    try:
        lo, hi = (float(v) for v in input_range)
    except (TypeError, ValueError):
        lo = hi = float("nan")
    if not (np.isfinite(lo) and np.isfinite(hi) and lo <= hi):
        raise PhysicsError(f"A Series' input_range must be (low, high), finite, low <= high, or None. "
                           f"Got {input_range!r} instead.")
    return lo, hi


class Series:
    """Blocks in signal order: the output of each is the input of the next.

    The model's parameters and states are the blocks' own, concatenated in
    order and named ``"<block>.<name>"`` (``"lag.time_constant_s"``). The
    equations live in the blocks' CasADi ``step``; simulation, identification,
    inversion and export all use that one graph.

    Parameters
    ----------
    *blocks : AbstractBlock
        The blocks, input side first.
    dt : float
        Sample time of the model (s). Default 0.04 s (25 Hz, the seed paper's rate).
    input_range : (float, float) or None
        The range of the input the model was fitted on (set by identification; ``None``:
        unknown). Kept with the model and its export, where a controller takes it as its
        default input bounds (:class:`hybrid.control.TrackingMPC`).

    Examples
    --------
    >>> import numpy as np
    >>> from physics import Series, Lag, BoucWen, LinearMap
    >>> model = Series(Lag(), BoucWen(), LinearMap(), dt=0.04)
    >>> model.spec
    'lag+boucwen+linear'
    >>> u = 3 - 3 * np.cos(2 * np.pi * 0.2 * np.arange(0, 10, 0.04))
    >>> y = model.simulate(u)
    >>> u_back = model.inverse(y)
    >>> bool(np.max(np.abs(u_back - u)) < 1e-6)
    True
    """

    def __init__(self, *blocks: AbstractBlock, dt: float = 0.04,
                 input_range: tuple[float, float] | None = None):
        if not blocks:
            raise PhysicsError("A Series needs at least one block, e.g. Series(LinearMap()).")
        for b in blocks:
            if not isinstance(b, AbstractBlock):
                raise PhysicsError(f"Series takes blocks; got {type(b).__name__}.")
        if not (np.isfinite(dt) and dt > 0):
            raise PhysicsError(f"The model's sample time dt must be > 0 s. Got {dt} instead.")
        wide = [i for i, b in enumerate(blocks) if b.output_size != 1]
        if wide and wide[0] != len(blocks) - 1:
            b = blocks[wide[0]]
            raise PhysicsError(f"Block '{b.name}' outputs {b.output_size} signals, so it must be the model's last "
                               f"block; '{blocks[wide[0] + 1].name}' follows it. Put the blocks that act on "
                               "one signal before it.")
        self.blocks = tuple(blocks)
        self.dt = float(dt)
        self.input_range = _check_range(input_range)

    @classmethod
    def from_spec(cls, spec: str, dt: float = 0.04) -> "Series":
        """A model from a spec string such as ``"lag+boucwen+linear"``."""
        names = [s for s in spec.replace(" ", "").split("+")]
        if not spec.strip() or any(not n for n in names):
            raise PhysicsError(f"Bad model spec '{spec}': write block names joined by '+', "
                               "e.g. 'lag+boucwen+linear'.")
        return cls(*(make_block(n) for n in names), dt=dt)

    # -- naming ------------------------------------------------------------
    @property
    def spec(self) -> str:
        return "+".join(b.name for b in self.blocks)

    @cached_property
    def _prefixes(self) -> tuple[str, ...]:
        seen: dict[str, int] = {}
        out = []
        for b in self.blocks:
            seen[b.name] = seen.get(b.name, 0) + 1
            out.append(b.name if seen[b.name] == 1 else f"{b.name}{seen[b.name]}")
        return tuple(out)

    @property
    def param_names(self) -> list[str]:
        return [f"{pre}.{p.name}" for pre, b in zip(self._prefixes, self.blocks) for p in b.parameters]

    @property
    def state_names(self) -> list[str]:
        return [f"{pre}.{s}" for pre, b in zip(self._prefixes, self.blocks) for s in b.state_names]

    @property
    def n_x(self) -> int:
        return sum(b.n_x for b in self.blocks)

    @property
    def n_p(self) -> int:
        return sum(b.n_p for b in self.blocks)

    @property
    def n_y(self) -> int:
        """How many outputs the model has: its last block's (1 unless it is a map to several)."""
        return self.blocks[-1].output_size

    def output_view(self, index: int) -> "Series":
        """This model seen through its output ``index`` alone (a model of one output with the same blocks,
        states and parameter names): what follows one output of several, e.g. ``model.output_view(2).inverse(
        wanted_y)``, the tendon path that makes the tip's ``y`` follow ``wanted_y`` (the other outputs go
        where that path takes them)."""
        from ._output_maps import OutputOf

        if self.n_y == 1:
            raise PhysicsError(f"'{self.spec}' has one output; it is its own view.")
        return Series(*self.blocks[:-1], OutputOf(self.blocks[-1], index), dt=self.dt, input_range=self.input_range)

    def _single_output(self, what: str) -> None:
        if self.n_y != 1:
            raise PhysicsError(f"{what} takes a model with one output; '{self.spec}' has {self.n_y}. "
                               "Use a model of the output you need (its own chain and map).")

    # -- parameter values ---------------------------------------------------
    def _meta(self, attr):
        return np.array([getattr(p, attr) for b in self.blocks for p in b.parameters], dtype=float)

    @property
    def params(self) -> np.ndarray:
        """Current parameter values, in ``param_names`` order."""
        if self.n_p == 0:
            return np.zeros(0)
        return np.concatenate([b.param_values() for b in self.blocks])

    @params.setter
    def params(self, values) -> None:
        values = np.asarray(values, dtype=float).ravel()
        if values.size != self.n_p:
            raise PhysicsError(f"Model '{self.spec}' has {self.n_p} parameters; got {values.size} values.")
        for b, chunk in zip(self.blocks, self._split(values, "p")):
            b.set_param_values(chunk)

    def param_dict(self) -> dict[str, float]:
        return dict(zip(self.param_names, self.params.tolist()))

    def set_params(self, **named) -> "Series":
        """Set parameters by name, ``model.set_params(**{"lag.time_constant_s": 0.1})``."""
        values = self.param_dict()
        unknown = sorted(set(named) - set(values))
        if unknown:
            raise PhysicsError(f"Unknown parameter(s) {unknown} for '{self.spec}'. "
                               f"Known: {', '.join(values)}.")
        for name, value in named.items():
            try:
                number = float(value)
            except (TypeError, ValueError):
                number = float("nan")
            if not np.isfinite(number):
                raise PhysicsError(f"The '{name}' parameter of '{self.spec}' must be a finite number. Got {value!r} "
                                   "instead.")
            values[name] = number
        self.params = list(values.values())
        return self

    def signal_scales(self, s_u: float, s_y: float) -> tuple[np.ndarray, np.ndarray]:
        """Typical magnitudes of the parameters and of the states for an input of scale ``s_u``
        and an output of scale ``s_y``: ``Parameter.scaling`` and ``state_scaling`` applied
        along the signal path, each block's input scale the previous block's output scale.
        Multiply ``lower_bounds``/``upper_bounds`` by the first to get bounds in the data's units."""
        params, states, s = [], [], float(s_u)
        for b in self.blocks:
            s_out = float(b.output_scale(s, s_y))
            params += [s ** a * s_out ** c for a, c in (p.scaling for p in b.parameters)]
            powers = b.state_scaling if b.state_scaling is not None else (1.0,) * b.n_x
            states += [s ** a for a in powers]
            s = s_out
        return np.array(params, dtype=float), np.array(states, dtype=float)

    def for_scales(self, s_u: float, s_y: float, u_range: tuple[float, float] | None = None) -> "Series":
        """A copy whose blocks resolve their data-dependent settings (``AbstractBlock.for_scale``)
        for an input of scale ``s_u`` and an output of scale ``s_y``, and, given the input's range
        ``u_range``, those set by its location (``AbstractBlock.for_range``; the blocks before the
        output map keep their input's units, so each sees about that range)."""
        blocks, s = [], float(s_u)
        for b in self.blocks:
            b = b.for_scale(s)
            if u_range is not None and b.affine_output is not None:
                u_range = None  # the output map leaves the input's units
            if u_range is not None:
                b = b.for_range(*u_range)
            blocks.append(copy.deepcopy(b))
            s = float(b.output_scale(s, s_y))
        return Series(*blocks, dt=self.dt, input_range=self.input_range)

    @property
    def lower_bounds(self) -> np.ndarray:
        return self._meta("lower")

    @property
    def upper_bounds(self) -> np.ndarray:
        return self._meta("upper")

    @property
    def fit_mask(self) -> np.ndarray:
        """True for parameters fitted by default."""
        return np.array([p.fit for b in self.blocks for p in b.parameters], dtype=bool)

    def _split(self, vec, kind):
        sizes = [b.n_p if kind == "p" else b.n_x for b in self.blocks]
        offsets = np.cumsum([0] + sizes)
        return [vec[offsets[i]:offsets[i + 1]] for i in range(len(sizes))]

    def constraints(self, p) -> list:
        """Parameter constraints ``(expr, lower, upper)`` the blocks declare."""
        return [c for b, pb in zip(self.blocks, self._split(p, "p")) for c in b.constraints(pb)]

    # -- equations ------------------------------------------------------------
    def step_expr(self, x, u, p):
        """Symbolic ``(x_next, y)`` of the whole chain (SX or MX)."""
        xs, ps = self._split(x, "x"), self._split(p, "p")
        nexts, signal = [], u
        for b, xb, pb in zip(self.blocks, xs, ps):
            xn, signal = b.step(xb, signal, pb, self.dt)
            nexts.append(xn)
        return ca.vertcat(*nexts), signal

    def step_function(self) -> ca.Function:
        """``Function('step', [x, u, p], [x_next, y])`` of the model at its rate. Built once per
        structure, as :meth:`rollout`: a selection's fold fits ask for it about ten times each."""
        return built(_STEPS, self._structure(), _ROLLOUT_CACHE_SIZE, self._build_step)

    def _build_step(self) -> ca.Function:
        x, u, p = ca.SX.sym("x", self.n_x), ca.SX.sym("u"), ca.SX.sym("p", self.n_p)
        x_next, y = self.step_expr(x, u, p)
        return ca.Function("step", [x, u, p], [x_next, y], ["x", "u", "p"], ["x_next", "y"])

    def rollout(self, n: int) -> ca.Function:
        """``Function('rollout', [x0, u, p], [x, y])`` over ``n`` samples.

        ``u`` and ``y`` are 1 x n; ``x`` (n_x x n) holds the state *after* each step.
        Built once per structure (block types, settings, dt) and length: building costs
        several times a call, and parameters are an input, so every simulation of the same
        structure and length shares it.
        """
        return built(_ROLLOUTS, (self._structure(), int(n)), _ROLLOUT_CACHE_SIZE, lambda: self._build_rollout(n))

    def _structure(self) -> tuple:
        return (float(self.dt),) + tuple(
            (type(b), repr(sorted(b.get_settings().items()))) for b in self.blocks)

    def _build_rollout(self, n: int) -> ca.Function:
        step = self.step_function()
        acc = step.mapaccum("acc", n)
        x0, u, p = ca.MX.sym("x0", self.n_x), ca.MX.sym("u", 1, n), ca.MX.sym("p", self.n_p)
        xs, ys = acc(x0, u, ca.repmat(p, 1, n))
        return ca.Function("rollout", [x0, u, p], [xs, ys], ["x0", "u", "p"], ["x", "y"])

    def steady_state(self, u0: float, p=None) -> np.ndarray:
        """State after the input has rested at ``u0``: each block at its own input."""
        return self._steady(u0, p)[0]

    def steady_state_expr(self, u0, p):
        """``(x0, y0)``: the rest state and output at input ``u0``, for numbers, SX, MX or DM.

        Each block rests at its own input (the rest output of the blocks before it);
        the one rule behind :meth:`steady_state` and the exported models' ``x0``.
        """
        parts, signal = [], u0
        for b, pb in zip(self.blocks, self._split(p, "p")):
            xb = b.steady_state(signal, pb) if b.n_x else ca.DM.zeros(0, 1)
            _, signal = b.step(xb, signal, pb, self.dt)
            parts.append(xb)
        return ca.vertcat(*parts) if parts else ca.DM.zeros(0, 1), signal

    def _steady(self, u0: float, p=None) -> tuple[np.ndarray, float]:
        p = self.params if p is None else np.asarray(p, dtype=float)
        x0, y0 = self.steady_state_expr(ca.DM(float(u0)), ca.DM(p) if p.size else ca.DM.zeros(0, 1))
        y0 = np.asarray(ca.DM(y0), dtype=float).ravel()
        return np.asarray(ca.DM(x0), dtype=float).ravel(), (float(y0[0]) if y0.size == 1 else y0)

    def steady_input(self, y0: float, p=None, bounds: tuple[float, float] | None = None) -> float:
        """The constant input whose steady output is ``y0`` (secant, then bisection); with
        ``bounds = (lo, hi)`` the nearest input within them (an inverse's rest input). Where the secant's
        root lies outside the bounds but the outputs at the bounds bracket ``y0`` (a map that turns back,
        a cubic or an arc), the root between them, by bisection."""
        lo, hi = _check_bounds(bounds)
        root = self._steady_input(y0, p)
        if lo <= root <= hi or not (np.isfinite(lo) and np.isfinite(hi)):
            return float(np.clip(root, lo, hi))
        out = lambda v: self._steady(v, p)[1] - y0  # noqa: E731
        f_lo, f_hi = out(lo), out(hi)
        if f_lo * f_hi > 0:
            return float(np.clip(root, lo, hi))
        if f_lo == 0:
            return float(lo)
        return float(_bisect(out, lo, hi) if f_lo < 0 else _bisect(out, hi, lo))

    def _steady_input(self, y0: float, p=None) -> float:
        self._single_output("The steady input of an output")
        out = lambda v: self._steady(v, p)[1] - y0  # noqa: E731
        a, b = 0.0, 1.0
        fa, fb = out(a), out(b)
        for _ in range(60):
            if fb == 0 or fb == fa:
                break
            a, fa, b = b, fb, b - fb * (b - a) / (fb - fa)
            fb = out(b)
            if abs(b - a) <= 1e-12 * (1 + abs(b)):
                return b
        lo, hi = -1.0, 1.0  # not smooth (e.g. Preisach): bracket, then bisect
        while out(lo) > 0 and lo > -1e9:
            lo *= 2
        while out(hi) < 0 and hi < 1e9:
            hi *= 2
        return _bisect(out, lo, hi)

    # -- continuous time ----------------------------------------------------------
    @property
    def continuous_state_names(self) -> list[str]:
        missing = [b.name for b in self.blocks if b.continuous_states is None]
        if missing:
            usable = [n for n in BLOCKS if make_block(n).continuous_states is not None]
            raise PhysicsError(f"Block(s) {', '.join(missing)} have no continuous-time form; "
                               f"a neural-ODE model can use {', '.join(usable)}.")
        return [f"{pre}.{s}" for pre, b in zip(self._prefixes, self.blocks) for s in b.continuous_states]

    def ode_function(self) -> ca.Function:
        """``Function('ode', [xc, u, udot, p], [xc_dot, y])``: the chain in continuous time.

        ``udot`` is the input's rate (e.g. from the input interpolated linearly
        between samples); each block passes the rate of its output on.
        """
        names = self.continuous_state_names
        xc, u = ca.SX.sym("xc", len(names)), ca.SX.sym("u")
        udot, p = ca.SX.sym("udot"), ca.SX.sym("p", self.n_p)
        sizes = np.cumsum([0] + [len(b.continuous_states) for b in self.blocks])
        dots, signal, rate = [], u, udot
        for i, (b, pb) in enumerate(zip(self.blocks, self._split(p, "p"))):
            xd, signal, rate = b.derivative(xc[int(sizes[i]):int(sizes[i + 1])], signal, rate, pb)
            dots.append(xd)
        return ca.Function("ode", [xc, u, udot, p], [ca.vertcat(*dots), signal],
                           ["xc", "u", "udot", "p"], ["xc_dot", "y"])

    def continuous_steady_state(self, u0: float, p=None) -> np.ndarray:
        """Continuous state at rest at input ``u0``.

        Each block's continuous states are among its discrete ones, by name.
        """
        x = self.steady_state(u0, p)
        return x[[self.state_names.index(n) for n in self.continuous_state_names]]

    # -- numerics ---------------------------------------------------------------
    def _check_path(self, v, what):
        v = np.asarray(v, dtype=float)
        if v.ndim != 1 or v.size < 1:
            raise PhysicsError(f"The {what} must be a 1-D array with at least one sample; "
                               f"got shape {v.shape}.")
        bad = np.flatnonzero(~np.isfinite(v))
        if bad.size:
            raise PhysicsError(f"The {what} has a non-finite value at index {bad[0]}; "
                               "clean or interpolate the data first.")
        return v

    def _check_x0(self, x0, default):
        x0 = default if x0 is None else np.asarray(x0, dtype=float).ravel()
        if x0.size != self.n_x:
            raise PhysicsError(f"x0 must have {self.n_x} entries ({', '.join(self.state_names)}); "
                               f"got {x0.size}.")
        return x0

    def estimate_state(self, u_w, y_w, p=None, offset: bool = False):
        """The state after the measured window ``(u_w, y_w)``, where a prediction of the samples that
        follow it starts: the state before the window fitted to it by least squares (the rest state
        at ``u_w[0]`` as the prior), then rolled through it. ``offset=True`` also estimates a constant
        output offset. Returns a :class:`~physics._warmup.WarmState` ``(x, x0, offset)``."""
        from ._warmup import estimate

        return estimate(self, u_w, y_w, p, offset)

    def simulate(self, u, x0=None, p=None, return_states: bool = False, warmup=None,
                 offset: bool = False):
        """Output for the input path ``u`` sampled at ``dt``.

        ``x0`` defaults to the steady state at ``u[0]``; ``warmup=(u_w, y_w)``, the measured
        samples just before ``u`` (or a Trajectory of them), sets it from them instead (:meth:`estimate_state`, with an output
        offset when ``offset=True``). With ``return_states=True`` also returns the (n, n_x) states
        *before* each sample. A model with several outputs (``n_y > 1``) returns them as ``(n, n_y)``.
        """
        u = self._check_path(u, "input path u")
        p = self.params if p is None else np.asarray(p, dtype=float)
        bias = 0.0
        if warmup is not None:
            self._single_output("A warm-up window")
            if x0 is not None:
                raise PhysicsError("Give x0 or a warm-up window, not both: the window sets the state.")
            x0, _, bias = self.estimate_state(*_pair(warmup), p=p, offset=offset)
        x0 = self._check_x0(x0, None if x0 is not None else self.steady_state(u[0], p))
        xs, ys = self.rollout(u.size)(x0, u[None, :], p)
        y = np.asarray(ys, dtype=float).reshape(self.n_y, u.size).T if self.n_y > 1 else \
            np.asarray(ys, dtype=float).ravel() + bias
        if not return_states:
            return y
        xs = np.asarray(xs, dtype=float).reshape(self.n_x, u.size)
        before = np.hstack([x0[:, None], xs[:, :-1]]).T
        return y, before

    # -- inverse -----------------------------------------------------------------
    @property
    def has_delay(self) -> bool:
        """True when a block is a pure delay (the model then has no causal inverse step)."""
        return any(b.pure_delay for b in self.blocks)

    def _causal(self) -> tuple["Series", int]:
        delay = sum(b.delay_samples for b in self.blocks)
        rest = [b for b in self.blocks if not b.pure_delay]
        return (Series(*rest, dt=self.dt) if rest else None), delay

    def inverse_step_function(self, bounds: tuple[float, float] | None = None,
                              quasi_static: bool = False) -> ca.Function:
        """``Function('inverse_step', [x, y, p], [x_next, u])`` for a delay-free model.

        Each block is inverted in turn from the output side: explicitly where the
        block is invertible (lag, linear, drift, backlash), by a Newton root
        solve (CasADi ``rootfinder``) or bisection otherwise. With ``bounds = (lo, hi)``
        the input is clipped to them and the state advanced by the clipped input: the model
        follows the wanted path as closely as an actuator limited to that range can (a wanted
        output the model cannot reach, or one whose noise a lag's inverse amplifies, then asks
        for the nearest bound, not for an input far outside anything the actuator was driven with).
        With ``quasi_static=True`` blocks of unit static gain (a lag) pass the wanted signal
        through instead of inverting their dynamics: on noisy wanted paths the exact inverse of a
        lag amplifies the noise by about ``T / dt``.
        """
        if self.has_delay:
            raise PhysicsError("A model with a delay has no causal inverse step; "
                               "use Series.inverse, which advances the wanted path.")
        self._single_output("The inverse")
        lo, hi = _check_bounds(bounds)
        x, y, p = ca.MX.sym("x", self.n_x), ca.MX.sym("y"), ca.MX.sym("p", self.n_p)
        xs, ps = self._split(x, "x"), self._split(p, "p")
        signal = y
        for b, xb, pb in reversed(list(zip(self.blocks, xs, ps))):
            if not (quasi_static and b.unit_static_gain):
                signal = b.inverse_output(xb, signal, pb, self.dt)
        if bounds is not None:  # fmax/fmin take the bound over a NaN (a root solve that failed)
            signal = ca.fmin(ca.fmax(signal, lo), hi)
        x_next, _ = self.step_expr(x, signal, p)
        return ca.Function("inverse_step", [x, y, p], [x_next, signal],
                           ["x", "y", "p"], ["x_next", "u"])

    def inverse(self, y, x0=None, p=None, bounds: tuple[float, float] | None = None,
                quasi_static: bool = False, warmup=None) -> np.ndarray:
        """Input path that makes the model follow the output path ``y``.

        A pure delay of ``d`` samples is inverted by advancing ``y`` by ``d``
        (the last ``d`` inputs repeat the last value). ``x0`` defaults to the
        steady state whose output is ``y[0]``; ``warmup=(u_w, y_w)``, the measured input and output
        just before ``y`` (in the forward model's roles), sets it from them (:meth:`estimate_state`).
        ``bounds = (lo, hi)`` limits the input, and ``quasi_static`` passes the wanted signal through
        lags (see :meth:`inverse_step_function`).
        """
        self._single_output("The inverse")
        y = self._check_path(y, "wanted output path y")
        if warmup is not None:
            if x0 is not None:
                raise PhysicsError("Give x0 or a warm-up window, not both: the window sets the state.")
            if self.has_delay:
                raise PhysicsError("A warm-up window sets the state of a delay-free inverse; this model has "
                                   "a delay (its inverse advances the wanted path instead).")
            x0 = self.estimate_state(*_pair(warmup), p=p).x
        lo, hi = _check_bounds(bounds)
        p = self.params if p is None else np.asarray(p, dtype=float)
        causal, delay = self._causal()
        if causal is None:
            return np.clip(np.concatenate([y[delay:], np.full(min(delay, y.size), y[-1])])[: y.size], lo, hi)
        keep = [not b.pure_delay for b in self.blocks]
        pc = np.concatenate([pb for pb, k in zip(self._split(p, "p"), keep) if k] or [np.zeros(0)])
        target = np.concatenate([y[delay:], np.full(delay, y[-1])])[: y.size]
        inv = causal.inverse_step_function(bounds, quasi_static)
        if x0 is None:
            x0 = causal.steady_state(causal.steady_input(target[0], pc, bounds), pc)
        x0 = causal._check_x0(x0, None)
        _, us = inv.mapaccum("inverse", y.size)(x0, target[None, :], ca.repmat(ca.DM(pc), 1, y.size))
        return np.asarray(us, dtype=float).ravel()

    # -- serialization -------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: dt, each block's name and structural settings, and the parameters.

        ``Series.from_dict(model.to_dict())`` rebuilds the model exactly.
        """
        return {"spec": self.spec, "dt": self.dt,
                "blocks": [{"name": b.name, "settings": b.get_settings()} for b in self.blocks],
                "params": [float(v) for v in self.params],
                "parameters": self.param_dict(),
                **({} if self.input_range is None else {"input_range": list(self.input_range)})}

    @classmethod
    def from_dict(cls, state: dict[str, Any]) -> "Series":
        """The model written by :meth:`to_dict` (``parameters`` by name, or the ``params`` list)."""
        try:
            blocks = [make_block(b["name"], **b.get("settings", {})) for b in state["blocks"]]
            model = cls(*blocks, dt=float(state["dt"]), input_range=state.get("input_range"))
        except (KeyError, TypeError) as exc:
            raise PhysicsError(f"Not a Series dictionary (keys 'blocks' with 'name' and 'settings', "
                               f"and 'dt'): {exc!r}. Known blocks: {', '.join(BLOCKS)}.") from None
        if "parameters" in state:
            model.set_params(**state["parameters"])
        elif "params" in state:
            model.params = np.asarray(state["params"], dtype=float)
        return model

    def __repr__(self) -> str:
        return f"Series({', '.join(map(repr, self.blocks))}, dt={self.dt})"


def _pair(warmup) -> tuple[np.ndarray, np.ndarray]:
    """A warm-up window ``(u_w, y_w)`` in the forward model's roles (a Trajectory: its input and output)."""
    from .data import Trajectory

    if isinstance(warmup, Trajectory):
        return np.asarray(warmup.u, dtype=float), np.asarray(warmup.y, dtype=float)
    try:
        u_w, y_w = warmup
    except (TypeError, ValueError):
        raise PhysicsError("warmup must be a pair (u_w, y_w) of the measured input and output just before "
                           f"the prediction; got {type(warmup).__name__}.") from None
    return np.asarray(u_w, dtype=float), np.asarray(y_w, dtype=float)


def _bisect(f, below: float, above: float, steps: int = 100) -> float:
    """A root of ``f`` between ``below`` (where ``f < 0``) and ``above`` (``f >= 0``), by ``steps`` halvings;
    the end on ``above``'s side."""
    for _ in range(steps):
        mid = 0.5 * (below + above)
        below, above = (mid, above) if f(mid) < 0 else (below, mid)
    return above


def _check_bounds(bounds) -> tuple[float, float]:
    """``(lo, hi)`` of an inverse's input bounds (``(-inf, inf)`` for None), checked."""
    if bounds is None:
        return -np.inf, np.inf
    try:
        lo, hi = (float(b) for b in bounds)
    except (TypeError, ValueError):
        raise PhysicsError(f"bounds must be a pair (lo, hi) of numbers; got {bounds!r}.") from None
    if np.isnan(lo) or np.isnan(hi) or not lo < hi:
        raise PhysicsError(f"bounds must be (lo, hi) with lo < hi; got ({lo}, {hi}).")
    return lo, hi
