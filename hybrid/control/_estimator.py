"""Measured feedback: a moving-horizon estimate of a model's state and of a slow output offset.

A catheter's tip is seen now and then (imaging, a tracker), not at every sample. Between
measurements the estimate is the model itself, stepped on the inputs applied; when one arrives,
the estimator refits, over the last ``window`` samples, the state at the window's start (its
physics states; a network's states follow the model) and a constant output offset::

    min_{dx, d}  sum_k m_k ((y_k(x_s + dx) + d - y_meas_k) / noise)^2
               + |dx / (state_std x_span)|^2 + ((d - d_prior) / (offset_std y_span))^2

where ``m_k`` is 1 on the measured samples of the window and 0 elsewhere (any subset: every
Nth, irregular, dropped), ``x_s`` the previous estimate of that state and ``d_prior`` the last
offset: a random walk, so the offset follows a slow drift. A model of several outputs (the tip's
angle and position) has one offset per output, each in its own span, and ``m_k`` per output: any
subset of them may be measured at a sample (a camera that sees the position, not the angle), and
the one state they share is fitted on those that were. For a hybrid, ``y_k`` in the fit is
its physics (the export's ``approximation``) plus the network's share of the output at the
prior, so an update costs two rollouts of the full model, not one per unknown and iteration. The problem is solved by a fixed
number of Gauss-Newton iterations (the same work on every update, whatever the data), written
once as a pure CasADi function over the model's exported ``step`` (:attr:`function`): compiled
with gcc where it is there, saved beside ``step`` and ``init``, and generated as C like them.
"""

from __future__ import annotations

import re
from pathlib import Path

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike, NDArray

from hybrid.export._codegen import has_compiler
from physics.data.io import atomic_path
from hybrid.export._model import ExportedModel, ExportError

from ._adjoint_sqp import _compiled
from ._scaling import Scaling

__all__ = ["MovingHorizonEstimator", "estimated_states", "measurement_mask"]

#: Default Gauss-Newton iterations per update: enough for the model's nonlinearity over a window
#: (the first one does most of the work from a good prior), a fixed cost per update.
ITERATIONS = 3


def estimated_states(model: ExportedModel) -> list[int]:
    """Indices of the states the estimator fits: the physics blocks' states (``"lag.position"``,
    a hybrid's ``"physics.backlash.position"``), not a block's copy of its last input
    (``"*.u_prev"``, which the applied input sets) nor a network's states, which follow the model
    (an LSTM's 128 are not observable from a few angles)."""
    from physics import BLOCKS

    out = []
    for i, name in enumerate(model.state_names):
        name = name.removeprefix("physics.")
        block = re.sub(r"\d+$", "", name.split(".")[0])
        if "." in name and block in BLOCKS and not name.endswith("u_prev"):
            out.append(i)
    return out


def measurement_mask(n: int, measure_every: int | None = None, at: ArrayLike | None = None) -> NDArray[np.bool_]:
    """Which of ``n`` samples are measured: every ``measure_every``-th from the first, or the
    sample indices ``at`` (irregular); both None: none."""
    mask = np.zeros(int(n), dtype=bool)
    if measure_every is not None:
        if isinstance(measure_every, bool) or int(measure_every) != measure_every or measure_every < 1:
            raise ExportError(f"measure_every must be a whole number of samples >= 1. Got {measure_every!r}.")
        mask[::int(measure_every)] = True
    if at is not None:
        idx = np.asarray(at, dtype=int).ravel()
        if idx.size and (idx.min() < 0 or idx.max() >= n):
            raise ExportError(f"Measured sample indices must lie in [0, {n - 1}]; got {idx.min()}..{idx.max()}.")
        mask[idx] = True
    return mask


class MovingHorizonEstimator:
    """State and output offset of an exported model from measurements on any subset of samples.

    Parameters
    ----------
    model : ExportedModel
        The model whose state is estimated (``export_model(fitted)``).
    window : int
        Samples the fit looks back over (50: 2 s at 25 Hz); at least 1.
    iterations : int
        Gauss-Newton iterations per measurement (fixed: the same cost on every update).
    noise_std : float, sequence of float or None
        Standard deviation of the measurement noise, in output units (one per output of a model
        of several, or one for all); default 1 % of each output's span over the input range.
    state_std : float
        Prior standard deviation of the fitted states at the window's start, as a share of each
        state's span: how far a window of measurements may move them.
    offset_std : float
        Standard deviation of the output offset's change between two updates, as a share of
        the output span: how fast it may drift.
    u_bounds : (float, float) or None
        Input range the scales are measured on; default the model's ``input_range``.
    compile : bool or None
        Compile the update with gcc (default: when gcc is on the PATH).

    Attributes
    ----------
    x_ : ndarray
        The state estimate before the next sample (after the last one given to :meth:`update`).
    offset_ : float or ndarray
        The output offset estimate, in output units (one per output of a model of several).
    function : casadi.Function
        ``mhe(x_start, d, U, Y, mask) -> (x_start_new, d_new, x_now)``: the update over a window
        (``U``: n_u x window, ``Y``, ``mask``: n_y x window, ``d``: n_y), pure and code-generable.

    Examples
    --------
    >>> import numpy as np
    >>> from physics import Series
    >>> from hybrid.export import export_model
    >>> from hybrid.control import MovingHorizonEstimator
    >>> model = export_model(Series.from_spec("lag+linear"))
    >>> mhe = MovingHorizonEstimator(model, window=20, u_bounds=(0.0, 6.0), compile=False)
    >>> u = np.full(60, 3.0)
    >>> y = model.simulate(u) + 5.0                        # the plant reads 5 units higher
    >>> y_hat = mhe.filter(u, y, measure_every=10)
    >>> bool(abs(y_hat[-1] - y[-1]) < 0.1)
    True
    """

    def __init__(self, model: ExportedModel, window: int = 50, iterations: int = ITERATIONS,
                 noise_std: float | None = None, state_std: float = 0.1, offset_std: float = 0.1,
                 u_bounds: tuple[float, float] | None = None, compile: bool | None = None):
        if not isinstance(model, ExportedModel):
            raise ExportError("MovingHorizonEstimator needs an ExportedModel: export_model(fitted_model).")
        for name, value, low in (("window", window, 1), ("iterations", iterations, 0)):
            if isinstance(value, bool) or int(value) != value or value < low:
                raise ExportError(f"{name} must be a whole number >= {low}. Got {value!r} instead.")
        for name, value in (("state_std", state_std), ("offset_std", offset_std)):
            if not (np.isfinite(value) and value > 0):
                raise ExportError(f"{name} must be a finite number > 0 (a share of the span). Got {value!r}.")
        u_bounds = u_bounds if u_bounds is not None else model.input_range
        if u_bounds is None:
            raise ExportError("This model does not record the input range it was fitted on; give the estimator's "
                              "scales as MovingHorizonEstimator(..., u_bounds=(low, high)) in input units.")
        self.model, self.window, self.iterations = model, int(window), int(iterations)
        lo, hi = (float(v) for v in u_bounds)
        self.scaling, self.y_spans = _scales(model, lo, hi)
        noise = _noise(noise_std, self.y_spans)
        self.noise_std = float(noise[0]) if model.n_y == 1 else noise
        self.state_std, self.offset_std = float(state_std), float(offset_std)
        self.states = estimated_states(model)
        self.function = self._build()
        self.compiled = has_compiler() if compile is None else bool(compile)
        self._update = _compiled([self.function])[0] if self.compiled else self.function
        self._fresh = True

    def _build(self) -> ca.Function:
        m, M, sc = self.model, self.window, self.scaling
        n_x, n_u, n_y, n_e = m.n_x, m.n_u, m.n_y, len(self.states)
        x_s, d0 = ca.MX.sym("x_start", n_x), ca.MX.sym("d", n_y)
        U, Y, mask = ca.MX.sym("U", n_u, M), ca.MX.sym("Y", n_y, M), ca.MX.sym("mask", n_y, M)
        E = ca.DM.zeros(n_x, n_e)  # fitted states, each in its own span
        for j, i in enumerate(self.states):
            E[i, j] = sc.x_span[i] * self.state_std
        v = ca.MX.sym("v", n_e + n_y)  # (dx, d - d0) over their prior standard deviations
        rollout = m.step.mapaccum("window", M)
        d_std = ca.DM(self.offset_std * self.y_spans)

        def unscaled(v):
            return (x_s + E @ v[:n_e] if n_e else x_s), d0 + v[n_e:] * d_std

        x, d = unscaled(v)
        shift = ca.MX.sym("shift", n_y, M)  # the full model's outputs less the fitted one's, at the prior
        if m.approximation is None:
            fitted, prior = rollout, ca.MX.zeros(n_y, M)
        else:  # a hybrid: the physics (its approximation) is fitted, the network's part held at the prior's
            fitted = m.approximation.mapaccum("window_physics", M)
            prior = rollout(x_s, U)[1] - fitted(x_s, U)[1]
        ys = fitted(x, U)[1] + shift
        noise = ca.repmat(ca.DM(self.noise_std), 1, M)
        r = ca.vertcat(ca.vec((ys + ca.repmat(d, 1, M) - Y) * mask / noise), v)
        residual = ca.Function("residual", [v, x_s, d0, U, Y, mask, shift], [r, ca.jacobian(r, v)])
        vk = ca.MX.zeros(n_e + n_y, 1)
        for _ in range(self.iterations):  # Gauss-Newton; the prior rows make J'J positive definite
            rk, jk = residual(vk, x_s, d0, U, Y, mask, prior)
            vk = vk - ca.solve(jk.T @ jk, jk.T @ rk)
        x, d = unscaled(vk)
        xs, _ = rollout(x, U)
        return ca.Function("mhe", [x_s, d0, U, Y, mask], [x, d, xs[:, M - 1]],
                           ["x_start", "d", "U", "Y", "mask"], ["x_start_new", "d_new", "x_now"])

    # -- running -------------------------------------------------------------
    def reset(self, x: ArrayLike | None = None, u0: float | ArrayLike | None = None,
              offset: float | ArrayLike = 0.0):
        """Start from state ``x`` (default: the model at rest at input ``u0``, default the middle of
        the input range) and output ``offset`` (one, or one per output) with no measurement yet;
        returns self."""
        lo, span = self.scaling.u_lo, self.scaling.u_span
        u0 = np.atleast_1d(np.asarray(lo + 0.5 * span if u0 is None else u0, dtype=float))
        u0 = np.r_[u0, np.zeros(self.model.n_u - u0.size)]
        x = self.model.x0(u0) if x is None else np.asarray(x, dtype=float).ravel()
        if x.size != self.model.n_x or not np.all(np.isfinite(x)):
            raise ExportError(f"The estimator's state must hold {self.model.n_x} finite values; got {x.size}.")
        # the window before the first sample: the model held at rest (so x is also its start), unmeasured
        n_y = self.model.n_y
        offset = np.asarray(offset, dtype=float).ravel()
        if offset.size not in (1, n_y) or not np.all(np.isfinite(offset)):
            raise ExportError(f"The offset must be one finite number or {n_y} (one per output); got {offset}.")
        self._U = np.repeat(u0[:, None], self.window, axis=1)
        self._Y, self._mask = np.zeros((n_y, self.window)), np.zeros((n_y, self.window))
        self._x_start, self.x_ = x.copy(), x.copy()
        self.offset_ = float(offset[0]) if n_y == 1 else np.broadcast_to(offset, (n_y,)).copy()
        self._fresh = False
        return self

    def predict(self, u: float | ArrayLike) -> float | NDArray[np.float64]:
        """The output at the next sample under input ``u``, from the estimate (offset included): a float,
        or one value per output of a model of several."""
        if self._fresh:
            self.reset(u0=u)
        y = np.asarray(self.model.step(self.x_, u)[1], dtype=float).ravel() + self.offset_
        return float(y[0]) if self.model.n_y == 1 else y

    def update(self, u: float | ArrayLike, y: float | ArrayLike | None = None) -> float | NDArray[np.float64]:
        """Advance by one sample with input ``u`` applied and output ``y`` measured at it (None or
        NaN: not measured; a model of several outputs takes one value per output, NaN where that
        output was not measured); returns the output predicted for that sample *before* ``y`` was seen."""
        y_hat = self.predict(u)
        u = np.atleast_1d(np.asarray(u, dtype=float))
        if u.size != self.model.n_u or not np.all(np.isfinite(u)):
            raise ExportError(f"The input must hold {self.model.n_u} finite value(s) per sample; got {u}.")
        seen = self._seen(y)
        measured = bool(seen.any())
        x_first, _ = self.model.step(self._x_start, self._U[:, 0])  # the window slides by one sample
        self._x_start = np.asarray(x_first, dtype=float).ravel()
        self._U = np.hstack([self._U[:, 1:], u[:, None]])
        self._Y = np.hstack([self._Y[:, 1:], np.where(seen, y if measured else 0.0, 0.0)[:, None]])
        self._mask = np.hstack([self._mask[:, 1:], seen.astype(float)[:, None]])
        if measured:
            x_start, d, x_now = self._update(self._x_start, self.offset_, self._U, self._Y, self._mask)
            self._x_start = np.asarray(x_start, dtype=float).ravel()
            d = np.asarray(d, dtype=float).ravel()
            self.offset_ = float(d[0]) if self.model.n_y == 1 else d
            self.x_ = np.asarray(x_now, dtype=float).ravel()
        else:
            self.x_ = np.asarray(self.model.step(self.x_, u)[0], dtype=float).ravel()
        return y_hat

    def _seen(self, y) -> NDArray[np.bool_]:
        """Which outputs ``y`` (one sample's measurement, None: none) holds a finite value for."""
        n_y = self.model.n_y
        if y is None:
            return np.zeros(n_y, dtype=bool)
        y = np.asarray(y, dtype=float).ravel()
        if y.size != n_y:
            raise ExportError(f"A measurement holds one value per output of the model ({n_y}); got {y.size}. Use NaN "
                              "for an output that was not measured at that sample.")
        return np.isfinite(y)

    def filter(self, u: ArrayLike, y: ArrayLike, measure_every: int | None = None, at: ArrayLike | None = None,
               x0: ArrayLike | None = None) -> NDArray[np.float64]:
        """The prediction of every sample of a run from the measurements before it.

        ``u`` (n or n x n_u) are the inputs applied, ``y`` the outputs (n, or n x n_y for a model of
        several); only the samples picked by ``measure_every`` / ``at`` (:func:`measurement_mask`) or,
        with both None, the finite ones are given to the estimator. A model of several outputs is
        given, at those samples, the outputs that are finite there: a column of NaN is an output
        never measured. Sample ``k``'s prediction uses the measurements before ``k``.
        """
        n_y = self.model.n_y
        u = np.asarray(u, dtype=float)
        u = u.reshape(-1, 1) if u.ndim == 1 else u
        y = np.asarray(y, dtype=float)
        y = y.ravel() if n_y == 1 else y
        if y.shape[0] != u.shape[0] or (n_y > 1 and y.shape != (u.shape[0], n_y)):
            want = "one output" if n_y == 1 else f"an (n, {n_y}) array: one column per output"
            raise ExportError(f"u has {u.shape[0]} samples but y has shape {y.shape}; give {want} per input sample.")
        if not np.all(np.isfinite(u)):
            raise ExportError("The inputs hold non-finite values; every sample's applied input must be known.")
        finite = np.isfinite(y) if n_y == 1 else np.isfinite(y).any(axis=1)
        if measure_every is None and at is None:
            mask = finite
        else:
            mask = measurement_mask(u.shape[0], measure_every, at)
            if not np.all(finite[mask]):
                raise ExportError("Some measured samples of y are not finite; drop them from 'at' or use NaN for "
                                  "the unmeasured samples without measure_every/at.")
        self.reset(x=x0, u0=u[0])
        return np.array([self.update(u[k], y[k] if mask[k] else None) for k in range(u.shape[0])])

    def save(self, path) -> Path:
        """Write :attr:`function` (CasADi's serialised form) to ``path``; load with
        ``casadi.Function.load``."""
        path = Path(path)
        with atomic_path(path) as tmp:
            self.function.save(str(tmp))
        return path


def _scales(model: ExportedModel, lo: float, hi: float) -> tuple[Scaling, NDArray[np.float64]]:
    """The states' scales (:class:`Scaling`, measured on the first output's step) and each output's span,
    on a sweep across ``[lo, hi]`` widened to the model at rest at each end."""
    n_d = model.n_u - 1
    views = [model] if model.n_y == 1 else [model.output(j) for j in range(model.n_y)]
    spans, first = [], None
    for view in views:
        rest = tuple((view.x0(np.r_[u, np.zeros(n_d)]), float(view.step(view.x0(np.r_[u, np.zeros(n_d)]),
                                                                        np.r_[u, np.zeros(n_d)])[1]))
                     for u in (lo, hi))
        scaling = Scaling.measure(view.step, rest[0][0], (lo, hi), n_d, rest)
        first = scaling if first is None else first
        spans.append(scaling.y_span)
    return first, np.asarray(spans, dtype=float)


def _noise(noise_std, spans: NDArray[np.float64]) -> NDArray[np.float64]:
    """``noise_std`` as one positive standard deviation per output (default: 1 % of each one's span)."""
    if noise_std is None:
        return 0.01 * spans
    noise = np.asarray(noise_std, dtype=float).ravel()
    if noise.size not in (1, spans.size) or not np.all(np.isfinite(noise) & (noise > 0)):
        raise ExportError(f"noise_std must be a finite number > 0 in output units (or one per output, {spans.size}). "
                          f"Got {noise_std!r}.")
    return np.broadcast_to(noise, spans.shape).astype(float)
