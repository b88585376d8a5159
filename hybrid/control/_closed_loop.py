"""Closed loop: the MPC drives a plant (the virtual catheter's true physics plus sensor noise).

The MPC's model state is advanced by running the model itself on the inputs
applied (an open-loop observer: the state of a hysteresis model cannot be
measured, and a tip-angle sensor does not make it observable in a useful
time). Model error is handled by output-error correction (``correction="offset"``,
the default): the filtered difference between measured and predicted angle is
treated as a constant output disturbance over the horizon, i.e. subtracted from
the reference. This is the classical offset-free MPC trick with a disturbance
model ``d_{k+1} = d_k``; ``correction="none"`` tracks on the model alone. How the output is fed
back is one :class:`Feedback` (``run_closed_loop(..., feedback=Feedback(...))``).

With ``measure_every=N`` the tip is seen only every N-th sample (imaging, a tracker), and a
:class:`~hybrid.control.MovingHorizonEstimator` refits the model's state and the output offset
at each measurement over its window; the MPC starts from its state and tracks the reference
less its offset. A plant of several outputs (the tip's angle and position) with an MPC that tracks
one of them (``MPCSettings(track=j)``) and an estimator on the model of them all measures every
output, or those ``Feedback.outputs`` names: the one state they share is fitted on them.

With ``online`` (an :class:`~hybrid.intervals.AdaptiveIntervals`) and an MPC built with
``tighten=True``, the interval the output bounds keep inside is the online band: before each solve
its half-widths over the horizon (``ahead = 1 .. horizon``) go to ``TrackingMPC.solve(half_widths=)``,
and each measured sample moves it by the error of the prediction made before it (the estimator's,
or the open-loop model's), so the bounds back off by what the measurements say the model misses
rather than by the offline band. As before, the bounds apply to the model's output; the estimated
offset moves the reference, not the bounds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from hybrid.export._export import export_model
from hybrid.export._model import ExportedModel, ExportError
from physics.data.io import raise_if_pressed, recording

from ._estimator import MovingHorizonEstimator, measurement_mask
from ._mpc import TrackingMPC
from ._static import input_for

__all__ = ["ClosedLoopResult", "Feedback", "run_closed_loop", "reference_signal", "REFERENCES"]

REFERENCES = ("sine", "steps")


@dataclass
class ClosedLoopResult:
    """Signals of a closed-loop run, one entry per control sample."""

    time: NDArray[np.float64]
    reference: NDArray[np.float64]
    u: NDArray[np.float64]
    y: NDArray[np.float64]          # measured (with noise)
    y_true: NDArray[np.float64]     # plant output without noise
    y_model: NDArray[np.float64]    # the MPC model's prediction of the applied input
    solve_times: NDArray[np.float64]
    #: The online band's half-width the MPC kept inside the bounds at each sample (None without ``online``).
    half_width: NDArray[np.float64] | None = None

    @property
    def rmse_deg(self) -> float:
        """Tracking RMSE of the true (noise-free) tip angle against the reference (deg)."""
        return float(np.sqrt(np.mean((self.y_true - self.reference) ** 2)))

    def table(self) -> NDArray[np.float64]:
        """Columns time, reference, u, y, y_true, y_model, solve_time_s."""
        return np.column_stack([self.time, self.reference, self.u, self.y, self.y_true, self.y_model,
                                self.solve_times])


#: The sine reference's frequency, Hz (:func:`reference_signal`).
SINE_HZ = 0.2


def reference_signal(kind: str, y_low: float, y_high: float, duration_s: float = 20.0,
                     dt: float = 0.04, frequency_hz: float = SINE_HZ, step_s: float = 2.5,
                     seed: int = 0) -> NDArray[np.float64]:
    """A tip-angle reference (deg) at ``dt``: ``"sine"`` from ``y_low`` to ``y_high`` and back,
    or ``"steps"``: random levels in ``[y_low, y_high]`` held ``step_s`` seconds (starting at ``y_low``)."""
    t = np.arange(int(round(duration_s / dt))) * dt
    if kind == "sine":
        return y_low + (y_high - y_low) * 0.5 * (1 - np.cos(2 * np.pi * frequency_hz * t))
    if kind == "steps":
        n_levels = int(np.ceil(duration_s / step_s)) + 1
        levels = np.r_[y_low, np.random.default_rng(seed).uniform(y_low, y_high, n_levels - 1)]
        return levels[np.minimum((t / step_s).astype(int), n_levels - 1)]
    raise ExportError(f"Unknown reference {kind!r}. Must be one of: {', '.join(REFERENCES)}, or a file.")


@dataclass(frozen=True)
class Feedback:
    """How the plant's measured output reaches the MPC of :func:`run_closed_loop` (see the module
    docstring). The default: measured at every sample, the offset filtered with gain 0.3.

    Parameters
    ----------
    correction : {"offset", "none"}
        Output-error correction at every measured sample; ``"none"`` tracks on the model alone.
    filter_gain : float
        Gain in (0, 1] of the first-order filter on the output error.
    measure_every : int, optional
        The plant's output is measured only every this many samples (from the first), and the
        MPC's state and offset come from a moving-horizon estimator fed with those measurements
        (``correction`` is then not used). None: measured at every sample.
    estimator : MovingHorizonEstimator, optional
        The estimator to use with ``measure_every`` (default: one on the model with its defaults
        and the MPC's input bounds).
    online : AdaptiveIntervals, optional
        Fitted; needs ``TrackingMPC(..., tighten=True)``. The online band whose half-widths the output
        bounds keep inside, updated at each measured sample.
    outputs : tuple of int, optional
        A plant of several outputs and an ``estimator`` on the model of them all: the outputs measured
        (indices; default every one). The tracked output need not be among them.

    Examples
    --------
    >>> from hybrid.control import Feedback
    >>> Feedback(measure_every=25).correction
    'offset'
    """

    correction: str = "offset"
    filter_gain: float = 0.3
    measure_every: int | None = None
    estimator: MovingHorizonEstimator | None = None
    online: object = None
    outputs: tuple[int, ...] | None = None

    def __post_init__(self) -> None:
        if self.correction not in ("offset", "none"):
            raise ExportError(f"correction must be 'offset' or 'none'. Got {self.correction!r} instead.")
        if isinstance(self.filter_gain, bool) or not (isinstance(self.filter_gain, (int, float))
                                                      and 0 < self.filter_gain <= 1):
            raise ExportError(f"filter_gain must be a number in (0, 1]. Got {self.filter_gain!r} instead.")


def run_closed_loop(mpc: TrackingMPC, plant, reference: ArrayLike, model: ExportedModel | None = None,
                    u0: float | None = None, noise_std_deg: float = 0.15, seed: int = 0,
                    measured: ArrayLike | None = None, feedback: Feedback | None = None) -> ClosedLoopResult:
    """Run ``mpc`` against ``plant`` over ``reference`` (deg, one value per sample).

    Parameters
    ----------
    mpc : TrackingMPC
        Built on ``model`` (default ``mpc.model``, which an MPC built from an
        ``ExportedModel`` keeps).
    plant : ExportedModel or physics.Series
        The truth, stepped at the control rate; e.g. ``VirtualCatheter().truth_model()``.
    u0 : float, optional
        Input both plant and model rest at before the start; default: the model's
        input whose rest output is ``reference[0]`` (bisection within ``mpc.u_bounds``).
    noise_std_deg : float
        Gaussian sensor noise added to the plant's output.
    measured : array, shape (n, n_d), optional
        For a model that reads measured inputs besides the command (``mpc.n_d`` of them):
        their values at each sample, fed to the model, to the MPC (over its horizon) and
        to a plant that reads them too.
    feedback : Feedback, optional
        How the measured output reaches the MPC: the offset correction, sparse measurements and
        their estimator, the online band (default ``Feedback()``).
    """
    feedback = Feedback() if feedback is None else feedback
    if not isinstance(feedback, Feedback):
        raise ExportError(f"feedback must be a hybrid.control.Feedback, e.g. Feedback(measure_every=25). "
                          f"Got {type(feedback).__name__} instead.")
    correction, filter_gain, measure_every = feedback.correction, feedback.filter_gain, feedback.measure_every
    estimator, online = feedback.estimator, feedback.online
    model = model if model is not None else mpc.model
    if model is None:
        raise ExportError("run_closed_loop needs the MPC's model as an ExportedModel (for its initial "
                          "state): build TrackingMPC(export_model(...)) or pass model=.")
    if online is not None and not mpc.tighten:
        raise ExportError("online= gives the interval the output bounds keep inside: build the MPC with "
                          "TrackingMPC(..., y_bounds=(low, high), tighten=True).")
    plant = export_model(plant)
    ref = np.asarray(reference, dtype=float).ravel()
    if ref.size < 1 or not np.all(np.isfinite(ref)):
        raise ExportError("The reference must be a non-empty array of finite angles (deg).")
    if plant.n_y > 1:
        return _run_several(mpc, plant, ref, model, u0, noise_std_deg, seed, feedback)
    if feedback.outputs is not None:
        raise ExportError("Feedback(outputs=...) names the measured outputs of a plant of several; this plant has one "
                          "output. Leave outputs out.")
    meas = np.zeros((ref.size, 0)) if measured is None else np.asarray(measured, dtype=float).reshape(ref.size, -1)
    if meas.shape[1] != mpc.n_d:
        raise ExportError(f"The model reads {mpc.n_d} measured input(s); measured= gives {meas.shape[1]} per sample.")
    with_d = lambda u, k, m: np.r_[u, meas[k]] if m.n_u > 1 else u  # noqa: E731
    u_start = input_for(model, ref[0], mpc.u_bounds, meas[0]) if u0 is None else float(u0)
    rng = np.random.default_rng(seed)
    x_m, x_p, u_prev, d = model.x0(with_d(u_start, 0, model)), plant.x0(with_d(u_start, 0, plant)), u_start, 0.0
    mhe, mask = None, measurement_mask(ref.size, 1 if measure_every is None else measure_every)
    if measure_every is not None or estimator is not None:
        mhe = estimator or MovingHorizonEstimator(model, u_bounds=mpc.u_bounds)
        if mhe.model is not model and mhe.model.step is not model.step:
            raise ExportError("The estimator must be built on the MPC's model: MovingHorizonEstimator(model, ...).")
        mhe.reset(x=x_m, u0=with_d(u_start, 0, model))
    n, N = ref.size, mpc.horizon
    out = {k: np.zeros(n) for k in ("u", "y", "y_true", "y_model", "solve", "half")}
    band = None if online is None else online.initial()
    mpc.reset()
    with recording():  # Ctrl-C stops the loop after the step in progress
        for k in range(n):
            raise_if_pressed()
            if mhe is not None:
                x_m, d = mhe.x_, mhe.offset_
            window = ref[k:k + N] - (d if correction == "offset" or mhe is not None else 0.0)
            widths = None if band is None else [float(online.half_width(band, ahead=i)) for i in range(1, N + 1)]
            u = mpc.solve(x_m, window, u_prev=u_prev, measured=meas[k:k + N] if mpc.n_d else None,
                          half_widths=widths)
            x_p, y_true = plant.step(x_p, with_d(u, k, plant))
            y_true = float(y_true)
            y_meas = y_true + noise_std_deg * rng.standard_normal()
            if mhe is not None:  # the model's prediction of this sample, before its measurement
                y_m = mhe.update(with_d(u, k, model), y_meas if mask[k] else None)
            else:
                x_m, y_m = model.step(x_m, with_d(u, k, model))
                y_m = float(y_m)
                d += filter_gain * ((y_meas - y_m) - d)
            if band is not None:  # the band of this sample, then its measurement (if any) moves it
                out["half"][k], band = widths[0], online.advance(band)
                band = online.update(band, y_meas - y_m) if mask[k] else band
            out["u"][k], out["y"][k], out["y_true"][k], out["y_model"][k] = u, y_meas, y_true, y_m
            out["solve"][k] = mpc.stats.solve_times[-1]
            u_prev = u
    dt = model.dt or plant.dt or 1.0
    return ClosedLoopResult(np.arange(n) * dt, ref, out["u"], out["y"], out["y_true"], out["y_model"], out["solve"],
                            None if online is None else out["half"])


def _run_several(mpc: TrackingMPC, plant: ExportedModel, ref: np.ndarray, model, u0, noise, seed: int,
                 feedback: Feedback) -> ClosedLoopResult:
    """:func:`run_closed_loop` on a plant of several outputs: the MPC tracks ``mpc.settings.track``, the estimator
    (on the model of every output) reads those ``feedback.outputs`` names every ``feedback.measure_every``
    samples; ``noise``: one standard deviation, or one per output. The result's outputs are the tracked one's."""
    mhe, track, n_y = feedback.estimator, mpc.settings.track, plant.n_y
    if track is None or mhe is None or mhe.model.n_y != n_y or feedback.online is not None:
        raise ExportError(f"A plant of {n_y} outputs: build the MPC on the model of them all with the output it tracks "
                          "(TrackingMPC(model, MPCSettings(track=j))) and give Feedback(estimator=MovingHorizonEstimator("
                          "model, ...)) on that model (no online band).")
    model = model if model is not None else mpc.model
    if mhe.model.n_x != model.n_x or mpc.n_d or plant.n_u != 1:
        raise ExportError("The estimator's model must have the MPC's state (the model of every output whose output "
                          "the MPC tracks), with one input.")
    picked = list(range(n_y)) if feedback.outputs is None else list(feedback.outputs)
    if not all(isinstance(j, (int, np.integer)) and not isinstance(j, bool) and 0 <= j < n_y for j in picked):
        raise ExportError(f"Feedback(outputs=...) names the measured outputs by index in 0..{n_y - 1}. "
                          f"Got {feedback.outputs!r}.")
    seen = np.zeros(n_y, dtype=bool)
    seen[picked] = True
    noise = np.asarray(noise, dtype=float).ravel()
    if noise.size not in (1, n_y) or not np.all(np.isfinite(noise) & (noise >= 0)):
        raise ExportError(f"The sensor noise of a plant of {n_y} outputs is one standard deviation >= 0, or one per "
                          f"output. Got {noise.tolist()}.")
    noise = np.broadcast_to(noise, (n_y,)).astype(float)
    u_prev = input_for(model, ref[0], mpc.u_bounds) if u0 is None else float(u0)
    x_p = plant.x0(u_prev)
    mhe.reset(x=model.x0(u_prev), u0=u_prev)
    mask = measurement_mask(ref.size, 1 if feedback.measure_every is None else feedback.measure_every)
    rng = np.random.default_rng(seed)
    n, N = ref.size, mpc.horizon
    out = {k: np.zeros(n) for k in ("u", "y", "y_true", "y_model", "solve")}
    mpc.reset()
    with recording():
        for k in range(n):
            raise_if_pressed()
            u = mpc.solve(mhe.x_, ref[k:k + N] - np.asarray(mhe.offset_)[track], u_prev=u_prev)
            x_p, y_true = plant.step(x_p, u)
            y_true = np.asarray(y_true, dtype=float).ravel()
            y_meas = y_true + noise * rng.standard_normal(n_y)
            y_m = mhe.update(u, np.where(seen, y_meas, np.nan) if mask[k] else None)
            out["u"][k], out["y"][k], out["y_true"][k], out["y_model"][k] = u, y_meas[track], y_true[track], y_m[track]
            out["solve"][k] = mpc.stats.solve_times[-1]
            u_prev = u
    dt = model.dt or plant.dt or 1.0
    return ClosedLoopResult(np.arange(n) * dt, ref, out["u"], out["y"], out["y_true"], out["y_model"], out["solve"])
