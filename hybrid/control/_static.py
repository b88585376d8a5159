"""The model at rest: its output for an input held from the start, and the input for an output."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from hybrid.export._model import ExportedModel

__all__ = ["rest_output", "input_for"]


def rest_output(model: ExportedModel, u0: float | ArrayLike) -> float:
    """The model's first output of a run that starts at ``u0`` (the robot at rest there);
    ``u0`` is ``[command, *measured]`` for a model that reads measured inputs."""
    return float(model.step(model.x0(u0), u0)[1])


def input_for(model: ExportedModel, y0: float, bounds, measured: ArrayLike = ()) -> float:
    """The command within ``bounds`` whose rest output is ``y0`` (bisection; the nearer bound if out of
    reach), the ``measured`` inputs held."""
    measured = np.asarray(measured, dtype=float).ravel()

    def gap(u: float) -> float:
        return rest_output(model, np.r_[u, measured]) - y0

    lo, hi = bounds
    f_lo, f_hi = gap(lo), gap(hi)
    if f_lo * f_hi > 0:  # out of reach: the nearer bound
        return lo if abs(f_lo) < abs(f_hi) else hi
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        f_mid = gap(mid)
        lo, f_lo, hi = (mid, f_mid, hi) if f_mid * f_lo > 0 else (lo, f_lo, mid)
    return 0.5 * (lo + hi)
