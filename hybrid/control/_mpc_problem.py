"""The tracking problem a solver is built on: the settings resolved on the model, in its own scales."""

from __future__ import annotations

import functools
from dataclasses import dataclass, field, replace

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike

from ._mpc_settings import MPCSettings, check_du_max, check_u_bounds
from ._scaling import Scaling
from ._static import rest_output
from hybrid.export._model import ExportedModel, ExportError

__all__ = ["MPCProblem", "COST_SCALE", "choose_solver"]

#: The scaled cost is multiplied by this (the optimum does not change): an error of 3 % of the
#: output span costs about 1, about as 2 deg do on the catheter in its own units, where the solvers'
#: absolute tolerances and IPOPT's barrier were set. 1 leaves sqpmethod's steps too small to meet
#: them, 1e4 its dual tolerance too tight (measured on a sine and on out-of-reach references).
COST_SCALE = 1e3


@dataclass(frozen=True, eq=False)
class MPCProblem:
    """The tracking problem a solver is built on: the model's step, the settings resolved on it
    (:meth:`build`) and the problem in the model's own scales (:class:`Scaling`), on which the
    solvers work: ``step_n`` is the step on scaled state, command and output."""

    step: ca.Function
    model: ExportedModel | None
    settings: MPCSettings
    scale: Scaling
    step_n: ca.Function
    #: With ``y_bounds`` on another output than the tracked one (``settings.bound``): that output's view of the model
    #: (:meth:`ExportedModel.output`), its scale, and its step on the scaled problem; else None.
    bounded: ExportedModel | None = None
    bound_scale: Scaling | None = None
    bound_n: ca.Function | None = None
    _rest: dict = field(default_factory=dict, repr=False)

    @classmethod
    def build(cls, step, settings: MPCSettings) -> "MPCProblem":
        """``settings`` resolved on ``step`` (a ``casadi.Function`` or an :class:`ExportedModel`): the
        input bounds, rate limit, input reference and solver their defaults give, checked against
        the model."""
        model = step if isinstance(step, ExportedModel) else None
        model, bounded = _views(model, settings)
        step = model.step if model is not None else step
        _check_step(step)
        n_x, n_d = int(step.size1_in(0)), int(step.numel_in(1)) - 1  # measured disturbances beside the command
        if settings.tighten:  # the bounded output's interval: the tracked one's, or another's (ExportedModel.output)
            _check_interval(model if bounded is None else bounded)
        u_bounds = settings.u_bounds
        if u_bounds is None:
            u_bounds = model.input_range if model is not None else None
            if u_bounds is None:
                raise ExportError("This model does not record the input range it was fitted on; give the MPC's "
                                  "input limits in its input units: TrackingMPC(..., u_bounds=(low, high)).")
            u_bounds = check_u_bounds(u_bounds)
        lo, hi = u_bounds
        du_max = settings.du_max
        if du_max is None:
            du_max = check_du_max(min((hi - lo) / 12, model.meta.get("max_input_step", np.inf) if model else np.inf))
        solver = settings.solver if settings.solver != "auto" else choose_solver(model, n_d, settings.y_bounds)
        settings = replace(settings, u_bounds=(lo, hi), du_max=float(du_max), solver=solver,
                           u_ref=0.5 * (lo + hi) if settings.u_ref is None else settings.u_ref)
        rest = ()
        if model is not None:  # at rest at each bound: the static span, at any rate
            rest = tuple((model.x0(u0), rest_output(model, u0)) for u0 in (np.r_[u, np.zeros(n_d)] for u in (lo, hi)))
        x0 = rest[0][0] if rest else np.zeros(n_x)
        scale = Scaling.measure(step, x0, (lo, hi), n_d, rest)
        if bounded is None:
            return cls(step, model, settings, scale, scale.wrap(step))
        rest_b = tuple((x, rest_output(bounded, u0)) for (x, _), u0 in
                       zip(rest, (np.r_[u, np.zeros(n_d)] for u in (lo, hi))))
        bound_scale = Scaling.measure(bounded.step, x0, (lo, hi), n_d, rest_b)
        return cls(step, model, settings, scale, scale.wrap(step), bounded, bound_scale,
                   bound_scale.wrap(bounded.step))

    @property
    def horizon(self) -> int:
        return self.settings.horizon

    @property
    def n_x(self) -> int:
        return int(self.step.size1_in(0))

    @property
    def n_d(self) -> int:
        """Measured inputs the step reads besides the command."""
        return int(self.step.numel_in(1)) - 1

    @property
    def scaled(self) -> tuple[float, float, float, float, float]:
        """``(w_track, w_du, w_u, u_ref, du_max)`` of the scaled problem (weights times :data:`COST_SCALE`)."""
        s, sc, k = self.settings, self.scale, COST_SCALE
        return k * s.w_track, k * s.w_du, k * s.w_u, float(sc.u(s.u_ref)), s.du_max / sc.u_span

    def approximation_n(self) -> ca.Function:
        """The model's ``approximation`` (a hybrid's physics) on the scaled problem; else the model itself."""
        return _approximation(self.model, self.scale, self.step_n)

    def bound_views(self) -> tuple[ca.Function, ca.Function, Scaling] | None:
        """With the bounds on another output than the tracked one (``settings.bound``): that output's step,
        its approximation (:meth:`approximation_n`) and its scale; None where the tracked output is bounded."""
        if self.bounded is None:
            return None
        return self.bound_n, _approximation(self.bounded, self.bound_scale, self.bound_n), self.bound_scale

    @property
    def y_scale(self) -> Scaling:
        """The scale of the output ``y_bounds`` limit (the tracked one's unless ``settings.bound`` names another)."""
        return self.scale if self.bound_scale is None else self.bound_scale

    def cost_function(self) -> ca.Function:
        """The objective of a scaled input path by rollout, ``cost(x0, U, ref, u_prev, d)``, all scaled."""
        N = self.horizon
        x0, U, ref, u_prev = ca.MX.sym("x0", self.n_x), ca.MX.sym("U", 1, N), ca.MX.sym("ref", N), ca.MX.sym("u_prev")
        D = ca.MX.sym("d", self.n_d, N)
        w_track, w_du, w_u, u_ref, _ = self.scaled
        _, y = self.step_n.mapaccum("cost", N)(x0, ca.vertcat(U, D))
        du = U - ca.horzcat(u_prev, U[:, :N - 1])
        f = w_track * ca.sumsqr(y.T - ref) + w_du * ca.sumsqr(du) + w_u * ca.sumsqr(U - u_ref)
        return ca.Function("mpc_cost", [x0, U, ref, u_prev, D], [f])

    def half_widths(self, x: np.ndarray, U: np.ndarray, u_prev: float, D: np.ndarray) -> np.ndarray:
        """The bounded output's interval half-widths (its view's ``half_width``: the tracked output's, or another's
        where ``settings.bound`` names it) along the inputs ``U`` and the outputs they lead to from ``x``, over the
        horizon; all scaled, the half-widths in :attr:`y_scale` (``D`` as the scaled step takes it)."""
        N, sc, ys = self.horizon, self.scale, self.y_scale
        rollout, half_width = self._backoff
        _, y = rollout(x, np.vstack([U[None, :], D]))
        u = sc.u_back(U)
        h, _ = half_width(u[None, :], np.r_[sc.u_back(u_prev), u[:-1]][None, :],
                          ys.y_back(np.asarray(y, dtype=float))[None, :].reshape(1, N))
        return np.asarray(h, dtype=float).ravel() / ys.y_span

    @functools.cached_property
    def _backoff(self) -> tuple[ca.Function, ca.Function]:
        """The bounded output's scaled step rolled over the horizon and its half-width mapped over it: built once,
        read by every control step that tightens its bounds."""
        step_n, model = (self.step_n, self.model) if self.bounded is None else (self.bound_n, self.bounded)
        return step_n.mapaccum("backoff", self.horizon), model.half_width.map(self.horizon)

    def state(self, x: ArrayLike) -> np.ndarray:
        """``x`` checked: the step's state, finite."""
        x = np.asarray(x, dtype=float).ravel()
        if x.size != self.n_x:
            raise ExportError(f"The state must have {self.n_x} entries; got {x.size}.")
        if not np.all(np.isfinite(x)):
            raise ExportError(f"The state has non-finite entries at {np.flatnonzero(~np.isfinite(x)).tolist()}; "
                              "pass the model's state (e.g. model.x0(u)) advanced on the applied inputs.")
        return x

    def reference(self, window: ArrayLike) -> np.ndarray:
        """The reference over the horizon: ``window`` cut, or padded with its last value."""
        N = self.horizon
        ref = np.asarray(window, dtype=float).ravel()
        if ref.size == 0 or not np.all(np.isfinite(ref)):
            raise ExportError("The reference window must hold at least one finite value.")
        return np.r_[ref[:N], np.full(max(0, N - ref.size), ref[-1])]

    def measured(self, measured) -> np.ndarray:
        """The measured inputs over the horizon, ``n_d x horizon``."""
        N, n_d = self.horizon, self.n_d
        if n_d == 0:
            if measured is not None and np.size(measured):
                raise ExportError("This model reads no measured inputs besides the command; drop measured=.")
            return np.zeros((0, N))
        if measured is None:
            raise ExportError(f"This model also reads {n_d} measured input(s) (meta 'inputs' of the export); "
                              "give their values: solve(..., measured=[...]).")
        rows = np.atleast_2d(np.asarray(measured, dtype=float))
        if rows.shape[1] != n_d or not np.all(np.isfinite(rows)):
            raise ExportError(f"measured must hold {n_d} finite value(s) per sample; got shape {np.shape(measured)}.")
        rows = np.vstack([rows[:N], np.repeat(rows[-1:], max(0, N - rows.shape[0]), axis=0)])
        return rows.T

    def static_inputs(self, ref: np.ndarray, u_prev: float, d: np.ndarray) -> np.ndarray:
        """Inputs heading, within the rate limit, to those whose rest outputs are ``ref`` (physical units)."""
        key = tuple(np.round(d, 12))
        if self._rest.get("key") != key:
            u = np.linspace(*self.settings.u_bounds, 201)
            self._rest.update(key=key, u=u, y=np.array([rest_output(self.model, np.r_[v, d]) for v in u]))
        u_grid, y_grid, du_max = self._rest["u"], self._rest["y"], self.settings.du_max
        out, u = np.empty(self.horizon), u_prev
        for k, r in enumerate(ref):
            target = u_grid[int(np.argmin(np.abs(y_grid - r)))]
            u = float(np.clip(target, u - du_max, u + du_max))
            out[k] = u
        return out


def _approximation(model: ExportedModel | None, scale: Scaling, step_n: ca.Function) -> ca.Function:
    approx = model.approximation if model is not None else None
    if approx is None:
        return step_n
    try:  # physics blocks: scalar code, and so are the Jacobians the solvers take of it
        approx = approx.expand()
    except RuntimeError:  # a block with no SX form
        pass
    return scale.wrap(approx)


def _views(model: ExportedModel | None, settings: MPCSettings) -> tuple[ExportedModel | None, ExportedModel | None]:
    """``(tracked, bounded)``: a model of several outputs seen through the output ``settings.track`` names and,
    where ``settings.bound`` names another, through that one (None: the tracked output is the bounded one)."""
    n_y = 1 if model is None else model.n_y
    track, bound = settings.track, settings.bound
    for name, index in (("track", track), ("bound", bound)):
        if index is not None and index >= n_y:
            raise ExportError(f"{name}={index} is not an output of this model: it has {n_y} (indices 0..{n_y - 1}).")
    if n_y == 1:
        return model, None
    if track is None:
        raise ExportError(f"This model has {n_y} outputs; name the one to track: MPCSettings(track=j) (and "
                          "y_bounds={k: (low, high)} for bounds on another).")
    bounded = model.output(bound) if bound is not None and bound != track else None
    return model.output(track), bounded


def choose_solver(model: ExportedModel | None, n_d: int, y_bounds) -> str:
    """What ``solver="auto"`` means: IPOPT with output bounds (they live in the full NLP, and sqp
    with qrqp stalls on a backlash's kinks), the adjoint SQP for a model with an approximation and
    one input, else sqp."""
    if y_bounds is not None:
        return "ipopt"
    approx = model is not None and model.approximation is not None
    return "adjoint-sqp" if approx and not n_d else "sqp"


def _check_step(step) -> None:
    if not isinstance(step, ca.Function) or step.n_in() != 2 or step.n_out() != 2:
        raise ExportError("The MPC needs a step Function (x, u) -> (x_next, y), e.g. export_model(model).step.")
    if step.numel_in(1) < 1 or step.numel_out(1) != 1:
        raise ExportError(f"The MPC handles a command (plus measured inputs) and one output; the step has {step.numel_in(1)} "
                          f"input(s) and {step.numel_out(1)} output(s).")


def _check_interval(model) -> None:
    """``tighten`` needs a model that carries its interval (``ExportedModel.half_width``) and reads one input."""
    if getattr(model, "half_width", None) is None:
        raise ExportError("tighten=True needs a model that carries its prediction interval (ExportedModel.half_width: "
                          "the step.casadi of a model folder from `hyst fit`, or set it from "
                          "ConformalIntervals.function()).")
    if int(model.step.numel_in(1)) != 1:
        raise ExportError("tighten=True works for a model with one input; this one also reads measured inputs.")
