"""Where the residual was trained: its weight falls to zero away from the training data.

A residual network learns what the physics misses on the training runs. On feature rows it never
saw (the catheter's falling branch near 0 mm after training on runs that never went below 1.5 mm)
it extrapolates arbitrarily, and can spoil a physics that extrapolates well: on the real catheter,
set 1 -> set 2, the physics alone (lag+backlash+linear) is at 2.50 deg and its hybrids at 1.9-5.0
deg depending on the seed. :class:`ResidualDomain` keeps the residual's training rows (scaled by
their standard deviation) and weights the residual by ``exp(-(d / radius)^2)``, ``d`` the distance
from the current row to the nearest training row and ``radius`` ``scale`` times the 99th percentile
of that distance among the training rows themselves (``scaled_rows``, as the intervals' distance):
inside the data the residual keeps almost all of its weight, far outside it the physics speaks
alone. The weight is one CasADi function, used by ``predict``, ``step`` and the export.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike, NDArray

from physics.data import DataError

from hybrid.intervals._distance import nearest_squared, scaled_rows

__all__ = ["ResidualDomain"]

#: Training rows kept (every k-th beyond this many): the export holds them as constants.
MAX_ROWS = 3000


def check_scale(scale, what: str) -> None:
    """Raise a :class:`DataError` naming ``what`` unless ``scale`` is a number > 0."""
    if isinstance(scale, bool) or not isinstance(scale, (int, float)) or not (np.isfinite(scale) and scale > 0):
        raise DataError(f"{what} must be a number > 0, e.g. 0.5. Got {scale!r} instead.")


class ResidualDomain:
    """Trust in the residual as a function of its input row: 1 on the training data, 0 far from it.

    Parameters
    ----------
    scale : float
        Radius in units of the 99th percentile of the training rows' nearest-neighbour distances
        (features scaled by their std). Smaller trusts the residual less off the data; on the
        catheter 0.5 cost 0.00-0.05 deg in distribution and saved 0.5-2.7 deg on the other baseline.
    max_rows : int
        Keep at most this many training rows (every k-th, in order).

    Examples
    --------
    >>> dom = ResidualDomain(scale=1.0).fit(np.c_[np.linspace(0, 1, 101), np.linspace(0, 1, 101) ** 2])
    >>> w = dom.weight([[0.5, 0.25], [3.0, 0.0]])
    >>> bool(w[0] > 0.99 and w[1] < 1e-6)
    True
    """

    def __init__(self, scale: float = 0.5, max_rows: int = MAX_ROWS):
        self.scale = scale
        self.max_rows = max_rows

    def fit(self, rows: ArrayLike) -> ResidualDomain:
        """Remember the training rows ``(n, n_features)``; returns ``self``."""
        check_scale(self.scale, "The 'scale' of ResidualDomain (HybridModel's residual_domain)")
        if isinstance(self.max_rows, bool) or not isinstance(self.max_rows, (int, np.integer)) or self.max_rows < 2:
            raise DataError(f"The 'max_rows' of ResidualDomain must be an integer >= 2. Got {self.max_rows!r}.")
        x = np.asarray(rows, dtype=float)
        if x.ndim != 2 or x.shape[0] < 2 or not np.all(np.isfinite(x)):
            raise DataError(f"ResidualDomain needs finite training rows of shape (n >= 2, n_features); got {x.shape}.")
        self.mean_, self.std_, self.rows_, spacing = scaled_rows(x, self.max_rows)
        self.radius_ = max(self.scale * spacing, 1e-9)
        self._fn = None
        return self

    def function(self) -> ca.Function:
        """``Function('domain_weight', [v], [w])``: the weight of one feature row ``v`` (physical units)."""
        if getattr(self, "_fn", None) is None:
            self._check_fitted()
            v = ca.MX.sym("v", self.rows_.shape[1])
            d2 = nearest_squared(v, self.mean_, self.std_, self.rows_)
            self._fn = ca.Function("domain_weight", [v], [ca.exp(-d2 / self.radius_**2)], ["v"], ["w"])
        return self._fn

    def weight(self, rows: ArrayLike) -> NDArray[np.float64]:
        """The weight (0 to 1) of each row ``(n, n_features)``."""
        x = np.atleast_2d(np.asarray(rows, dtype=float))
        self._check_fitted()
        if x.shape[1] != self.rows_.shape[1]:
            raise DataError(f"rows must have {self.rows_.shape[1]} features (the residual's); got {x.shape[1]}.")
        return np.asarray(self.function().map(x.shape[0])(x.T), dtype=float).ravel()

    def to_dict(self) -> dict:
        """Settings and fitted values (the rows as a nested list) for a checkpoint."""
        self._check_fitted()
        return {"scale": self.scale, "max_rows": self.max_rows, "mean": self.mean_.tolist(), "std": self.std_.tolist(),
                "radius": self.radius_}

    @classmethod
    def from_dict(cls, d: dict, rows: ArrayLike) -> ResidualDomain:
        out = cls(d["scale"], d["max_rows"])
        out.mean_, out.std_ = np.asarray(d["mean"], dtype=float), np.asarray(d["std"], dtype=float)
        out.rows_, out.radius_, out._fn = np.asarray(rows, dtype=float), float(d["radius"]), None
        return out

    def _check_fitted(self) -> None:
        if not hasattr(self, "rows_"):
            from physics.data import NotFittedError

            raise NotFittedError("This ResidualDomain is not fitted yet. Call fit(rows) first.")

    def __repr__(self) -> str:
        rows = f", {self.rows_.shape[0]} rows" if hasattr(self, "rows_") else ", unfitted"
        return f"ResidualDomain(scale={self.scale}{rows})"
