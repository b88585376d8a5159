"""A polynomial NARX model through SysIdentPy (FROLS term selection), the classic nonlinear peer."""

from __future__ import annotations

import warnings

import numpy as np
from numpy.typing import NDArray

from ._base import EXTRA, AbstractPeer, past

__all__ = ["PolynomialNARX"]


class PolynomialNARX(AbstractPeer):
    """SysIdentPy's FROLS (forward regression with orthogonal least squares) on a polynomial basis:
    ``y[t]`` a sum of monomials up to ``degree`` in ``y[t-1..t-ylag]`` and ``u[t-1..t-xlag]``, the
    number of terms chosen by an information criterion, simulated free. SysIdentPy fits one series:
    the training runs are joined end to end (their joins are a few regressors out of thousands).

    Needs the optional extra ``peers`` (``sysidentpy==0.9.0``).

    Parameters
    ----------
    ylag, xlag : int
        Output and input lags.
    degree : int
        Polynomial degree of the basis.
    n_info_values : int
        Most terms the information criterion weighs.
    direction : {"forward", "inverse"}
    outputs : sequence of str, optional
        Several output columns (as :class:`LinearARX`'s): SysIdentPy's FROLS fits one output, so each output
        gets its own NARX of its own past and the input (each normalised by its own spread); ``predict`` then
        returns ``(n, k)``.
    """

    name = "narx"

    def __init__(self, ylag: int = 2, xlag: int = 2, degree: int = 2, n_info_values: int = 15,
                 direction: str = "forward", outputs=None):
        self.ylag = ylag
        self.xlag = xlag
        self.degree = degree
        self.n_info_values = n_info_values
        self.direction = direction
        self.outputs = outputs

    @property
    def lags(self) -> int:
        return max(int(self.ylag), int(self.xlag), 1)

    def _fit(self, runs) -> None:
        try:
            from sysidentpy.basis_function import Polynomial
            from sysidentpy.model_structure_selection import FROLS
            from sysidentpy.parameter_estimation import LeastSquares
        except ImportError as exc:
            raise ImportError(f"PolynomialNARX needs sysidentpy: {EXTRA}") from exc
        u = np.concatenate([r[0] for r in runs])[:, None]
        y = np.concatenate([r[1] for r in runs])
        columns = [y] if y.ndim == 1 else list(y.T)  # one FROLS per output
        self.models_ = []
        for column in columns:
            model = FROLS(ylag=int(self.ylag), xlag=int(self.xlag), order_selection=True,
                          n_info_values=int(self.n_info_values), info_criteria="aic",
                          estimator=LeastSquares(), basis_function=Polynomial(degree=int(self.degree)),
                          model_type="NARMAX")
            with warnings.catch_warnings():  # its rank checks warn on near-collinear candidate terms
                warnings.simplefilter("ignore")
                model.fit(X=u, y=column[:, None])
            self.models_.append(model)

    def _simulate(self, u_past, y_past, u) -> NDArray:
        y_past = np.asarray(y_past, dtype=float)
        pasts = [y_past] if y_past.ndim == 1 else list(y_past.T)
        outs = []
        for model, own in zip(self.models_, pasts):
            n = model.max_lag
            x = np.concatenate([past(u_past, n), u])[:, None]
            y0 = np.concatenate([past(own, n), np.zeros(u.size)])[:, None]  # only the first n are read
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                out = np.asarray(model.predict(X=x, y=y0), dtype=float).ravel()[n:]
            outs.append(np.where(np.isfinite(out), out, np.nan))
        return outs[0] if y_past.ndim == 1 else np.column_stack(outs)
