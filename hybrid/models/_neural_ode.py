"""A neural-ODE hybrid: the physics model's continuous-time dynamics plus a network in the state derivative.

``dxc/dt = f_physics(xc, u, udot; p) + udot * g_theta(xc, u, udot)``, ``y = h_physics(xc, u; p)``,
integrated with torchdiffeq (``odeint``, method ``'rk4'``: fixed steps, one per sample
interval, or 2, 4 or 8 where the fitted physics is too stiff for one at the data's rate, and
proportionally more, once fitted, on an interval whose input or states move faster than on any
training sample), the
input linear between samples so ``udot`` is constant on each interval.
``f`` and ``h`` are ``Series.ode_function()`` translated to torch once
(``physics.torch_expression``); the physics parameters are torch parameters
initialised from the CasADi fit and trained with the network.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable
from typing import Any

import casadi as ca
import numpy as np
import torch
from numpy.typing import ArrayLike, NDArray
from torch import Tensor, nn

from hybrid.learning._learned import _as_trajectories, _threads
from hybrid.learning._segments import segment_length, train_on_segments
from identification import PhysicsPolicy, data_scales, fit_physics
from physics import Series
from physics.data import BaseEstimator, DataError, NotFittedError, Trajectory, as_warmup

from ._hybrid_io import read_hybrid_blob, write_hybrid_blob
from ._torch_physics import TorchPhysics

__all__ = ["NeuralODEHybrid"]


def ode_state_names(series: Series) -> list[str]:
    """The continuous states a neural ODE corrects; a PhysicsError names the blocks without a
    continuous form, or says the spec has no state at all (a static map such as ``poly+linear``)."""
    from physics import PhysicsError

    names = series.continuous_state_names
    if not names:
        raise PhysicsError(f"'{series.spec}' has no state, so a neural ODE has no derivative to correct; "
                           "use a spec with a dynamic block (lag, backlash, boucwen, creep, ...).")
    return names


#: RK4 steps per sample tried in turn: the fewest at which the physics ODE follows the discrete
#: physics on the training runs is used (a mode or loop too stiff for one step at the rate).
SUBSTEPS = (1, 2, 4, 8)
#: The physics ODE's rollout may differ from the discrete physics by at most this many times the
#: outputs' span before the step count is called unstable.
ROLLOUT_DRIFT = 10.0
#: An interval is integrated at most this many times finer than the trained ``substeps``
#: (:meth:`_ODE.refinement`): a jump of a thousand trained steps costs 256x one sample, not 1000x.
MAX_REFINEMENT = 256


def _rollout_problem(trajs, ys, discrete) -> str | None:
    """Where the ODE rollouts ``ys`` of the training runs blow up (non-finite, or far from the
    ``discrete`` physics' outputs, whose blocks are built to stay stable at any rate), or None."""
    span = float(np.ptp(np.concatenate([t.y for t in trajs]))) or 1.0
    for i, (t, y, ref) in enumerate(zip(trajs, ys, discrete)):
        bad = ~np.isfinite(y) | (np.abs(y - ref) > ROLLOUT_DRIFT * span)
        if bad.any():
            return f"run {t.source or i}, from sample {int(np.argmax(bad))}"
    return None


class _ODE(nn.Module):
    """Physics ODE plus the gated correction; float64 throughout."""

    def __init__(self, series: Series, hidden: int, gated: bool, dt: float,
                 signal_scales: tuple[float, float] | None = None, substeps: int = 1):
        super().__init__()
        self.physics = TorchPhysics(series, signal_scales=signal_scales)
        n = len(series.continuous_state_names)
        self.net = nn.Sequential(nn.Linear(n + 2, hidden), nn.Tanh(), nn.Linear(hidden, hidden), nn.Tanh(),
                                 nn.Linear(hidden, n)).double()
        nn.init.zeros_(self.net[-1].weight)  # a zero correction at the start: the physics ODE itself
        nn.init.zeros_(self.net[-1].bias)
        self.gated, self.dt, self.substeps = gated, float(dt), int(substeps)
        self.refine = False  # set once fitted: training runs on the runs that set the norms, where it is 1
        for name in ("x_lo", "x_span"):
            self.register_buffer(name, torch.zeros(n, dtype=torch.float64) if name == "x_lo" else
                                 torch.ones(n, dtype=torch.float64))
        self.register_buffer("u_norm", torch.tensor([0.0, 1.0, 1.0], dtype=torch.float64))  # u lo, u span, udot span
        self.register_buffer("rate_norm", torch.tensor(math.inf, dtype=torch.float64))  # fastest state_rate trained

    def rhs(self, x: Tensor, u: Tensor, udot: Tensor) -> Tensor:
        xdot, _ = self.physics.ode(x, u, udot)
        z = torch.cat([(x - self.x_lo) / self.x_span, ((u - self.u_norm[0]) / self.u_norm[1])[..., None],
                       (udot / self.u_norm[2])[..., None]], -1)
        corr = self.net(z)
        return xdot + (corr * udot[..., None] if self.gated else corr)

    def output(self, x: Tensor, u: Tensor) -> Tensor:
        return self.physics.ode(x, u, torch.zeros_like(u))[1]

    def interval(self, x: Tensor, u0: Tensor, udot: Tensor) -> Tensor:
        """State after one sample interval on which the input goes linearly from ``u0`` at slope ``udot``
        (``substeps`` RK4 steps; once fitted, times :meth:`refinement`)."""
        from torchdiffeq import odeint

        n = self.substeps * self.refinement(x, u0, udot) if self.refine else self.substeps
        t = torch.linspace(0.0, self.dt, n + 1, dtype=torch.float64)
        return odeint(lambda s, xs: self.rhs(xs, u0 + s * udot, udot), x, t, method="rk4")[-1]

    def state_rate(self, x: Tensor, u: Tensor, udot: Tensor) -> Tensor:
        """How fast the physics moves its states, ``max_i |xdot_i| / x_span_i`` (spans per second), (B,)."""
        return (self.physics.ode(x, u, udot)[0].abs() / self.x_span).amax(-1)

    def refinement(self, x: Tensor, u0: Tensor, udot: Tensor) -> int:
        """How many times finer than ``substeps`` the interval from state ``x`` is integrated: 1 while
        the input and the states move no faster than on the training runs (``u_norm[2]``,
        ``rate_norm``), above that in proportion. A loop's stiffness grows with the rate (Bouc-Wen's
        ``beta |x'|``), and a state keeps moving after its input stops: on a friction stage's random
        steps (5.7x the fastest trained input) the oscillator's velocity ran away at the trained step
        count, NaN by sample 613."""
        with torch.no_grad():
            ratio = float(torch.maximum(udot.abs().max() / self.u_norm[2],
                                        self.state_rate(x, u0, udot).max() / self.rate_norm))
        if math.isnan(ratio):  # a state already lost: no step count brings it back
            return 1
        if ratio >= MAX_REFINEMENT:
            return MAX_REFINEMENT
        return max(1, math.ceil(ratio * (1 - 1e-9)))

    def run(self, x: Tensor, u_prev: Tensor, u: Tensor) -> tuple[Tensor, Tensor]:
        """Outputs (B, L) and states after each sample (B, L, n) for inputs ``u`` (B, L) from state ``x``
        (the input was ``u_prev`` (B,) the sample before)."""
        ys, xs = [], []
        for k in range(u.shape[1]):
            udot = (u[:, k] - u_prev) / self.dt
            x = self.interval(x, u_prev, udot)
            u_prev = u[:, k]
            ys.append(self.output(x, u_prev))
            xs.append(x)
        return torch.stack(ys, 1), torch.stack(xs, 1)


class NeuralODEHybrid(BaseEstimator):
    """Physics ODE plus a small network correcting the state derivative, trained end to end.

    Parameters
    ----------
    physics : str, physics.Series or identification.FitResult
        A spec is identified on the training data first; every block needs a
        continuous-time form (lag, backlash, boucwen, poly, linear, drift, ...) and the
        spec a state to correct (not ``poly+linear``), else ``fit`` raises a PhysicsError;
        it does too, before training, where the physics ODE blows up under RK4 even at
        8 steps per sample (a loop or mode too stiff for the data's rate).
    hidden : int, default 32
        Width of the two tanh layers of the correction network.
    gated : bool, default True
        Multiply the correction by ``udot``: like the rate-independent
        hysteresis it corrects, it then vanishes at rest (no drift while the
        input holds). False: an ungated correction (for rate-dependent effects).
    epochs, batch_size, lr, physics_lr, segment_len, seed, progress, threads
        ``epochs=0``: no training, the physics ODE itself. Adam on segments of ``segment_len`` samples (``batch_size`` segments a
        step), each started from the state of a full run with the current
        parameters; ``physics_lr`` is the rate of the relative parameter change.
    identify_options : dict, optional

    Attributes
    ----------
    module_ : torch.nn.Module
        The ODE; ``module_.substeps`` is its RK4 steps per sample (the fewest of 1, 2, 4, 8 at
        which the physics ODE follows the discrete physics on the training runs), and
        ``module_.refinement`` how many times more an interval takes where the input or the
        states move faster than on any training sample.
    physics_ : physics.Series
        The physics with the trained parameters.
    physics_report_ : identification.PhysicsReport
        How the physics was reached (:func:`identification.fit_physics`).
    loss_ : list of float
        Mean training loss (MSE over the output's variance) per epoch.

    Examples
    --------
    >>> from hybrid.virtual import paper_protocol
    >>> split = paper_protocol(frequencies=(0.5,), tests=(0.45,), baselines=("mid",))
    >>> model = NeuralODEHybrid("backlash+boucwen+linear", epochs=1, progress=False).fit(split.train)
    >>> model.predict(split.test[0]).shape
    (389,)
    """

    direction = "forward"

    def __init__(self, physics: Any = "backlash+boucwen+linear", hidden: int = 32, *, gated: bool = True,
                 epochs: int = 20, batch_size: int = 16, lr: float = 1e-3, physics_lr: float = 1e-3,
                 segment_len: int = 50, seed: int = 0, progress: bool | None = None, threads: int | None = None,
                 identify_options: dict | None = None):
        self.physics = physics
        self.hidden = hidden
        self.gated = gated
        self.epochs = epochs
        self.batch_size = batch_size
        self.lr = lr
        self.physics_lr = physics_lr
        self.segment_len = segment_len
        self.seed = seed
        self.progress = progress
        self.threads = threads
        self.identify_options = identify_options

    name = "neural-ode"

    # ------------------------------------------------------------------ fit
    def fit(self, data: Trajectory | Iterable[Trajectory]) -> NeuralODEHybrid:
        for name in ("hidden", "epochs", "batch_size", "segment_len"):
            value, low = getattr(self, name), 0 if name == "epochs" else 1
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
                raise DataError(f"The {name!r} parameter of NeuralODEHybrid must be an integer >= {low}. "
                                f"Got {value!r} instead.")
        trajs = _as_trajectories(data)
        if isinstance(self.physics, str):  # fail before identifying when a block has no ODE form
            ode_state_names(Series.from_spec(self.physics))
        series, self.physics_fit_, self.physics_report_ = fit_physics(
            PhysicsPolicy(self.physics, identify_options=self.identify_options), trajs)
        ode_state_names(series)
        with _threads(self.threads):
            torch.manual_seed(self.seed)
            self.module_ = _ODE(series, self.hidden, self.gated, trajs[0].dt, data_scales(trajs))
            self._normalise(trajs)
            self.loss_ = _train(self, trajs)
            self._measure_rates(trajs)
        self.module_.eval()
        self.module_.refine = True
        return self

    @property
    def physics_(self) -> Series:
        self._check_fitted()
        return self.module_.physics.to_series()

    def _normalise(self, trajs) -> None:
        with torch.no_grad():
            u = np.concatenate([t.u for t in trajs])
            udot = np.concatenate([np.diff(t.u) for t in trajs]) / trajs[0].dt
            xs = torch.cat([x for _, x in self._stable_rollouts(trajs)])
            m = self.module_
            m.x_lo.copy_(xs.min(0).values)
            m.x_span.copy_(torch.tensor([_span(column) for column in xs.numpy().T], dtype=torch.float64))
            m.u_norm.copy_(torch.tensor([u.min(), _span(u), np.abs(udot).max() or 1.0]))

    def _measure_rates(self, trajs) -> None:
        """``rate_norm``: the fastest :meth:`_ODE.state_rate` on the training runs, trained (so
        predicting them takes no finer steps than training did)."""
        m, rates = self.module_, []
        with torch.no_grad():
            for t, before in zip(trajs, self._states_before([t.u for t in trajs])):
                u = torch.tensor(np.asarray(t.u, dtype=float))
                u_prev = torch.cat([u[:1], u[:-1]])
                rates.append(m.state_rate(before, u_prev, (u - u_prev) / m.dt).max())
            m.rate_norm.copy_(torch.stack(rates).max())

    def _stable_rollouts(self, trajs) -> list[tuple[Tensor, Tensor]]:
        """The physics ODE's rollouts of the training runs at the fewest RK4 steps per sample of
        :data:`SUBSTEPS` at which they follow the discrete physics (``module_.substeps``)."""
        from physics import PhysicsError

        m = self.module_
        series = m.physics.to_series()
        discrete = [series.simulate(t.u) for t in trajs]  # the same for every step count tried
        for n in SUBSTEPS:
            m.substeps = n
            runs = self._run_all([t.u for t in trajs])
            where = _rollout_problem(trajs, [y.numpy() for y, _ in runs], discrete)
            if where is None:
                return runs
        raise PhysicsError(
            f"The ODE form of '{series.spec}' diverges under RK4 even at {SUBSTEPS[-1]} steps per sample at "
            f"{1 / trajs[0].dt:.4g} Hz ({where}): a loop or mode of the fitted physics is too stiff for that "
            "rate. Use a HybridModel residual on it, or a neural ODE on a spec without that block.")

    # -------------------------------------------------------------- predict
    def _run(self, u: NDArray[np.float64], x0: NDArray[np.float64] | None = None) -> tuple[Tensor, Tensor]:
        """Output and states after each sample of ``u`` from the continuous state ``x0`` (default: at
        rest at ``u[0]``)."""
        m = self.module_
        u_t = torch.tensor(np.asarray(u, dtype=float))[None]
        if x0 is None:
            x0 = m.physics.to_series().continuous_steady_state(float(u[0]))
        y, xs = m.run(torch.tensor(np.asarray(x0, dtype=float))[None], u_t[:, 0], u_t)
        return y[0], xs[0]

    def _run_all(self, us: list[NDArray[np.float64]], x0: Tensor | None = None) -> list[tuple[Tensor, Tensor]]:
        """:meth:`_run` of every input path in ``us`` at once, as one batch (a shorter path is held at
        its last input, and cut back), from the states ``x0`` (B, n) (default: :meth:`_rest_states`):
        the same numbers to rounding in a fraction of the time, since a step of a few small tensors
        costs the same whatever the batch. For fitting, where ``refine`` is off (with it on, every
        path would take the finest steps any needs)."""
        m, n = self.module_, max(len(u) for u in us)
        u_t = torch.tensor(np.stack([np.pad(np.asarray(u, dtype=float), (0, n - len(u)), mode="edge") for u in us]))
        y, xs = m.run(self._rest_states(us) if x0 is None else x0, u_t[:, 0], u_t)
        return [(y[i, :len(u)], xs[i, :len(u)]) for i, u in enumerate(us)]

    def _rest_states(self, us: list[NDArray[np.float64]]) -> Tensor:
        """The physics' rest state at each path's first input, (B, n)."""
        series = self.module_.physics.to_series()
        return torch.tensor(np.stack([series.continuous_steady_state(float(u[0])) for u in us]), dtype=torch.float64)

    def _states_before(self, us: list[NDArray[np.float64]]) -> list[Tensor]:
        """The state before each sample of every input path in ``us`` with the current weights, (L, n)
        each: the rest state at ``u[0]``, then the rollout's."""
        x0 = self._rest_states(us)
        return [torch.cat([x0[i:i + 1], xs[:-1]]) for i, (_, xs) in enumerate(self._run_all(us, x0))]

    def predict(self, data: Trajectory | ArrayLike, mode: str | None = None, warmup=None) -> NDArray[np.float64]:
        """Tip angle for a trajectory's input (or an input path), from rest at its first sample, or from
        the state of the physics fitted to ``warmup``, the measured samples just before ``data`` (a
        Trajectory or ``(u_w, y_w)``: :func:`physics.data.as_warmup`), integrated on through the window."""
        self._check_fitted()
        window, x0 = as_warmup(warmup), None
        if window is not None:
            data = window.joined(data)
        u = data.u if isinstance(data, Trajectory) else np.asarray(data, dtype=float)
        if u.ndim != 1 or u.size == 0 or not np.all(np.isfinite(u)):
            raise DataError(f"input must be a finite 1-D path with n >= 1 samples; got shape {np.shape(u)}.")
        if window is not None:
            series = self.physics_
            x = series.estimate_state(u[:window.n], window.w).x0
            x0 = x[[series.state_names.index(n) for n in series.continuous_state_names]]
        with torch.no_grad():
            return self._run(u, x0)[0].numpy()[0 if window is None else window.n:].copy()

    def initial_state(self, u0: float, mode: str | None = None) -> tuple[NDArray[np.float64], float]:
        """``(xc, u_prev)``: the continuous state at rest at ``u0`` and the input it rests at."""
        self._check_fitted()
        return self.module_.physics.to_series().continuous_steady_state(float(u0)), float(u0)

    def step(self, state, u: float) -> tuple[tuple[NDArray[np.float64], float], float]:
        """One sample: integrate the interval from the previous input to ``u``; returns (state, y)."""
        self._check_fitted()
        x, u_prev = state
        with torch.no_grad():
            y, xs = self.module_.run(torch.tensor(np.asarray(x, dtype=float))[None], torch.tensor([float(u_prev)]),
                                     torch.tensor([[float(u)]], dtype=torch.float64))
        return (xs[0, -1].numpy().copy(), float(u)), float(y[0, -1])

    # ----------------------------------------------------------- checkpoint
    def save(self, path: str | os.PathLike[str]):
        """One ``.pt`` (weights, physics, settings) plus a ``.json`` copy of the metadata."""
        self._check_fitted()
        settings = {k: v for k, v in self.get_params(deep=False).items() if k not in ("physics", "identify_options")}
        meta = {"settings": settings, "physics": self.module_.physics.series.to_dict(), "dt": self.module_.dt,
                "substeps": self.module_.substeps, "loss": list(self.loss_)}
        return write_hybrid_blob(path, "neural-ode", meta, {"weights": self.module_.state_dict()})

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> NeuralODEHybrid:
        blob = read_hybrid_blob(path, "neural-ode")
        series = Series.from_dict(blob["physics"])
        model = cls(series, **blob["settings"])
        substeps = blob.get("substeps", 1)  # checkpoints before substeps took one RK4 step per sample
        if substeps not in SUBSTEPS or isinstance(substeps, bool):
            raise DataError(f"{path}: 'substeps' must be one of {SUBSTEPS}; got {substeps!r}. The checkpoint is "
                            "damaged or from another program; fit the model again.")
        model.module_ = _ODE(series, model.hidden, model.gated, blob["dt"], substeps=substeps)
        weights = {"rate_norm": torch.tensor(math.inf, dtype=torch.float64), **blob["weights"]}  # older: no refinement
        model.module_.load_state_dict(weights)
        model.module_.eval()
        model.module_.refine = True
        model.loss_, model.physics_fit_ = list(blob["loss"]), None
        return model

    def _check_fitted(self) -> None:
        if not hasattr(self, "module_"):
            raise NotFittedError("This NeuralODEHybrid is not fitted yet. Call fit(trajectories) or "
                                 "NeuralODEHybrid.load(path) first.")

    def __repr__(self) -> str:
        fitted = "" if hasattr(self, "module_") else ", unfitted"
        phys = self.physics if isinstance(self.physics, str) else type(self.physics).__name__
        return f"NeuralODEHybrid({phys!r}, hidden={self.hidden}{fitted})"


def _train(model: NeuralODEHybrid, trajs) -> list[float]:
    m = model.module_
    L = segment_length(model.segment_len, trajs)
    us = [torch.tensor(np.asarray(t.u, dtype=float)) for t in trajs]
    ys = [torch.tensor(np.asarray(t.y, dtype=float)) for t in trajs]
    var = float(np.var(np.concatenate([t.y for t in trajs]))) or 1.0

    def starts():  # states at every sample with the current weights: the segments' starts
        return model._states_before([t.u for t in trajs])

    def loss(start, batch):
        x0 = torch.stack([start[i][s] for i, s in batch])
        u_prev = torch.stack([us[i][max(s - 1, 0)] for i, s in batch])
        u = torch.stack([us[i][s:s + L] for i, s in batch])
        y = torch.stack([ys[i][s:s + L] for i, s in batch])
        yhat, _ = m.run(x0, u_prev, u)
        return ((yhat - y) ** 2).mean() / var

    groups = [{"params": m.net.parameters(), "lr": model.lr}, {"params": [m.physics.delta], "lr": model.physics_lr}]
    return train_on_segments(groups, trajs, L, epochs=model.epochs, batch_size=model.batch_size, seed=model.seed,
                             prepare=starts, loss=loss, desc="neural-ode", progress=model.progress)


def _span(v: NDArray[np.float64]) -> float:
    """``ptp(v)``, or ``v``'s size where it does not vary (1 for all zeros): any units, no absolute floor."""
    size = float(np.abs(v).max())
    return float(np.ptp(v)) if np.ptp(v) > 1e-9 * size else (size or 1.0)
