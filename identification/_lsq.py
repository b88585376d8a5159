"""Exact fit of a weights block then an affine output map (``preisach+linear``).

A block with a linear-weights structure declares ``weight_regressors(u, dt)``
and ``output_range``: its output is ``lower + (upper - lower) R w`` with
weights ``w >= 0`` summing to one and ``R`` (n x m) depending on the input path
only (Preisach's relay states). Then
``y = gain (lower + (upper - lower) R w) + offset``. With
``v = gain (upper - lower) w`` and ``c = gain lower + offset`` this is
``y = c + R v`` with all ``v`` of one sign, a bounded linear least-squares
problem (``scipy.optimize.lsq_linear``, exact) instead of a bilinear NLP; the
weights are ``v / sum(v)`` (summing to 1) and the gain ``sum(v) / (upper - lower)``.
"""

from __future__ import annotations

import time

import numpy as np
from scipy.optimize import lsq_linear

from physics import Series

from ._checks import Record


def applies(model: Series, free: np.ndarray, x0) -> bool:
    """True for a weights block then an affine map, every parameter free and a steady start."""
    blocks = model.blocks
    return (len(blocks) == 2 and callable(getattr(blocks[0], "weight_regressors", None))
            and blocks[1].affine_output == tuple(p.name for p in blocks[1].parameters)
            and bool(np.all(free)) and isinstance(x0, str) and x0 == "steady")


def relay_states(block, u: np.ndarray, dt: float) -> np.ndarray:
    """(n, m) relay states after each sample, from the steady state at ``u[0]``."""
    return block.weight_regressors(u, dt)


def fit(model: Series, records: list[Record]):
    """Parameters, residuals, Jacobian (physical units) and solver info."""
    t0 = time.perf_counter()
    pre = model.blocks[0]
    lower, upper = pre.output_range
    span = upper - lower
    R = np.vstack([relay_states(pre, r.u, model.dt) for r in records])
    y = np.concatenate([r.y for r in records])
    A = np.column_stack([np.ones(len(y)), R])
    m = R.shape[1]
    best = None
    for sign in (1.0, -1.0):
        lb = np.r_[-np.inf, np.zeros(m) if sign > 0 else np.full(m, -np.inf)]
        ub = np.r_[np.inf, np.full(m, np.inf) if sign > 0 else np.zeros(m)]
        res = lsq_linear(A, y, bounds=(lb, ub), method="bvls", tol=1e-12)
        if best is None or res.cost < best.cost:
            best = res
    c, v = best.x[0], best.x[1:]
    total = float(v.sum())
    if total == 0.0:
        weights, gain = np.full(m, 1.0 / m), 0.0
    else:
        weights, gain = np.clip(v / total, 0.0, 1.0), total / span
    offset = c - gain * lower
    p = np.r_[weights, gain, offset]
    resid = A @ best.x - y
    # d y / d (w, gain, offset)
    J = np.column_stack([gain * span * R, lower + span * R @ weights, np.ones(len(y))])
    info = {"status": f"lsq_linear: {best.message}", "success": bool(best.status > 0),
            "iterations": int(best.nit), "wall_time_s": time.perf_counter() - t0}
    return p, resid, J, info
