"""How far a sample is from the data a model was fitted on.

A row is ``(u, du/dt, y)``: the input, its rate (backward difference) and the output (measured
for the training rows, predicted for new ones), each scaled by its standard deviation over the
training rows. The distance of a row is the Euclidean distance to the
nearest training row in units of the *radius*: the 99th percentile of that distance among the
training rows themselves. Inside the data the distance stays near or under 1; on a baseline, an
amplitude or a rate the model never saw it grows. The same numbers are one CasADi function, so an
exported step reports them too.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike, NDArray

from physics.data import DataError, NotFittedError

__all__ = ["DataDistance", "input_rows", "nearest", "nearest_squared", "scaled_rows"]

#: Training rows kept (every k-th beyond this many): an export holds them as constants and
#: searches them all each step (256 rows: about 1.4 us compiled; 1811 rows took 10 us).
MAX_ROWS = 256
#: Percentile of the training rows' nearest-neighbour distances that sets the radius.
PERCENTILE = 99.0
#: A row farther than this many radii from every training row is outside the data.
OUTSIDE_RADII = 2.0
#: An input beyond the training range by more than this share of the range is outside the data.
RANGE_MARGIN = 0.01


def input_rows(u: ArrayLike, dt: float, y: ArrayLike | None = None) -> NDArray[np.float64]:
    """``(n, 2)`` rows ``(u, du/dt)``, or ``(n, 3)`` rows ``(u, du/dt, y)`` with an output; the
    rate is the backward difference (the first sample takes the second's), which is what a step
    that keeps the previous input can compute."""
    u = np.asarray(u, dtype=float).ravel()
    rate = np.zeros_like(u)
    if u.size > 1:
        rate[1:] = np.diff(u) / dt
        rate[0] = rate[1]
    return np.column_stack([u, rate] + ([] if y is None else [np.asarray(y, dtype=float).ravel()]))


def nearest(a: NDArray, b: NDArray, exclude_self: bool = False) -> NDArray[np.float64]:
    """Distance from each row of ``a`` to its nearest row of ``b`` (itself excluded when ``a is b``)."""
    from scipy.spatial import cKDTree

    tree = cKDTree(np.asarray(b, dtype=float))
    if exclude_self:
        return np.asarray(tree.query(np.asarray(a, dtype=float), k=2)[0][:, 1], dtype=float)
    return np.asarray(tree.query(np.asarray(a, dtype=float), k=1)[0], dtype=float)


def scaled_rows(x: NDArray, max_rows: int) -> tuple[NDArray, NDArray, NDArray, float]:
    """Every k-th row of ``x`` (at most ``max_rows``), their mean and std (1 where a feature is
    constant), the rows scaled by them, and the :data:`PERCENTILE` of the scaled rows'
    nearest-neighbour distances: what :class:`DataDistance` and the residual's domain keep."""
    x = x[:: int(np.ceil(x.shape[0] / max_rows))]
    mean = x.mean(axis=0)
    std = np.where(x.std(axis=0) > 0, x.std(axis=0), 1.0)
    rows = (x - mean) / std
    return mean, std, rows, float(np.percentile(nearest(rows, rows, exclude_self=True), PERCENTILE))


def nearest_squared(v, mean: NDArray, std: NDArray, rows: NDArray):
    """CasADi: the squared distance of the symbolic row ``v`` (physical units), scaled by ``mean``
    and ``std``, to the nearest of the scaled ``rows``; the symbolic twin of :func:`nearest`."""
    z = (v - ca.DM(mean)) / ca.DM(std)
    return ca.mmin(ca.sum1((ca.DM(rows.T) - ca.repmat(z, 1, rows.shape[0])) ** 2))


#: Percentile of a training run's distances to the other runs' rows: how far one run lies from the rest.
SPACING_PERCENTILE = 90.0


def _spacing(z: NDArray, runs: NDArray) -> float:
    """How far one training run lies from the others (scaled rows ``z``, run label per row): the median
    over the runs of the :data:`SPACING_PERCENTILE` of its rows' distances to the other runs' rows (a
    new run between two trained ones is no farther; a repeated run does not set it alone); 0 with one run."""
    labels = list(dict.fromkeys(runs.tolist()))
    if len(labels) < 2:
        return 0.0
    step = int(np.ceil(z.shape[0] / (4 * MAX_ROWS)))
    z, runs = z[::step], runs[::step]
    return float(np.median([np.percentile(nearest(z[runs == k], z[runs != k]), SPACING_PERCENTILE) for k in labels]))


class DataDistance:
    """Distance of rows ``(u, du/dt[, y])`` to the training rows, in radii, and the training ranges.

    Examples
    --------
    >>> t = np.arange(0, 20, 0.04)
    >>> dist = DataDistance().fit(input_rows(np.sin(t), 0.04))
    >>> d = dist.distance(input_rows(3 * np.sin(t), 0.04))
    >>> bool(d.max() > 10 and dist.distance(input_rows(np.sin(t), 0.04)).max() < 1)
    True
    """

    def __init__(self, max_rows: int = MAX_ROWS):
        self.max_rows = max_rows

    def fit(self, rows: ArrayLike, runs: ArrayLike | None = None) -> DataDistance:
        """``rows`` of the training data; ``runs`` (one label per row) the run each row comes from: a
        row is then outside only where it is farther from the training rows than one training run lies
        from the others (``spacing_``, in radii), so a run between two trained ones (an amplitude or
        a rate between theirs) is inside."""
        x = np.asarray(rows, dtype=float)
        if x.ndim != 2 or x.shape[0] < 2 or not np.all(np.isfinite(x)):
            raise DataError(f"DataDistance needs finite rows of shape (n >= 2, n_features); got {np.shape(x)}.")
        self.low_, self.high_ = x.min(axis=0), x.max(axis=0)
        self.mean_, self.std_, self.rows_, radius = scaled_rows(x, self.max_rows)
        self.radius_ = max(radius, 1e-9)
        self.spacing_ = 1.0 if runs is None else _spacing((x - self.mean_) / self.std_, np.asarray(runs)) / self.radius_
        self._fn = None
        return self

    def distance(self, rows: ArrayLike) -> NDArray[np.float64]:
        """Each row's distance to the nearest training row, in radii."""
        self._check_fitted()
        x = np.atleast_2d(np.asarray(rows, dtype=float))
        return nearest((x - self.mean_) / self.std_, self.rows_) / self.radius_

    def spacings(self, rows: ArrayLike, reference: ArrayLike | None = None,
                 distance: ArrayLike | None = None) -> NDArray[np.float64]:
        """Each row's distance to the nearest training row (or ``reference`` row: the data of a model
        fitted on part of the training runs, in the same scaling), in units of the training runs'
        spacing (:meth:`distance` over ``spacing_``, at least one radius): how far a run is from the
        data, measured by how far the training runs lie from each other, the width's yardstick.
        ``distance``: the rows' :meth:`distance`, already computed (to the training rows)."""
        self._check_fitted()
        if reference is None:
            return (self.distance(rows) if distance is None else np.asarray(distance, dtype=float)) / self._unit
        x = (np.atleast_2d(np.asarray(rows, dtype=float)) - self.mean_) / self.std_
        ref = (np.asarray(reference, dtype=float) - self.mean_) / self.std_
        ref = ref[:: int(np.ceil(ref.shape[0] / self.max_rows))]
        return nearest(x, ref) / (self.radius_ * self._unit)

    @property
    def _unit(self) -> float:
        return max(1.0, float(getattr(self, "spacing_", 1.0)))

    def outside(self, rows: ArrayLike, distance: ArrayLike | None = None) -> NDArray[np.bool_]:
        """True where a row leaves the training range of any feature (input, rate, output; by more
        than 1 % of the range) or is more than :data:`OUTSIDE_RADII` radii from every training row."""
        x = np.atleast_2d(np.asarray(rows, dtype=float))
        d = self.distance(x) if distance is None else np.asarray(distance, dtype=float)
        margin = RANGE_MARGIN * np.maximum(self.high_ - self.low_, 1e-12)
        return np.any((x < self.low_ - margin) | (x > self.high_ + margin), axis=1) | (d > self._far)

    @property
    def _far(self) -> float:
        """Radii beyond which a row is outside: :data:`OUTSIDE_RADII`, or the training runs' spacing."""
        return max(OUTSIDE_RADII, float(getattr(self, "spacing_", 1.0)))

    def function(self) -> ca.Function:
        """``Function('data_distance', [v], [d, outside])``: :meth:`distance` and :meth:`outside` of
        one row ``v`` (``outside`` 1 or 0), for an export."""
        if getattr(self, "_fn", None) is None:
            self._check_fitted()
            v = ca.SX.sym("v", self.rows_.shape[1])
            d = ca.sqrt(nearest_squared(v, self.mean_, self.std_, self.rows_)) / self.radius_
            margin = RANGE_MARGIN * np.maximum(self.high_ - self.low_, 1e-12)
            out = d > self._far
            for i in range(v.numel()):
                out = ca.logic_or(out, ca.logic_or(v[i] < self.low_[i] - margin[i], v[i] > self.high_[i] + margin[i]))
            self._fn = ca.Function("data_distance", [v], [d, out, d / self._unit], ["v"],
                                   ["d", "outside", "spacings"])
        return self._fn

    def to_dict(self) -> dict:
        self._check_fitted()
        return {"max_rows": self.max_rows, "low": self.low_.tolist(), "high": self.high_.tolist(), "mean": self.mean_.tolist(),
                "std": self.std_.tolist(), "radius": self.radius_, "spacing": self.spacing_,
                "rows": np.round(self.rows_, 7).tolist()}

    @classmethod
    def from_dict(cls, d: dict) -> DataDistance:
        out = cls(int(d["max_rows"]))
        out.low_, out.high_ = np.asarray(d["low"], dtype=float), np.asarray(d["high"], dtype=float)
        out.radius_, out.spacing_ = float(d["radius"]), float(d.get("spacing", 1.0))  # older files: none
        out.mean_, out.std_ = np.asarray(d["mean"], dtype=float), np.asarray(d["std"], dtype=float)
        out.rows_, out._fn = np.asarray(d["rows"], dtype=float), None
        return out

    def _check_fitted(self) -> None:
        if not hasattr(self, "rows_"):
            raise NotFittedError("This DataDistance is not fitted yet. Call fit(rows) first.")
