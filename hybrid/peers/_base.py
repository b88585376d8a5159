"""What every peer shares: the estimator contract our scorer calls, runs in either direction, warm-up windows."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from physics.data import BaseEstimator, DataError, NotFittedError, Trajectory, as_warmup

__all__ = ["AbstractPeer", "EXTRA"]

#: How to install the optional peers.
EXTRA = "pip install 'hysteresis-hybrid[peers]'"


class AbstractPeer(BaseEstimator):
    """A system-identification model from another tool, scored like ours: ``fit(runs)`` returns self,
    ``predict(data, warmup=None)`` simulates free (its own past outputs fed back) over ``data``'s input,
    its past set from the measured ``warmup`` window (:func:`physics.data.as_warmup`) or, without one,
    from the first input held at rest (:meth:`_rest_past`)."""

    name = "peer"
    #: Samples of the past the model's regressors or encoder read.
    lags = 1
    #: The output columns of a peer of several outputs (None: the runs' ``y``); a setting where a peer takes it.
    outputs = None

    def fit(self, data) -> "AbstractPeer":
        runs = self._runs(data)
        short = [r for r in runs if r.n <= self.lags + 1]
        if short:
            raise DataError(f"{type(self).__name__} needs runs longer than its {self.lags} lags; "
                            f"'{short[0].source}' has {short[0].n} samples.")
        u = np.concatenate([r.u for r in runs])
        ys = [self._y(r) for r in runs]
        y = np.concatenate(ys)
        self.u_mean_, self.u_std_ = float(u.mean()), float(u.std()) or 1.0
        if y.ndim == 1:
            self.y_mean_, self.y_std_ = float(y.mean()), float(y.std()) or 1.0
        else:  # each output in its own units
            std = y.std(axis=0)
            self.y_mean_, self.y_std_ = y.mean(axis=0), np.where(std > 0, std, 1.0)
        self._fit([((r.u - self.u_mean_) / self.u_std_, (yr - self.y_mean_) / self.y_std_) for r, yr in zip(runs, ys)])
        return self

    def predict(self, data, warmup=None) -> NDArray[np.float64]:
        if not hasattr(self, "y_std_"):
            raise NotFittedError(f"This {type(self).__name__} is not fitted yet. Call fit(runs) first.")
        u = self._input(data)
        u_past, y_past = self._window(warmup)
        un = (u - self.u_mean_) / self.u_std_
        if u_past is None:
            u_past, y_past = self._rest_past(un[0])
        else:
            u_past, y_past = (u_past - self.u_mean_) / self.u_std_, (y_past - self.y_mean_) / self.y_std_
        return self.y_mean_ + self.y_std_ * np.asarray(self._simulate(u_past, y_past, un), dtype=float)

    # -- for each peer -----------------------------------------------------------------
    def _fit(self, runs: list[tuple[NDArray, NDArray]]) -> None:
        """Fit on normalised ``(u, y)`` runs."""
        raise NotImplementedError

    def _simulate(self, u_past: NDArray, y_past: NDArray, u: NDArray) -> NDArray:
        """Free-run output (normalised) over ``u`` after the measured past ``(u_past, y_past)``."""
        raise NotImplementedError

    def _rest_past(self, u0: float) -> tuple[NDArray, NDArray]:
        """The past of a run that starts at rest at ``u0``: the input held there, the output at the
        model's own rest output for it (its free run on the constant input, settled)."""
        n = max(self.lags, 1)
        u_hold = np.full(n, u0)
        k = len(self.outputs) if self.outputs else 0  # several outputs: a row of the past per sample
        y_rest = self._simulate(u_hold, np.zeros((n, k)) if k else np.zeros(n), np.full(200, u0))[-1]
        return u_hold, np.tile(y_rest, (n, 1)) if k else np.full(n, y_rest)

    # -- helpers -----------------------------------------------------------------------
    def _y(self, run: Trajectory) -> NDArray[np.float64]:
        """The run's output: its ``y``, or ``(n, k)`` of the named ``outputs``."""
        if not self.outputs:
            return run.y
        from identification import output_columns

        return output_columns(run, self.outputs, refuse_copies=False, error=DataError)

    def _window(self, warmup) -> tuple[NDArray | None, NDArray | None]:
        """The measured past ``(u_w, y_w)`` (None, None without one); with ``outputs``, ``y_w`` is ``(k, n_y)``:
        from a Trajectory's named columns, or a pair ``(u_w, y_w)``."""
        if not self.outputs or warmup is None:
            window = as_warmup(warmup, inverse=self.direction == "inverse")
            return (None, None) if window is None else (self._input(window.data), np.asarray(window.w, dtype=float))
        if isinstance(warmup, Trajectory):
            return self._input(warmup), self._y(warmup)
        u_w, y_w = (np.asarray(v, dtype=float) for v in warmup)
        if u_w.ndim != 1 or y_w.shape != (u_w.size, len(self.outputs)) or not u_w.size \
                or not (np.all(np.isfinite(u_w)) and np.all(np.isfinite(y_w))):
            raise DataError(f"A warm-up window of {type(self).__name__} with outputs {', '.join(self.outputs)} is a "
                            f"finite input of k >= 1 samples and a (k, {len(self.outputs)}) output; got shapes "
                            f"{u_w.shape} and {y_w.shape}.")
        return u_w, y_w

    def _check_direction(self) -> None:
        if self.direction not in ("forward", "inverse"):
            raise DataError(f"The 'direction' parameter of {type(self).__name__} must be 'forward' or "
                            f"'inverse'. Got {self.direction!r} instead.")

    def _runs(self, data) -> list[Trajectory]:
        self._check_direction()
        runs = [data] if isinstance(data, Trajectory) else list(data)
        if not runs or not all(isinstance(r, Trajectory) for r in runs):
            raise DataError(f"{type(self).__name__}.fit needs a Trajectory or a list of them.")
        return [r.swap() if self.direction == "inverse" else r for r in runs]

    def _input(self, data) -> NDArray[np.float64]:
        if isinstance(data, Trajectory):
            t = data.swap() if self.direction == "inverse" else data
            return np.asarray(t.u, dtype=float)
        u = np.asarray(data, dtype=float)
        if u.ndim != 1 or u.size == 0 or not np.all(np.isfinite(u)):
            raise DataError(f"input must be a finite 1-D path with n >= 1; got shape {u.shape}.")
        return u


def past(values: NDArray, n: int) -> NDArray:
    """The last ``n`` samples (rows) of ``values``, padded at the front with its first sample when shorter."""
    values = np.asarray(values, dtype=float)
    if len(values) >= n:
        return values[len(values) - n:]
    return np.concatenate([np.repeat(values[:1], n - len(values), axis=0), values])
