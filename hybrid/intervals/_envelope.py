"""Where a run lies among the training runs as a whole: its input's amplitude and rate.

A sample-by-sample distance cannot see a run traced ten times slower than any training run: each of
its samples has an input, a rate and an output that some training sample had. Hysteresis that
depends on rate (a piezo's loop doubles from 1 Hz to 0.01 Hz) or on amplitude does: the run as a
whole lies outside the training runs. :class:`Envelope` holds the training runs' amplitudes and rates
(on a log scale); a run beyond them is outside, and its band widens with how far, in units of the
spread of the training runs themselves, the same yardstick for the held-out runs that calibrate
the band and for a new run.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["Envelope", "run_features", "FEATURES", "MARGIN"]

#: The run-level features, in order: the input's range (1st to 99th percentile) and its typical rate
#: (median |du/dt| over the samples where it moves).
FEATURES = ("amplitude", "rate")
#: A run whose amplitude or rate lies beyond the training runs' by more than this factor is outside them.
MARGIN = 1.25
#: The smallest spread of a feature over the training runs, as a factor: one run, or runs of one
#: amplitude, still measure a run twice as fast as one such spread beyond.
LEAST_SPREAD = 2.0


def run_features(u: ArrayLike, dt: float) -> NDArray[np.float64]:
    """``log(amplitude), log(rate)`` of an input path sampled at ``dt`` (see :data:`FEATURES`)."""
    u = np.asarray(u, dtype=float).ravel()
    lo, hi = np.percentile(u, [1, 99]) if u.size else (0.0, 0.0)
    amplitude = float(hi - lo)
    tiny = 1e-300
    steps = np.abs(np.diff(u)) / float(dt)
    moving = steps[steps > 1e-9 * max(amplitude, tiny) / float(dt)]
    rate = float(np.median(moving)) if moving.size else 0.0
    return np.log([max(amplitude, tiny), max(rate, tiny)])


@dataclass
class Envelope:
    """The training runs' range of each feature (``low``, ``high``, logs) and its yardstick ``unit``
    (the log spread of the training runs, at least ``log LEAST_SPREAD``)."""

    low: NDArray[np.float64]
    high: NDArray[np.float64]
    unit: NDArray[np.float64]

    @classmethod
    def fit(cls, runs: Sequence, unit: NDArray | None = None) -> "Envelope":
        """From training runs (``Trajectory``); ``unit`` another envelope's (a fold's runs measured with
        the whole training set's yardstick)."""
        f = np.array([run_features(r.u, r.dt) for r in runs])
        low, high = f.min(axis=0), f.max(axis=0)
        own = np.maximum(high - low, np.log(LEAST_SPREAD))
        return cls(low, high, own if unit is None else np.asarray(unit, dtype=float))

    def beyond(self, u: ArrayLike, dt: float) -> NDArray[np.float64]:
        """Per feature, how far the run's lies beyond the training runs' range (0 inside, within
        :data:`MARGIN`), in units of ``unit``."""
        return self._beyond(run_features(u, dt))

    def _beyond(self, f: NDArray) -> NDArray[np.float64]:
        m = np.log(MARGIN)
        return np.maximum(np.maximum(f - self.high - m, self.low - m - f), 0.0) / self.unit

    def distance(self, u: ArrayLike, dt: float) -> float:
        """The run's distance beyond the training runs: the sum of :meth:`beyond` over the features."""
        return float(np.sum(self.beyond(u, dt)))

    def describe(self, u: ArrayLike, dt: float) -> str | None:
        """``"rate 0.27 (training runs 2.6-27)"`` for each feature beyond the training runs; None inside."""
        f, out = run_features(u, dt), []
        for name, b, v, lo, hi in zip(FEATURES, self._beyond(f), f, self.low, self.high):
            if b > 0:
                out.append(f"{name} {np.exp(v):.3g} (training runs {np.exp(lo):.3g}-{np.exp(hi):.3g})")
        return ", ".join(out) or None

    def to_dict(self) -> dict:
        return {"features": list(FEATURES), "low": self.low.tolist(), "high": self.high.tolist(),
                "unit": self.unit.tolist()}

    @classmethod
    def from_dict(cls, d: dict | None) -> "Envelope | None":
        if not d:
            return None
        return cls(*(np.asarray(d[k], dtype=float) for k in ("low", "high", "unit")))
