"""The state of a model from measured samples: a warm-up window instead of a rest state.

A free run from the blocks' rest state at the first input carries whatever the robot's real
start was not (a catheter relaxed at the start of a run, a play resting at one edge of its band,
a lag still settling). Given ``K`` measured samples ``(u_w, y_w)`` before a prediction, the state
*before* the window is estimated by a regularised least-squares fit over the window,

    min_x0,b  sum_k ((y_k(x0) + b - y_w,k) / s_y)^2 + rho * sum_i ((x0_i - xs_i) / s_x,i)^2 + rho_b (b / s_y)^2

with ``xs`` the rest state at ``u_w[0]`` (the prior: where the model would have started), ``s_x`` and
``s_y`` the states' and the output's typical magnitudes (:meth:`Series.signal_scales`) and ``b`` an
optional output offset. The fit is Levenberg-Marquardt with a fixed number of iterations and the
step accepted only where it lowers the cost, written as one CasADi function over the model's own
rollout and its Jacobian: the same function gives Python's estimate and the export's ``init``.
The model's state after the window (where a prediction starts) is the estimate rolled through it.
"""

from __future__ import annotations

from typing import NamedTuple

import casadi as ca
import numpy as np

from ._cache import built
from ._errors import PhysicsError

__all__ = ["WarmState", "WARMUP_ITERATIONS", "PRIOR_WEIGHT", "OFFSET_PRIOR_WEIGHT", "init_function", "scales", "estimate"]

#: Levenberg-Marquardt iterations of the window fit (fixed: the same work every call).
WARMUP_ITERATIONS = 12
#: Weight of the states' rest-state prior against the window's output error (both scaled): a
#: state the window does not show stays at rest; one it shows moves freely.
PRIOR_WEIGHT = 1e-4
#: Weight of the output offset's zero prior (an offset of 10 % of the output's scale costs
#: about what a 1 % error on every sample of a 10-sample window does).
OFFSET_PRIOR_WEIGHT = 1e-3

_FUNCTIONS: dict[tuple, ca.Function] = {}


class WarmState(NamedTuple):
    """A model's state estimated from a warm-up window: ``x`` after the window (where the prediction
    starts), ``x0`` before it, and the output ``offset`` (0 unless estimated)."""

    x: np.ndarray
    x0: np.ndarray
    offset: float


def init_function(series, n: int, offset: bool, expanded: bool = False, read: tuple[int, ...] | None = None
                  ) -> ca.Function:
    """``Function('init', [u_w, y_w, p, s_x, s_y], [x, x0, offset])``: the window fit of ``series``
    over ``n`` samples (``u_w``, ``y_w``: 1 x n), given the states' scales ``s_x`` and the output's
    ``s_y`` (:func:`scales`). Cached per structure, length, offset, ``expanded`` and ``read`` (building
    costs several calls).

    ``read``: a model of several outputs fitted on the outputs of these indices (``y_w``: len(read) x n,
    ``s_y`` one scale each; no offset): the one state they share, from whichever of them were measured.

    ``expanded``: the window's residuals as scalar operations (``Function.expand``), for a fit that
    differentiates the state with respect to the parameters (``identify(warmup=)``): its Jacobian in
    a third of the time, and values in half, equal to the last bits or nearly (a creep's differ by
    1e-12 of themselves). Predictions, scores and the export use the function as written."""
    if n < 1:
        raise PhysicsError(f"A warm-up window needs at least one sample; got {n}.")
    if read is not None:
        read = tuple(int(j) for j in read)
        if offset or not read or not all(0 <= j < series.n_y for j in read):
            raise PhysicsError(f"A window fit reads outputs among 0..{series.n_y - 1}, at least one, with no offset; "
                               f"got read={read}, offset={offset}.")
    elif series.n_y != 1:
        raise PhysicsError(f"'{series.spec}' has {series.n_y} outputs: name the ones the window measures (read=).")
    return built(_FUNCTIONS, (series._structure(), int(n), bool(offset), bool(expanded), read), 64,
                 lambda: _build(series, int(n), bool(offset), bool(expanded), read))


def _build(series, n: int, offset: bool, expanded: bool = False, read: tuple[int, ...] | None = None
           ) -> ca.Function:
    n_x, n_p = series.n_x, series.n_p
    # a block's copy of its last input (``u_prev``, for the input's ramp inside a step) is the input
    # before the window: at rest there, it stays at the prior (a free one buys a spurious first step)
    free = [i for i, name in enumerate(series.state_names) if not name.endswith("u_prev")]
    n_v = len(free) + int(offset)
    select = ca.DM.zeros(n_x, len(free))
    for j, i in enumerate(free):
        select[i, j] = 1
    n_r = 1 if read is None else len(read)
    u, y, p = ca.MX.sym("u_w", 1, n), ca.MX.sym("y_w", n_r, n), ca.MX.sym("p", n_p)
    s_x, s_y = ca.MX.sym("s_x", n_x), ca.MX.sym("s_y", n_r)
    weight = np.concatenate([np.full(len(free), PRIOR_WEIGHT), [OFFSET_PRIOR_WEIGHT] if offset else []])
    rollout = series.rollout(n)
    xs = series.steady_state_expr(u[0, 0], p)[0] if n_x else ca.MX.zeros(0, 1)

    def unscaled(v):  # the unknowns are scaled, (x0 - xs) / s_x and b / s_y: the fit reads alike in any units
        x0 = xs + (select @ v[:len(free)]) * s_x if n_x else ca.MX.zeros(0, 1)
        return x0, (v[len(free)] * s_y if offset else ca.MX(0))

    v = ca.MX.sym("v", n_v)
    x0, b = unscaled(v)
    ys = rollout(x0, u, p)[1]
    if read is None:
        r = ca.vertcat((ys.T + b - y.T) / s_y, np.sqrt(weight) * v)  # the cost's residuals
    else:  # each output measured over its own scale
        rows = ca.vertcat(*[ys[j, :] for j in read])
        r = ca.vertcat(ca.vec((rows - y) / ca.repmat(s_y, 1, n)), np.sqrt(weight) * v)
    residual = ca.Function("residual", [v, u, y, p, s_x, s_y], [r, ca.jacobian(r, v)])
    if expanded:
        try:
            residual = residual.expand()
        except RuntimeError:  # a block whose step is not scalar operations
            pass

    vk, mu = ca.MX.zeros(n_v, 1), ca.MX(1e-3)
    rk, jk = residual(vk, u, y, p, s_x, s_y)
    for _ in range(WARMUP_ITERATIONS):
        grad, hess = jk.T @ rk, jk.T @ jk
        step = -ca.solve(hess + mu * (ca.diag(ca.diag(hess)) + 1e-9 * ca.MX.eye(n_v)), grad)
        r_new, j_new = residual(vk + step, u, y, p, s_x, s_y)
        better = ca.sumsqr(r_new) < ca.sumsqr(rk)
        vk = ca.if_else(better, vk + step, vk)
        rk, jk = ca.if_else(better, r_new, rk), ca.if_else(better, j_new, jk)
        mu = ca.if_else(better, mu / 3, mu * 4)
    x0k, bk = unscaled(vk)
    x_end = rollout(x0k, u, p)[0][:, n - 1] if n_x else ca.MX.zeros(0, 1)
    return ca.Function("init", [u, y, p, s_x, s_y], [x_end, x0k, bk],
                       ["u_w", "y_w", "p", "s_x", "s_y"], ["x", "x0", "offset"])


def scales(series, u_w: np.ndarray, y_w: np.ndarray, p) -> tuple[np.ndarray, float]:
    """``(s_x, s_y)``: the states' typical sizes and the output's. The input's scale is the width of the
    range the model was fitted on (else the window's), the output's the model's rest outputs across
    it (else the window's spread)."""
    if series.input_range is not None and series.input_range[1] > series.input_range[0]:
        lo, hi = series.input_range
    else:
        mid, half = float(np.mean(u_w)), max(float(np.ptp(u_w)), 1e-3 * max(abs(float(np.mean(u_w))), 1.0))
        lo, hi = mid - half, mid + half
    s_u = hi - lo
    s_y = abs(series._steady(hi, p)[1] - series._steady(lo, p)[1])
    if not (np.isfinite(s_y) and s_y > 0):
        s_y = max(float(np.ptp(y_w)), float(np.std(y_w)), 1e-12 * max(abs(float(np.mean(y_w))), 1.0))
    s_x = series.signal_scales(s_u, s_y)[1]
    return np.where(np.isfinite(s_x) & (s_x > 0), s_x, 1.0), float(s_y)


def estimate(series, u_w, y_w, p=None, offset: bool = False) -> WarmState:
    """The state of ``series`` from the measured window ``(u_w, y_w)`` (see the module's text)."""
    u_w, y_w = series._check_path(u_w, "warm-up input"), series._check_path(y_w, "warm-up output")
    if u_w.size != y_w.size:
        raise PhysicsError(f"The warm-up input has {u_w.size} samples and its output {y_w.size}; "
                           "give both over the same samples.")
    p = series.params if p is None else np.asarray(p, dtype=float)
    s_x, s_y = scales(series, u_w, y_w, p)
    x, x0, b = init_function(series, u_w.size, offset)(u_w[None, :], y_w[None, :], p, s_x, s_y)
    x, x0 = np.asarray(x, dtype=float).ravel(), np.asarray(x0, dtype=float).ravel()
    if not (np.all(np.isfinite(x)) and np.isfinite(float(b))):
        raise PhysicsError(f"The warm-up fit of '{series.spec}' gave a non-finite state; check that the "
                           "window's input lies where the model was fitted.")
    return WarmState(x, x0, float(b))
