"""Physics plus a residual network: ``y = y_physics + r``, forward (u -> y) or inverse (y -> u)."""

from __future__ import annotations

import os
from collections.abc import Iterable, Sequence
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike, NDArray

from hybrid.learning._learned import DIRECTIONS, LearnedModel, _as_trajectories
from hybrid.learning._settings import DEFAULT_TRAINING, TrainingSettings, check_training
from hybrid.networks import AbstractNetwork, LSTMNet, make_network
from identification import PhysicsPolicy, fit_physics, output_columns
from physics import Series
from physics.data import BaseEstimator, DataError, NotFittedError, Trajectory, as_warmup

from ._domain import ResidualDomain, check_scale
from ._hybrid_io import load_hybrid, save_hybrid
from ._hybrid_tune import FineTuneSettings, fine_tune

__all__ = ["HybridModel", "resolve_network"]

#: Feature names every hybrid knows: the model's own input and the physics output.
BUILTIN_FEATURES = ("u", "physics")
#: An inverse hybrid's physics inverse is limited to the training inputs' range widened by this
#: share of their span on each side (``input_bounds_``).
INVERSE_MARGIN = 0.2


def input_bounds(trajectories, margin: float = INVERSE_MARGIN) -> tuple[float, float]:
    """The training inputs' range widened by ``margin`` times its span on each side (any units)."""
    u = np.concatenate([np.asarray(t.u, dtype=float) for t in trajectories])
    lo, hi, span = float(u.min()), float(u.max()), float(np.ptp(u))
    span = span or max(abs(lo), 1.0)
    return lo - margin * span, hi + margin * span


def inverse_form(series, trajectories, margin: float = INVERSE_MARGIN) -> tuple[tuple[float, float], bool]:
    """How to invert ``series`` for these runs: the input bounds (:func:`input_bounds`) and whether
    to pass its lags through (``quasi_static``), whichever reproduces the runs' inputs from their
    measured outputs better. A lag's exact inverse amplifies the outputs' noise by about its time
    constant over the sample time: at 200 Hz with 80 ms that made a 0-500 kPa muscle's physics
    inverse swing between its bounds; where the noise is small the exact inverse wins."""
    bounds = input_bounds(trajectories, margin)
    if not any(b.unit_static_gain for b in series.blocks):
        return bounds, False
    sq = {}
    for quasi_static in (False, True):
        e = np.concatenate([series.inverse(t.y, bounds=bounds, quasi_static=quasi_static) - t.u for t in trajectories])
        sq[quasi_static] = float(e @ e)
    return bounds, sq[True] < sq[False]


def resolve_network(network: AbstractNetwork | str | None, default: AbstractNetwork | None = None) -> AbstractNetwork:
    """A network spec from a spec object, a registry name ("fnn", "fnn-hib", "lstm") or None."""
    if network is None:
        return LSTMNet() if default is None else default
    if isinstance(network, str):
        return make_network(network)  # unknown names: "Must be one of [...]"
    if not isinstance(network, AbstractNetwork):
        from hybrid.networks import NETWORKS

        raise DataError(f"residual must be a network spec (an AbstractNetwork, e.g. LSTMNet()) or one of "
                        f"{list(NETWORKS)}; got {network!r}.")
    return network


class HybridModel(BaseEstimator):
    """A physics model plus a residual network that learns what the physics misses.

    Forward (``direction="forward"``): ``y = y_physics(u) + r``, the network
    predicting ``r = y - y_physics`` from the input history, the physics output
    and optionally the physics states. Inverse (``"inverse"``): the physics
    inverse (``Series.inverse``) gives ``u_physics(y)`` and the network learns
    ``u - u_physics``. Scaling, windows, training, prediction modes and
    sequential stepping are those of :class:`LearnedModel`, which holds the
    residual network (``residual_``).

    Parameters
    ----------
    physics : str, physics.Series or identification.FitResult
        A spec (``"backlash+boucwen+linear"``) is identified on the training data
        first (``identification.identify``); a Series or FitResult is used as
        given (already fitted). ``"auto"`` chooses the spec that extrapolates best
        to whole training runs left out of the fit
        (``identification.select_physics``, leave one run out; the choice and its
        cross-validated errors are in ``physics_selection_``).
    residual : AbstractNetwork or {"fnn", "fnn-hib", "lstm"}, default LSTMNet()
    direction : {"forward", "inverse"}
    features : tuple of str, default ("u", "physics")
        Columns fed to the network: ``"u"`` (the model's input: tendon
        displacement forward, tip angle inverse), ``"physics"`` (the physics
        output at the same sample) or names of ``Trajectory.extra`` columns.
    physics_states : bool, default False
        Also feed the physics model's internal states after each sample
        (actuator position, hysteresis state; not the stored previous inputs).
    residual_domain : float, optional
        Trust the residual only near the rows it was trained on
        (:class:`~hybrid.models.ResidualDomain`): the residual is weighted by
        ``exp(-(d / radius)^2)``, ``d`` the distance of the network's input row to
        the nearest training row (features scaled by their std), ``radius`` this
        value times the 99th percentile of that distance among the training rows.
        Off the training data the physics speaks alone. None (default): no weight.
    fine_tune : FineTuneSettings or None, default None
        After training the network on the frozen physics, train both jointly
        (forward only) with these settings (:class:`FineTuneSettings`: epochs,
        physics learning rate, residual penalty, segment length; ``FineTuneSettings()``
        for the defaults). None: no joint stage.
    identify_options : dict, optional
        Passed to ``identify`` when ``physics`` is a spec.
    training : TrainingSettings, default TrainingSettings()
        Training of the residual, as for :class:`LearnedModel` (``training__epochs`` etc. to
        scikit-learn).
    outputs : tuple of str, default ()
        A forward model of several outputs (the tip's angle and its position), each the trajectory's
        ``y`` (by ``output_name``) or an ``extra`` column: one physics chain whose output maps read one
        state (a Series with ``len(outputs)`` outputs, an :class:`identification.OutputsFit`, or a spec
        fitted by :func:`identification.identify_outputs` with ``identify_options``), and one residual
        network ending in one unit per output, fed every physics output. :meth:`predict` returns
        ``(n, len(outputs))``; a warm-up window sets the state from the output the physics' state is
        fitted on (:func:`identification._outputs.primary_view`). Empty: ``y`` alone.

    Attributes
    ----------
    physics_ : physics.Series
        The physics model in use (fine-tuned when ``fine_tune``).
    physics_fit_ : FitResult or None
    physics_failed_ : dict of str to str
        With a list of specs for ``physics``: the specs tried before the one in use that
        failed to fit, each with the reason (empty when the first fitted).
    physics_selection_ : identification.Selection or None
        With ``physics="auto"``: each candidate spec's held-out error and the choice.
    physics_report_ : identification.PhysicsReport
        How the physics in use was reached (:func:`identification.fit_physics`): the specs tried, why
        each failed, the selection.
    input_bounds_ : tuple of float or None
        Inverse only: the physics inverse's input is limited to the training inputs' range
        widened by :data:`INVERSE_MARGIN` of its span (``Series.inverse(bounds=...)``), so a
        wanted output the physics cannot reach, or noise a lag's inverse amplifies, asks for the
        nearest bound rather than an input far outside what the actuator was driven with.
    inverse_quasi_static_ : bool
        Inverse only: True when the physics inverse passes lags through (``Series.inverse(
        quasi_static=True)``) because that reproduces the training inputs better than inverting
        them (:func:`inverse_form`; the network then learns the lag from the data).
    domain_ : ResidualDomain or None
        With ``residual_domain``: the training rows and the radius.
    residual_ : LearnedModel
        The residual network, trained on trajectories whose output is the residual.
    feature_names_ : tuple of str
    fine_tune_loss_ : list of float

    Examples
    --------
    >>> from hybrid.virtual import paper_protocol
    >>> from hybrid.networks import FNNHIBNet
    >>> split = paper_protocol(frequencies=(0.3, 0.5), tests=(0.45,), baselines=("mid",))
    >>> from hybrid.learning import TrainingSettings
    >>> model = HybridModel("backlash+boucwen+linear", FNNHIBNet(buffer=10),
    ...                     training=TrainingSettings(epochs=2, progress=False))
    >>> model.fit(split.train).predict(split.test[0]).shape
    (389,)
    """

    def __init__(self, physics: Any = "backlash+boucwen+linear", residual: AbstractNetwork | str | None = None,
                 direction: str = "forward", *, features: Sequence[str] = BUILTIN_FEATURES,
                 physics_states: bool = False, residual_domain: float | None = None,
                 fine_tune: FineTuneSettings | None = None, identify_options: dict | None = None,
                 training: TrainingSettings = DEFAULT_TRAINING, outputs: Sequence[str] = ()):
        self.physics = physics
        self.residual = residual
        self.direction = direction
        self.features = features
        self.physics_states = physics_states
        self.residual_domain = residual_domain
        self.fine_tune = fine_tune
        self.identify_options = identify_options
        self.training = training
        self.outputs = outputs

    @property
    def network_(self) -> AbstractNetwork:
        return resolve_network(self.residual)

    @property
    def name(self) -> str:
        return f"{self.network_.name}+physics"

    @property
    def n_outputs_(self) -> int:
        """Outputs the model predicts: one per name in ``outputs``, else one."""
        return max(len(tuple(self.outputs)), 1)

    # ------------------------------------------------------------------ fit
    def fit(self, data: Trajectory | Iterable[Trajectory]) -> HybridModel:
        """Identify (or take) the physics, then train the residual; returns ``self``."""
        net = self._check_settings()
        trajs = _as_trajectories(data)
        if self.outputs:
            self.physics_, self.physics_fit_ = _physics_of_outputs(self.physics, trajs, tuple(self.outputs),
                                                                   self.identify_options)
            self.physics_report_, self.physics_failed_, self.physics_selection_ = None, {}, None
        else:
            self.physics_, self.physics_fit_, self.physics_report_ = fit_physics(
                PhysicsPolicy(self.physics, identify_options=self.identify_options), trajs)
            self.physics_failed_: dict[str, str] = self.physics_report_.failed
            self.physics_selection_ = self.physics_report_.selection
        self._check_physics(trajs[0].dt)
        self.input_bounds_, self.inverse_quasi_static_ = (inverse_form(self.physics_, trajs)
                                                          if self.direction == "inverse" else (None, False))
        self._fns = None
        self.state_names_ = tuple(n for n in self.physics_.state_names if not n.endswith("u_prev"))
        self.feature_names_ = tuple(self.features) + tuple(f"state:{n}" for n in self.state_names_
                                                           if self.physics_states)
        residuals = [self._residual_trajectory(t) for t in trajs]
        learned = LearnedModel(net, "forward", features=self._column_names()[1:], training=self.training,
                               outputs=self._residual_names())
        self.residual_ = learned.fit(residuals)
        self.fine_tune_loss_: list[float] = []
        if self.fine_tune is not None:
            with _threads(self.training.threads):
                self.fine_tune_loss_ = fine_tune(self, trajs)
            self._fns = None
        self.domain_ = None
        if self.residual_domain is not None:  # after fine-tuning: the rows of the physics in use
            rows = [self._columns(v, out, states, t.extra) for t, v, out, states in map(self._run_columns, trajs)]
            self.domain_ = ResidualDomain(self.residual_domain).fit(np.vstack(rows))
        return self

    # -------------------------------------------------------------- predict
    def predict(self, data: Trajectory | ArrayLike, mode: str | None = None, warmup=None) -> NDArray[np.float64]:
        """The whole output (forward: tip angle; inverse: tendon displacement) of a trajectory or input path:
        ``(n,)``, or ``(n, len(outputs))`` for a model of several outputs.

        ``warmup``, the measured samples just before ``data`` (a Trajectory, or ``(input, output)``
        arrays in the model's orientation: :func:`physics.data.as_warmup`), sets the state: the physics
        state is fitted to the window (``Series.estimate_state``), then physics and residual run over
        the window and on into ``data``. Without one, both start at rest at the first input.
        """
        out, residual = self._parts(data, mode, warmup)
        return out + residual

    def predict_physics(self, data: Trajectory | ArrayLike, warmup=None) -> NDArray[np.float64]:
        """The physics part alone (physics forward model or physics inverse), from the same state as
        :meth:`predict`."""
        self._check_fitted()
        window = as_warmup(warmup, inverse=self.direction == "inverse")
        if window is not None:
            v = self._model_input(window.joined(data))[0]
            return self._physics_run(v, self._warm_state(window))[0][window.n:]
        return self._physics_run(self._model_input(data)[0])[0]

    def _parts(self, data, mode, warmup=None):
        self._check_fitted()
        window = as_warmup(warmup, inverse=self.direction == "inverse")
        x0 = None
        if window is not None:
            x0, data = self._warm_state(window), window.joined(data)
        v, extra = self._model_input(data)
        out, states = self._physics_run(v, x0)
        cols = self._columns(v, out, states, extra)
        residual = self.residual_.predict(cols, mode=mode)
        if getattr(self, "domain_", None) is not None:
            weight = self.domain_.weight(cols)
            residual = residual * (weight if residual.ndim == 1 else weight[:, None])
        k = 0 if window is None else window.n
        return out[k:], residual[k:]

    def _warm_state(self, window) -> NDArray[np.float64]:
        """The physics state before the warm-up window, fitted to it in the forward model's roles (several
        outputs: to the output the state is fitted on, :func:`identification._outputs.primary_view`)."""
        v = self._model_input(window.data)[0]
        u_w, y_w = (v, window.w) if self.direction == "forward" else (window.w, v)
        if not self.outputs:
            return self.physics_.estimate_state(u_w, y_w).x0
        from identification._outputs import primary_view

        view, j = primary_view(self.physics_)
        if isinstance(window.data, Trajectory):  # every output measured; else the window's is the state's own
            y_w = output_columns(window.data, tuple(self.outputs), error=DataError)[:, j]
        return view.estimate_state(u_w, y_w).x0

    # ------------------------------------------------------------ sequential
    @property
    def extra_inputs_(self) -> tuple[str, ...]:
        """Measured input columns the residual reads besides ``u`` (e.g. ``"Motor Curr."``), in order:
        an array input or a step's input vector is ``[u, *extra_inputs_]``."""
        self._check_fitted()
        return tuple(f for f in self.feature_names_ if f not in BUILTIN_FEATURES and not f.startswith("state:"))

    def initial_state(self, v0: float | ArrayLike, mode: str | None = None):
        """State ``(physics_x, residual_state)`` before the first sample ``v0`` (at rest there);
        ``v0`` is ``[u, *extra_inputs_]`` when the residual reads measured inputs."""
        self._check_fitted()
        u0, extra = self._input_row(v0)
        if self.direction == "forward":
            x0 = self.physics_.steady_state(u0)
        else:
            x0 = self.physics_.steady_state(self.physics_.steady_input(u0, bounds=self.input_bounds_))
        x1, out = self._physics_step(x0, u0)
        row = self._columns(np.array([u0]), np.array([out]), x1[None], extra)[0]
        return np.asarray(x0, dtype=float), self.residual_.initial_state(row, mode=mode)

    def step(self, state, v: float | ArrayLike) -> tuple[Any, float]:
        """One sample: ``(state, input) -> (state, output)`` in physical units (state explicit);
        the input is ``[u, *extra_inputs_]`` when the residual reads measured inputs, the output a
        vector for a model of several outputs."""
        self._check_fitted()
        x, r_state = state
        u, extra = self._input_row(v)
        x_next, out = self._physics_step(x, u)
        row = self._columns(np.array([u]), np.array([out]), x_next[None], extra)[0]
        r_state, r = self.residual_.step(r_state, row)
        if getattr(self, "domain_", None) is not None:
            r = r * float(self.domain_.function()(row))  # one row: the weight's function, no map
        return (x_next, r_state), out + r

    def _input_row(self, v) -> tuple[float, dict]:
        row = np.atleast_1d(np.asarray(v, dtype=float)).ravel()
        names = self.extra_inputs_
        if row.size != 1 + len(names):
            raise DataError(f"one sample's input must be [u{''.join(', ' + n for n in names)}] "
                            f"({1 + len(names)} values); got {row.size}.")
        return float(row[0]), {n: row[1 + j:2 + j] for j, n in enumerate(names)}

    # ----------------------------------------------------------- checkpoint
    def save(self, path: str | os.PathLike[str]):
        """One ``.pt`` file (physics, residual weights, scalers, settings) plus a ``.json`` copy of the metadata."""
        return save_hybrid(self, path)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> HybridModel:
        return load_hybrid(cls, path)

    # -------------------------------------------------------------- helpers
    def _check_settings(self) -> AbstractNetwork:
        net = self.network_
        if self.direction not in DIRECTIONS:
            raise DataError(f"The 'direction' parameter of HybridModel must be one of {list(DIRECTIONS)}. "
                            f"Got {self.direction!r} instead.")
        feats = tuple(self.features)
        if not feats or any(not isinstance(f, str) for f in feats) or len(set(feats)) != len(feats):
            raise DataError(f"The 'features' of HybridModel must be distinct column names, e.g. ('u', 'physics'). "
                            f"Got {self.features!r}.")
        check_training(self.training, "HybridModel")
        if self.fine_tune is not None and not isinstance(self.fine_tune, FineTuneSettings):
            raise DataError(f"The 'fine_tune' parameter of HybridModel must be None (no joint stage) or a "
                            f"FineTuneSettings, e.g. FineTuneSettings(epochs=10) (FineTuneSettings() for the "
                            f"defaults). Got {self.fine_tune!r} instead.")
        if tuple(self.outputs) and (self.direction != "forward" or self.fine_tune is not None):
            raise DataError("outputs= is for a forward hybrid with no fine-tuning (the joint stage steps a physics "
                            "of one output); leave out direction='inverse' and fine_tune, or fit each output alone.")
        if self.fine_tune is not None and self.direction != "forward":
            raise DataError("fine_tune is for forward hybrids: the physics inverse has no torch form "
                            "(it solves for the input). Fine-tune a forward model, or set fine_tune=None.")
        if self.residual_domain is not None:
            check_scale(self.residual_domain, "The 'residual_domain' parameter of HybridModel (None: no weight)")
        return net

    def _check_physics(self, dt: float) -> None:
        if abs(self.physics_.dt - dt) > 1e-6 * dt:
            raise DataError(f"The physics model samples at dt = {self.physics_.dt} s but the data at {dt} s; "
                            "give a Series built with the data's dt.")
        if self.direction == "inverse":
            if self.physics_.has_delay:
                raise DataError("An inverse hybrid needs a delay-free physics model (a delay has no causal inverse).")

    def _check_fitted(self) -> None:
        if not hasattr(self, "residual_"):
            raise NotFittedError(f"This HybridModel ({self.name}, {self.direction}) is not fitted yet. "
                                 "Call fit(trajectories) or HybridModel.load(path) first.")

    def _functions(self):
        if getattr(self, "_fns", None) is None:
            if self.direction == "forward":
                self._fns = self.physics_.step_function()
            else:
                self._fns = self.physics_.inverse_step_function(self.input_bounds_, self.inverse_quasi_static_)
        return self._fns

    def _physics_step(self, x, v: float) -> tuple[NDArray[np.float64], Any]:
        x_next, out = self._functions()(x, v, self.physics_.params)
        out = np.asarray(out, dtype=float).ravel()
        return np.asarray(x_next, dtype=float).ravel(), float(out[0]) if out.size == 1 else out

    def _physics_run(self, v: NDArray[np.float64], x0=None) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Physics output and the physics states *after* each sample, shape (n, n_x), from ``x0``
        (default: at rest at the first sample)."""
        p = self.physics_.params
        if x0 is None and self.direction == "forward":
            x0 = self.physics_.steady_state(v[0])
        elif x0 is None:
            x0 = self.physics_.steady_state(self.physics_.steady_input(v[0], bounds=self.input_bounds_))
        acc = self._functions().mapaccum("run", v.size)
        xs, out = acc(x0, v[None, :], ca.repmat(ca.DM(p), 1, v.size))
        out = np.asarray(out, dtype=float)  # (n_y, n): one row per output
        return out[0] if out.shape[0] == 1 else out.T, np.asarray(xs, dtype=float).reshape(-1, v.size).T

    def _model_input(self, data) -> tuple[NDArray[np.float64], dict]:
        if isinstance(data, Trajectory):
            t = data.swap() if self.direction == "inverse" else data
            return np.asarray(t.u, dtype=float), dict(t.extra)
        v = np.asarray(data, dtype=float)
        names = self.extra_inputs_
        columns = v.ndim == 2 and v.shape[1] == 1 + len(names) and v.shape[0] > 0
        if not columns and (v.ndim != 1 or v.size == 0 or names):
            shape = "(n,)" if not names else f"(n, {1 + len(names)}): columns u, {', '.join(names)}"
            raise DataError(f"input must be a path of shape {shape} with n >= 1; got shape {v.shape}.")
        _check_finite(v, ("u", *names))
        if columns:
            return v[:, 0], {n: v[:, 1 + j] for j, n in enumerate(names)}  # columns [u, *extra_inputs_]
        return v, {}

    def _column_names(self) -> tuple[str, ...]:
        """The names of the residual's input columns (:meth:`_columns`): the features, the physics output one
        column per output (``physics:NAME``) for a model of several."""
        several = tuple(self.outputs)
        return tuple(n for f in self.feature_names_
                     for n in ((f,) if f != "physics" or not several else (f"physics:{o}" for o in several)))

    def _residual_names(self) -> tuple[str, ...]:
        """The residual network's outputs for a model of several (``residual:NAME``); empty for one."""
        return tuple(f"residual:{o}" for o in self.outputs)

    def _columns(self, v, out, states, extra) -> NDArray[np.float64]:
        cols = []
        for name in self.feature_names_:
            if name == "u":
                cols.append(v)
            elif name == "physics":
                cols.append(out)
            elif name.startswith("state:"):
                cols.append(states[:, self.physics_.state_names.index(name[6:])])
            elif name in extra:
                cols.append(np.asarray(extra[name], dtype=float))
            else:
                raise DataError(f"feature {name!r} is neither 'u', 'physics' nor a column of the trajectory "
                                f"(it has {sorted(extra)}); load it as an input column (hyst --input 'u,{name}').")
        return np.column_stack(cols)

    def _run_columns(self, traj: Trajectory):
        """``(t, v, physics output, physics states)`` of a training trajectory, ``t`` the trajectory
        as the model sees it (swapped for an inverse model)."""
        t = traj.swap() if self.direction == "inverse" else traj
        v = np.asarray(t.u, dtype=float)
        out, states = self._physics_run(v)
        return t, v, out, states

    def _residual_trajectory(self, traj: Trajectory) -> Trajectory:
        t, v, out, states = self._run_columns(traj)
        cols = self._columns(v, out, states, t.extra)
        extra = {n: cols[:, j] for j, n in enumerate(self._column_names()) if j > 0}
        if not self.outputs:
            return Trajectory(t.time, cols[:, 0], t.y - out, source=t.source, extra=extra, meta=dict(t.meta))
        r, names = output_columns(t, tuple(self.outputs), error=DataError) - out, self._residual_names()
        extra.update({n: r[:, j] for j, n in enumerate(names) if j > 0})
        return Trajectory(t.time, cols[:, 0], r[:, 0], source=t.source, extra=extra, meta=dict(t.meta),
                          output_name=names[0])

    def __repr__(self) -> str:
        fitted = "" if hasattr(self, "residual_") else ", unfitted"
        phys = self.physics if isinstance(self.physics, str) else type(self.physics).__name__
        several = f", outputs={tuple(self.outputs)!r}" if self.outputs else ""
        return f"HybridModel({phys!r}, {self.network_!r}, direction={self.direction!r}{several}{fitted})"


def _physics_of_outputs(physics, trajectories, outputs: tuple[str, ...], identify_options: dict | None = None):
    """``(series, fit)``: the physics of a hybrid of several ``outputs``, a Series with one output per name (used
    as given, ``fit`` None), an :class:`identification.OutputsFit` (its series), or a spec fitted to the runs by
    :func:`identification.identify_outputs` (``identify_options``, e.g. ``warmup``)."""
    from identification import IdentificationError, OutputsFit, identify_outputs

    for t in trajectories:
        output_columns(t, outputs, error=DataError)  # a missing column, or a copy of the input, before any fit
    if isinstance(physics, OutputsFit):
        physics, fit = physics.series, physics
    elif isinstance(physics, str):
        try:
            fit = identify_outputs(physics, trajectories, outputs, **dict(identify_options or {}))
        except IdentificationError as exc:
            raise DataError(str(exc)) from None
        physics = fit.series
    else:
        fit = None
    if not isinstance(physics, Series) or physics.n_y != len(outputs):
        raise DataError(f"The physics of a hybrid of the outputs {list(outputs)} must have one output per name (a "
                        f"Series of {len(outputs)} outputs, an OutputsFit or a spec); got {physics!r}.")
    return physics, fit


def _check_finite(v: NDArray[np.float64], names: tuple[str, ...]) -> None:
    """Refuse an input path (shape (n,) or (n, columns named ``names``)) holding a NaN or an infinity,
    naming the first such sample (and its column)."""
    bad = np.argwhere(~np.isfinite(v))
    if bad.size:
        where = tuple(bad[0])
        value = v[where]
        shown = "NaN" if np.isnan(value) else ("inf" if value > 0 else "-inf")
        column = f" (column {names[where[1]]})" if v.ndim == 2 else ""
        raise DataError(f"input sample {where[0]}{column} is {shown}; the model needs finite inputs: fill in or "
                        "drop that sample.")


def _threads(n):
    from hybrid.learning._learned import _threads as threads

    return threads(n)
