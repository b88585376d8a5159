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

    def fit(self, data) -> "AbstractPeer":
        runs = self._runs(data)
        short = [r for r in runs if r.n <= self.lags + 1]
        if short:
            raise DataError(f"{type(self).__name__} needs runs longer than its {self.lags} lags; "
                            f"'{short[0].source}' has {short[0].n} samples.")
        u = np.concatenate([r.u for r in runs])
        y = np.concatenate([r.y for r in runs])
        self.u_mean_, self.u_std_ = float(u.mean()), float(u.std()) or 1.0
        self.y_mean_, self.y_std_ = float(y.mean()), float(y.std()) or 1.0
        self._fit([((r.u - self.u_mean_) / self.u_std_, (r.y - self.y_mean_) / self.y_std_) for r in runs])
        return self

    def predict(self, data, warmup=None) -> NDArray[np.float64]:
        if not hasattr(self, "y_std_"):
            raise NotFittedError(f"This {type(self).__name__} is not fitted yet. Call fit(runs) first.")
        u = self._input(data)
        window = as_warmup(warmup, inverse=self.direction == "inverse")
        if window is None:
            u_past, y_past = None, None
        else:
            u_past, y_past = self._input(window.data), np.asarray(window.w, dtype=float)
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
        y_rest = self._simulate(u_hold, np.zeros(n), np.full(200, u0))[-1]
        return u_hold, np.full(n, y_rest)

    # -- helpers -----------------------------------------------------------------------
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
    """The last ``n`` samples of ``values``, padded at the front with its first sample when shorter."""
    values = np.asarray(values, dtype=float)
    if values.size >= n:
        return values[values.size - n:]
    return np.concatenate([np.full(n - values.size, values[0]), values])
