"""A warm-up window: measured samples just before a prediction, from which a model sets its state.

Every model's ``predict(data, warmup=...)`` takes the same two forms, parsed here once:

- a :class:`Trajectory` of the measured samples just before ``data`` (the model swaps it, as it
  swaps ``data``, when it is an inverse model);
- a pair ``(v_w, w_w)`` of arrays in the model's own orientation: its input and its output over
  the window (for an inverse model, the wanted output and the input that produced it).

:func:`warmup_split` cuts a test run into the window and the rest, the protocol under which
``score_model(..., warmup=k)`` scores every model on the same samples.
"""

from __future__ import annotations

from dataclasses import replace
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from ._errors import DataError
from ._trajectory import Trajectory

__all__ = ["Warmup", "as_warmup", "check_warmup_length", "warmup_split"]


class Warmup(NamedTuple):
    """A checked warm-up window: ``data``, the window in the form ``predict`` takes (a Trajectory, or
    the model's input array), and ``w`` (n,), the model's measured output over it (for an inverse
    model, the input that was applied)."""

    data: Trajectory | NDArray[np.float64]
    w: NDArray[np.float64]

    @property
    def n(self) -> int:
        return int(self.w.size)

    def joined(self, data):
        """The window followed by ``data`` (same form: two trajectories, or two input arrays), the
        path a model runs over when it carries its state from the window on."""
        if isinstance(self.data, Trajectory) != isinstance(data, Trajectory):
            raise DataError("Give the warm-up window in the form of the data to predict: a Trajectory "
                            "before a Trajectory, or (input, output) arrays before an input array.")
        if isinstance(data, Trajectory):
            return join(self.data, data)
        a, b = np.asarray(self.data, dtype=float), np.asarray(data, dtype=float)
        if a.ndim != b.ndim or a.shape[1:] != b.shape[1:]:
            raise DataError(f"The warm-up window's input has shape {a.shape}, the data's {b.shape}: "
                            "give both with the same columns.")
        return np.concatenate([a, b])


def as_warmup(warmup, inverse: bool = False) -> Warmup | None:
    """``warmup`` (None, a Trajectory, or a pair ``(v_w, w_w)``) as a :class:`Warmup`, checked."""
    if warmup is None or isinstance(warmup, Warmup):
        return warmup
    if isinstance(warmup, Trajectory):
        return Warmup(warmup, np.asarray(warmup.u if inverse else warmup.y, dtype=float))
    try:
        v, w = warmup
    except (TypeError, ValueError):
        raise DataError("warmup must be None, a Trajectory of the measured samples before the prediction, "
                        f"or a pair (input_window, output_window) of arrays; got {type(warmup).__name__}.") from None
    v, w = np.asarray(v, dtype=float), np.asarray(w, dtype=float)
    if v.ndim not in (1, 2) or w.ndim != 1 or v.shape[0] != w.size or w.size < 1:
        raise DataError(f"A warm-up window's input and output must hold the same number (>= 1) of samples, "
                        f"the output 1-D; got shapes {v.shape} and {w.shape}.")
    bad = np.flatnonzero(~(np.isfinite(v).reshape(w.size, -1).all(axis=1) & np.isfinite(w)))
    if bad.size:
        raise DataError(f"The warm-up window has a non-finite value at sample {bad[0]}; "
                        "clean or interpolate the measurements first.")
    return Warmup(v, w)


def join(first: Trajectory, second: Trajectory) -> Trajectory:
    """``first`` then ``second`` as one trajectory (the same extra columns; times increasing)."""
    if set(first.extra) != set(second.extra):
        raise DataError(f"The warm-up window has columns {sorted(first.extra)}, the data {sorted(second.extra)}; "
                        "give both the same columns.")
    time = first.time
    if time[-1] >= second.time[0]:  # a window on its own clock: placed to end one step before the data
        step = second.dt if second.n > 1 else first.dt if first.n > 1 else 1.0
        time = time - time[-1] + second.time[0] - step
    time = np.concatenate([time, second.time])
    return replace(second, time=time, u=np.concatenate([first.u, second.u]), y=np.concatenate([first.y, second.y]),
                   extra={k: np.concatenate([first.extra[k], second.extra[k]]) for k in second.extra})


def check_warmup_length(k, n: int | None = None, where: str = "") -> int:
    """``k`` as a number of warm-up samples (an integer >= 0, fewer than ``n`` when given)."""
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 0:
        raise DataError(f"The warm-up length must be an integer number of samples >= 0. Got {k!r} instead.")
    if n is not None and k >= n:
        raise DataError(f"A warm-up of {k} samples leaves nothing to predict in a run of {n} samples"
                        f"{where}; use a shorter warm-up (--warmup) or a longer run.")
    return int(k)


def warmup_split(traj: Trajectory, k: int) -> tuple[Trajectory | None, Trajectory]:
    """``(window, rest)``: the first ``k`` samples of ``traj`` and the rest (``(None, traj)`` for k = 0)."""
    k = check_warmup_length(k, traj.n, f" ({traj.source})" if traj.source else "")
    if k == 0:
        return None, traj
    return traj.segment(0, k), traj.segment(k)
