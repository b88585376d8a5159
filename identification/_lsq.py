"""Exact fit of ``preisach+linear``: the output is linear in the relay weights.

Given the input path, each relay's state is known, so with ``R`` the relay
states (n x m), ``y = gain (lower + (upper - lower) R w) + offset``. With
``v = gain (upper - lower) w`` and ``c = gain lower + offset`` this is
``y = c + R v`` with all ``v`` of one sign, a bounded linear least-squares
problem (``scipy.optimize.lsq_linear``, exact) instead of a bilinear NLP; the
weights are ``v / sum(v)`` (summing to 1) and the gain ``sum(v) / (upper - lower)``.
"""

from __future__ import annotations

import time

import casadi as ca
import numpy as np
from scipy.optimize import lsq_linear

from physics import LinearMap, Preisach, Series

from ._checks import Record


def applies(model: Series, free: np.ndarray, x0) -> bool:
    """True for ``preisach+linear`` with every parameter free and a steady start."""
    blocks = model.blocks
    return (len(blocks) == 2 and isinstance(blocks[0], Preisach)
            and isinstance(blocks[1], LinearMap) and bool(np.all(free))
            and isinstance(x0, str) and x0 == "steady")


def relay_states(block: Preisach, u: np.ndarray, dt: float) -> np.ndarray:
    """(n, m) relay states after each sample, from the steady state at ``u[0]``."""
    alone = Series(block, dt=dt)
    p = alone.params
    x0 = alone.steady_state(u[0], p)
    xs, _ = alone.rollout(u.size)(x0, ca.DM(u[None, :]), p)
    return np.asarray(xs, dtype=float).T


def fit(model: Series, records: list[Record]):
    """Parameters, residuals, Jacobian (physical units) and solver info."""
    t0 = time.perf_counter()
    pre: Preisach = model.blocks[0]
    span = pre.upper - pre.lower
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
    offset = c - gain * pre.lower
    p = np.r_[weights, gain, offset]
    resid = A @ best.x - y
    # d y / d (w, gain, offset)
    J = np.column_stack([gain * span * R, pre.lower + span * R @ weights, np.ones(len(y))])
    info = {"status": f"lsq_linear: {best.message}", "success": bool(best.status > 0),
            "iterations": int(best.nit), "wall_time_s": time.perf_counter() - t0}
    return p, resid, J, info
