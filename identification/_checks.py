"""Validation of what the user passes to :func:`identify` (data, fixed, free, x0)."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np

from physics import Series

from ._errors import IdentificationError

#: Fewest samples accepted in one trajectory.
MIN_SAMPLES = 5


@dataclass(frozen=True)
class Record:
    """One validated trajectory: float arrays at the model's rate."""

    u: np.ndarray
    y: np.ndarray
    name: str

    @property
    def n(self) -> int:
        return self.u.size


def signal_scale(signals) -> float:
    """Order of magnitude of a signal: the power of ten nearest its standard deviation (else its
    largest value, else 1). A decade, not the value itself, so that data of ordinary size
    (a catheter's millimetres and degrees) keep the blocks' declared bounds as they are."""
    v = np.concatenate(signals)
    s = float(np.std(v)) or float(np.max(np.abs(v))) or 1.0
    return float(10.0 ** np.round(np.log10(s)))


def data_scales(runs) -> tuple[float, float]:
    """``(s_u, s_y)``: the orders of magnitude (:func:`signal_scale`) of the runs' inputs and outputs,
    the scales that ``Series.signal_scales`` turns into typical parameter magnitudes."""
    return signal_scale([r.u for r in runs]), signal_scale([r.y for r in runs])


def check_model(model) -> Series:
    if isinstance(model, str):
        return Series.from_spec(model)
    if not isinstance(model, Series):
        raise IdentificationError(
            f"model must be a physics.Series or a spec string such as 'lag+boucwen+linear'; "
            f"got {type(model).__name__}.")
    return model


def _as_list(trajectories) -> list:
    if hasattr(trajectories, "u") and hasattr(trajectories, "y"):
        return [trajectories]
    if isinstance(trajectories, tuple) and hasattr(trajectories, "_fields") \
            and "train" in trajectories._fields:
        raise IdentificationError("identify() got a train/test split; pass split.train.")
    if isinstance(trajectories, (str, bytes)) or not isinstance(trajectories, Iterable):
        raise IdentificationError(
            "trajectories must be a trajectory (an object with .u and .y arrays) or a list of "
            f"them; got {type(trajectories).__name__}.")
    items = list(trajectories)
    if not items:
        raise IdentificationError("identify() needs at least one trajectory; got none.")
    return items


def _rate_of(traj) -> float | None:
    meta = getattr(traj, "meta", None) or {}
    if isinstance(meta, Mapping) and meta.get("rate_hz"):
        return float(meta["rate_hz"])
    t = getattr(traj, "time", None)
    if t is None:
        return None
    t = np.asarray(t, dtype=float).ravel()
    if t.size < 2 or not np.all(np.isfinite(t)):
        return None
    return 1.0 / float(np.median(np.diff(t)))


def data_rate(trajectories) -> float:
    """The sample rate (Hz) of the first trajectory, from its time stamps or ``meta['rate_hz']``."""
    items = _as_list(trajectories)
    rate = _rate_of(items[0])
    if rate is None:
        raise IdentificationError("The trajectories carry no time stamps to read their sample rate from; "
                                  "give rate_hz=... (Hz) or pass physics.data.Trajectory(time, u, y).")
    return rate


def check_trajectories(trajectories, dt: float) -> list[Record]:
    """Validated copies of the trajectories' ``u``/``y`` (1-D, finite, same length, rate)."""
    records = []
    for i, traj in enumerate(_as_list(trajectories)):
        name = str(getattr(traj, "source", "") or f"trajectory {i}")
        label = f"trajectory {i}" + (f" ({name})" if name != f"trajectory {i}" else "")
        if not (hasattr(traj, "u") and hasattr(traj, "y")):
            raise IdentificationError(f"{label} has no .u/.y arrays; got {type(traj).__name__}.")
        u = np.asarray(traj.u, dtype=float)
        y = np.asarray(traj.y, dtype=float)
        if u.ndim != 1 or y.ndim != 1 or u.size != y.size:
            raise IdentificationError(
                f"{label}: u and y must be 1-D arrays of equal length; got shapes {u.shape} and "
                f"{y.shape}.")
        if u.size < MIN_SAMPLES:
            raise IdentificationError(
                f"{label} is too short: {u.size} samples; identification needs at least "
                f"{MIN_SAMPLES} per trajectory.")
        for what, v in (("u", u), ("y", y)):
            bad = np.flatnonzero(~np.isfinite(v))
            if bad.size:
                raise IdentificationError(
                    f"{label}: {what} has a non-finite value at index {bad[0]}; clean or "
                    "interpolate the data first.")
        rate = _rate_of(traj)
        if rate is not None and abs(rate * dt - 1.0) > 0.01:
            raise IdentificationError(
                f"{label} is sampled at {rate:.4g} Hz but the model runs at {1 / dt:.4g} Hz; "
                f"resample it first (trajectory.resample({1 / dt:.4g})).")
        records.append(Record(u.copy(), y.copy(), name))
    return records


def check_fixed(model: Series, fixed, free, bounds=None) -> tuple[np.ndarray, dict[str, float]]:
    """The free-parameter mask and the values of the held ones (name -> value).

    A parameter is held when the block says so (``fit_mask`` False) or when it is
    in ``fixed``; names in ``free`` are fitted even when the block holds them.
    """
    names = model.param_names
    known = ", ".join(names)
    if fixed is None:
        fixed = {}
    elif isinstance(fixed, str):
        fixed = [fixed]
    if not isinstance(fixed, Mapping):
        current = model.param_dict()
        fixed = {k: current[k] if k in current else None for k in fixed}
    free = [] if free is None else ([free] if isinstance(free, str) else list(free))
    for name in list(fixed) + free:
        if name not in names:
            raise IdentificationError(
                f"Unknown parameter '{name}' for model '{model.spec}'. Known: {known}.")
    both = sorted(set(fixed) & set(free))
    if both:
        raise IdentificationError(f"Parameter(s) {both} are both fixed and free; pick one.")
    lo, hi = bounds if bounds is not None else (model.lower_bounds, model.upper_bounds)
    for name, value in fixed.items():
        k = names.index(name)
        if value is None or not np.isfinite(float(value)) or not lo[k] <= float(value) <= hi[k]:
            raise IdentificationError(
                f"The fixed value of '{name}' must be a number in [{lo[k]}, {hi[k]}]. "
                f"Got {value} instead.")
    mask = model.fit_mask.copy()
    for name in free:
        mask[names.index(name)] = True
    for name in fixed:
        mask[names.index(name)] = False
    values = model.param_dict()
    values.update({k: float(v) for k, v in fixed.items()})
    held = {n: values[n] for n, m in zip(names, mask) if not m}
    return mask, held


def check_x0(x0, model: Series, n_traj: int):
    """``"steady"``, ``"estimate"`` or an (n_traj, n_x) array of initial states."""
    if isinstance(x0, str):
        if x0 not in ("steady", "estimate"):
            raise IdentificationError(
                f"x0 must be 'steady', 'estimate' or an array of initial states. Got '{x0}'.")
        return x0
    arr = np.asarray(x0, dtype=float)
    if arr.ndim == 1:
        arr = np.tile(arr, (n_traj, 1))
    if arr.shape != (n_traj, model.n_x) or not np.all(np.isfinite(arr)):
        raise IdentificationError(
            f"x0 as an array must be finite with shape ({model.n_x},) or ({n_traj}, {model.n_x}) "
            f"(states {', '.join(model.state_names)}); got shape {np.shape(x0)}.")
    return arr


def settings_or_default(value, kind: type, name: str, example: str):
    """``value`` when it is a ``kind`` (a settings object), ``kind()`` for None; anything else is refused
    with an example (a dict of its fields, say: the fields are checked when the object is built)."""
    if value is None:
        return kind()
    if not isinstance(value, kind):
        raise IdentificationError(f"{name} must be an {kind.__module__.split('._')[0]}.{kind.__name__}, e.g. "
                                  f"{example}. Got {type(value).__name__} instead.")
    return value

