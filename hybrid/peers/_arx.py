"""A linear ARX model fitted by least squares: the three-line baseline of system identification."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ._base import AbstractPeer, past

__all__ = ["LinearARX", "FORMAT"]

#: The ``format`` of a saved ARX (``LinearARX.save``), what ``hybrid.export.load`` recognises.
FORMAT = "hysteresis-hybrid/linear-arx/1"
_FITTED = ("a_", "b_", "c_", "u_mean_", "u_std_", "y_mean_", "y_std_")


class LinearARX(AbstractPeer):
    """``y[t] = sum_i a_i y[t-i] + sum_j b_j u[t-nk-j] + c``, ``i = 1..na``, ``j = 0..nb-1`` (MATLAB's
    ``arx(data, [na nb nk])``, plus a constant), fitted by least squares on one-step-ahead regressors
    of every run (no regressor crosses from one run into another), on inputs and outputs normalised by
    the training data's mean and std so the fit reads alike in any units. ``predict`` simulates it free.

    Parameters
    ----------
    na, nb : int
        Output and input lags.
    nk : int
        Input delay in samples (1, the default, as MATLAB's: no direct term; 0: ``u[t]`` enters ``y[t]``).
    direction : {"forward", "inverse"}
    outputs : sequence of str, optional
        Several output columns (the runs' ``y`` by its name, or ``Trajectory.extra`` columns) fitted at
        once: each output regressed on the past of every output and on the input (a MIMO ARX, each output
        normalised by its own spread). ``predict`` then returns ``(n, k)`` and a warm-up window is a run
        with those columns or a pair ``(u_w, y_w)``, ``y_w`` of shape ``(k_w, k)``. A forward ARX of one
        output (the default, None) is the one that exports as a step.

    Examples
    --------
    >>> import numpy as np
    >>> from physics.data import Trajectory
    >>> t = np.arange(400) * 0.04
    >>> u = np.sin(0.7 * t) + np.sin(2.3 * t)
    >>> y = np.zeros_like(u)
    >>> for k in range(1, u.size):
    ...     y[k] = 0.9 * y[k - 1] + 0.5 * u[k - 1]
    >>> arx = LinearARX(na=1, nb=1).fit(Trajectory(t, u, y))
    >>> bool(np.allclose(arx.predict(u[10:], warmup=(u[:10], y[:10])), y[10:]))
    True
    """

    name = "arx"

    def __init__(self, na: int = 3, nb: int = 3, nk: int = 1, direction: str = "forward", outputs=None):
        self.na = na
        self.nb = nb
        self.nk = nk
        self.direction = direction
        self.outputs = outputs

    @property
    def lags(self) -> int:
        return max(int(self.na), int(self.nk) + int(self.nb) - 1, 1)

    def _fit(self, runs) -> None:
        from physics.data import DataError

        for name, least in (("na", 0), ("nb", 1), ("nk", 0)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < least:
                raise DataError(f"The '{name}' parameter of LinearARX must be an integer >= {least}. Got {v!r} instead.")
        na, nb, nk = int(self.na), int(self.nb), int(self.nk)
        rows, targets = [], []
        for u, y in runs:
            for t in range(self.lags, u.size):
                rows.append(self._regressors(u[t - nk - nb + 1:t - nk + 1], y[t - na:t].ravel()))
                targets.append(y[t])
        theta, *_ = np.linalg.lstsq(np.array(rows), np.array(targets), rcond=None)
        if theta.ndim == 1:
            self.a_, self.b_, self.c_ = theta[:na][::-1], theta[na:na + nb][::-1], float(theta[-1])
        else:  # a_[i]: (k, k), y[t] += y[t-1-i] @ a_[i]; b_[j]: (k,), y[t] += u[t-nk-j] b_[j]
            k = theta.shape[1]
            self.a_, self.b_, self.c_ = theta[:na * k].reshape(na, k, k)[::-1], theta[na * k:na * k + nb][::-1], theta[-1]
        self.poles_ = _poles(self.a_, na)

    def _rest_past(self, u0: float):
        """At rest at ``u0``: the steady state ``(c + sum(b) u0) / (1 - sum(a))``."""
        n = self.lags
        if np.ndim(self.c_):
            return np.full(n, u0), np.tile(self._rest_several(u0), (n, 1))
        y_rest = (self.c_ + self.b_.sum() * u0) / (1.0 - self.a_.sum()) if abs(1.0 - self.a_.sum()) > 1e-12 else 0.0
        return np.full(n, u0), np.full(n, y_rest)

    def _regressors(self, u_recent: NDArray, y_recent: NDArray) -> NDArray:
        """Oldest first: ``y[t-na..t-1]``, ``u[t-nk-nb+1..t-nk]``, 1."""
        return np.concatenate([y_recent, u_recent, [1.0]])

    def _rest_several(self, u0: float) -> NDArray:
        """The steady output of several: ``y (I - sum a) = c + sum(b) u0`` (zeros where it has no steady state)."""
        gain = np.eye(self.c_.size) - self.a_.sum(axis=0)
        try:
            return np.linalg.solve(gain.T, self.c_ + self.b_.sum(axis=0) * u0)
        except np.linalg.LinAlgError:
            return np.zeros(self.c_.size)

    def _simulate(self, u_past, y_past, u) -> NDArray:
        na, nb, nk = int(self.na), int(self.nb), int(self.nk)
        if np.ndim(self.c_):
            return self._simulate_several(u_past, y_past, u)
        ys = list(past(y_past, na)) if na else []
        us = list(past(u_past, nk + nb - 1)) if nk + nb > 1 else []
        out = np.empty(u.size)
        for t, ut in enumerate(u):
            us.append(ut)
            recent = us[::-1][nk:nk + nb]  # u[t-nk], u[t-nk-1], ...
            y = self.c_ + (np.dot(self.a_, ys[::-1][:na]) if na else 0.0) + np.dot(self.b_, recent)
            out[t] = y
            ys.append(y)
        return out

    def _simulate_several(self, u_past, y_past, u) -> NDArray:
        na, nb, nk = int(self.na), int(self.nb), int(self.nk)
        ys = list(past(y_past, na)) if na else []
        us = list(past(u_past, nk + nb - 1)) if nk + nb > 1 else []
        out = np.empty((u.size, self.c_.size))
        for t, ut in enumerate(u):
            us.append(ut)
            recent = us[::-1][nk:nk + nb]
            y = self.c_ + np.dot(recent, self.b_)
            for i in range(na):
                y = y + ys[-1 - i] @ self.a_[i]
            out[t] = y
            ys.append(y)
        return out

    # -- a model like the others: saved, loaded, exported -------------------------------
    def to_dict(self) -> dict:
        """JSON-ready settings and fitted coefficients (:meth:`from_dict` reads them back)."""
        if not hasattr(self, "a_"):
            from physics.data import NotFittedError

            raise NotFittedError("This LinearARX is not fitted yet. Call fit(runs) first.")
        out = {"format": FORMAT, **self.get_params()}
        outputs = out.pop("outputs")  # a model of one output is saved as before
        if outputs:
            out["outputs"] = list(outputs)
        for name in _FITTED:
            value = getattr(self, name)
            out[name] = np.asarray(value, dtype=float).tolist() if np.ndim(value) else float(value)
        return out

    @classmethod
    def from_dict(cls, state: dict) -> "LinearARX":
        from physics.data import DataError

        missing = [k for k in ("na", "nb", "nk", *_FITTED) if k not in state]
        if state.get("format") != FORMAT or missing:
            raise DataError(f"Not a saved LinearARX (format {FORMAT!r} with {', '.join(_FITTED)}): "
                            + (f"missing {missing[0]!r}." if missing else f"format {state.get('format')!r}."))
        outputs = state.get("outputs")
        model = cls(na=int(state["na"]), nb=int(state["nb"]), nk=int(state["nk"]),
                    direction=state.get("direction", "forward"), outputs=tuple(outputs) if outputs else None)
        values = {k: np.asarray(state[k], dtype=float) for k in _FITTED}
        k_y = len(outputs) if outputs else 1
        shapes = {"a_": (model.na, k_y, k_y), "b_": (model.nb, k_y), "c_": (k_y,), "y_mean_": (k_y,), "y_std_": (k_y,)}
        if not all(np.all(np.isfinite(v)) for v in values.values()) or any(
                values[name].size != int(np.prod(shape)) for name, shape in shapes.items()):
            raise DataError(f"A saved LinearARX needs {model.na} finite a_ and {model.nb} finite b_ coefficients "
                            f"{'' if k_y == 1 else f'(for {k_y} outputs) '}and finite scales; fit it again.")
        for k, v in values.items():
            if k_y > 1 and k in shapes:
                setattr(model, k, v.reshape(shapes[k]))
            else:
                setattr(model, k, v if k in ("a_", "b_") else float(v))
        model.poles_ = _poles(model.a_, model.na)
        return model

    def save(self, path) -> Path:
        """Write :meth:`to_dict` to ``path`` (JSON, atomically)."""
        from physics.data.io import write_json

        write_json(Path(path), self.to_dict())
        return Path(path)

    @classmethod
    def load(cls, path) -> "LinearARX":
        from physics.data.io import read_json

        return cls.from_dict(read_json(Path(path), "linear ARX"))

    @property
    def past_inputs(self) -> int:
        """Past inputs a step needs beside the present one: ``nk + nb - 1``."""
        return int(self.nk) + int(self.nb) - 1

    def rest_output(self, u0):
        """The rest output at the input ``u0`` (physical units; symbolic or numeric)."""
        if np.ndim(self.c_):
            return self.y_mean_ + self.y_std_ * self._rest_several((u0 - self.u_mean_) / self.u_std_)
        u0_n = (u0 - self.u_mean_) / self.u_std_
        gain = 1.0 - float(np.sum(self.a_))
        y_n = (self.c_ + float(np.sum(self.b_)) * u0_n) / gain if abs(gain) > 1e-12 else 0.0 * u0_n
        return self.y_mean_ + self.y_std_ * y_n


def _poles(a: NDArray, na: int) -> NDArray:
    """The ARX's poles: the roots of ``1 - sum a_i z^-i``, or of several outputs the eigenvalues of the block
    companion matrix of its output lags."""
    if not na:
        return np.zeros(0)
    if a.ndim == 1:
        return np.roots(np.r_[1.0, -a])
    k = a.shape[1]
    companion = np.zeros((na * k, na * k))
    companion[:k] = np.hstack([a_i.T for a_i in a])  # column form: y[t] = sum a_i^T y[t-1-i]
    companion[k:, :-k] = np.eye((na - 1) * k)
    return np.linalg.eigvals(companion)
