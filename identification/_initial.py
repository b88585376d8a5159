"""Physics-based initial guesses and the extra starting points of a multi-start fit.

Poor starting points land IPOPT in wrong local minima (a near-zero time
constant, a flipped loop), so the first start is built from the data:

1. a straight line ``y = a u + b`` through all samples gives the output map's
   gain and offset;
2. the loop width is the mean gap between the falling and the rising branches
   at the same input (signed: positive when the output lags), divided by ``a``
   to get it in input units; it sets the backlash width and the Bouc-Wen
   saturation ``|z| = (A / (beta + gamma))^(1/n)`` (shared when both exist);
3. a small grid over what the line cannot tell, which each block declares
   (``AbstractBlock.initial_grid``: the lag's time constant, the Bouc-Wen
   initial slope ``A`` and saturation, the backlash width), is scored by
   simulating with the output map's gain and offset eliminated by linear least
   squares (variable projection), together with the model's own current values;
   the best point starts IPOPT.
"""

from __future__ import annotations

import itertools

import casadi as ca
import numpy as np

from physics import DataSummary, Series

from ._checks import Record, signal_scale
from ._problem import initial_state_exprs
from ._sensitivity import plain_rollout

#: Samples used to score grid points (each trajectory truncated proportionally).
SCORE_SAMPLES = 6000
#: Most grid points scored.
MAX_GRID = 120


def line_fit(records: list[Record]) -> tuple[float, float]:
    """Least-squares ``y = a u + b`` through all samples."""
    u = np.concatenate([r.u for r in records])
    y = np.concatenate([r.y for r in records])
    if np.ptp(u) == 0:
        return 1.0, float(np.mean(y))
    a, b = np.polyfit(u, y, 1)
    return float(a), float(b)


def loop_width(records: list[Record], bins: int = 20) -> float:
    """Mean (falling - rising) output gap at equal input, in output units (0 if none)."""
    u = np.concatenate([r.u for r in records])
    y = np.concatenate([r.y for r in records])
    du = np.concatenate([np.gradient(r.u) for r in records])
    if np.ptp(u) == 0:
        return 0.0
    edges = np.quantile(u, np.linspace(0, 1, bins + 1))
    which = np.clip(np.searchsorted(edges, u, side="right") - 1, 0, bins - 1)
    gaps = []
    for k in range(bins):
        rise = y[(which == k) & (du > 0)]
        fall = y[(which == k) & (du < 0)]
        if rise.size >= 3 and fall.size >= 3:
            gaps.append(np.mean(fall) - np.mean(rise))
    return float(np.median(gaps)) if gaps else 0.0


def affine_indices(model: Series) -> list[tuple[int, int, int]]:
    """``(block, gain, offset)`` indices of each block whose output is ``gain * u + offset``: the
    block's place in ``model.blocks`` and its two parameters' in ``model.params``."""
    offsets = np.cumsum([0] + [blk.n_p for blk in model.blocks])
    out = []
    for i, blk in enumerate(model.blocks):
        if blk.affine_output is not None:
            own = [par.name for par in blk.parameters]
            ig, io = (int(offsets[i]) + own.index(k) for k in blk.affine_output)
            out.append((i, ig, io))
    return out


def _block_candidates(block, names: list[str], free: dict[str, bool], data: DataSummary,
                      current: dict[str, float]) -> list[dict[str, float]]:
    """The block's own starting grid, with its parameters' full names."""
    own = [p.name for p in block.parameters]
    full = dict(zip(own, names))
    grid = block.initial_grid(data, {k: current[full[k]] for k in own}, {k: free[full[k]] for k in own})
    return [{full[k]: v for k, v in point.items()} for point in grid]


class _Scorer:
    """Sum of squared output errors for full parameter vectors, on truncated data."""

    def __init__(self, model: Series, records: list[Record], p_base: np.ndarray):
        total = sum(r.n for r in records)
        keep = min(1.0, SCORE_SAMPLES / total)
        P = ca.MX.sym("p", model.n_p)
        outs, ys, cache = [], [], {}
        x0s = initial_state_exprs(model, [r.u[0] for r in records], P, p_base)
        for r, x0 in zip(records, x0s):
            n = max(int(r.n * keep), min(r.n, 20))
            if n not in cache:
                cache[n] = plain_rollout(model, n)
            _, y = cache[n](x0, ca.DM(r.u[None, :n]), P)
            outs.append(y.T)
            ys.append(r.y[:n])
        self.f = ca.Function("score", [P], [ca.vertcat(*outs)])
        self.y = np.concatenate(ys)

    def all(self, points: list[np.ndarray], project: tuple[int, int] | None) -> list[tuple[float, np.ndarray]]:
        """``(cost, parameters)`` of each point, its outputs simulated in one call (``Function.map``: the
        same numbers as one call per point, a third less time over a starting grid)."""
        qs = [p.copy() for p in points]
        if project is not None:
            ig, io = project
            for q in qs:
                q[ig], q[io] = 1.0, 0.0
        outs = np.asarray(self.f.map(len(qs))(np.column_stack(qs)), dtype=float)
        return [self._cost(p, q, outs[:, j], project) for j, (p, q) in enumerate(zip(points, qs))]

    def _cost(self, p, q, s, project):
        if project is None:
            return float(np.sum((s - self.y) ** 2)), p
        if not np.all(np.isfinite(s)):
            return np.inf, p
        ig, io = project
        A = np.column_stack([s, np.ones_like(s)])
        coef, *_ = np.linalg.lstsq(A, self.y, rcond=None)
        q[ig], q[io] = coef
        return float(np.sum((A @ coef - self.y) ** 2)), q


def initial_guess(model: Series, records: list[Record], free: np.ndarray,
                  p_base: np.ndarray, bounds=None) -> np.ndarray:
    """A physics-based starting point (see the module docstring), within ``bounds`` (default the model's)."""
    names = model.param_names
    lo, hi = bounds if bounds is not None else (model.lower_bounds, model.upper_bounds)
    p = np.asarray(p_base, dtype=float).copy()
    is_free = dict(zip(names, free))
    a, b = line_fit(records)
    width_u = loop_width(records) / a if a != 0 else 0.0
    offsets = np.cumsum([0] + [blk.n_p for blk in model.blocks])
    project = None
    for i, ig, io in affine_indices(model):
        if is_free[names[ig]]:
            p[ig] = a
        if is_free[names[io]]:
            p[io] = b
        if i == len(model.blocks) - 1 and free[ig] and free[io]:
            project = (ig, io)
    p = np.clip(p, lo, hi)
    hysteretic = [blk for blk in model.blocks if blk.takes_loop_width]
    u_all = np.concatenate([r.u for r in records])
    data = DataSummary(a, b, width_u, 1.0 / max(len(hysteretic), 1), signal_scale([r.u for r in records]),
                       0.5 * float(u_all.min() + u_all.max()), float(model.dt))
    current = dict(zip(names, p))
    grids = [c for i, blk in enumerate(model.blocks)
             if (c := _block_candidates(blk, names[offsets[i]:offsets[i + 1]], is_free, data, current))]
    if not grids and project is None:
        return p
    points = list(itertools.product(*grids))
    if len(points) > MAX_GRID:
        pick = np.random.default_rng(0).choice(len(points), MAX_GRID, replace=False)
        points = [points[k] for k in sorted(pick)]
    points.insert(0, ())  # the model's own values compete too (a caller's informed start)
    starts = []
    for point in points:
        q = p.copy()
        for part in point:
            for name, value in part.items():
                q[names.index(name)] = value
        starts.append(np.clip(q, lo, hi))
    best, best_p = np.inf, p
    for cost, q in _Scorer(model, records, p).all(starts, project):
        if cost < best:
            best, best_p = cost, q
    return np.clip(best_p, lo, hi)


def perturbed(p: np.ndarray, free: np.ndarray, lo: np.ndarray, hi: np.ndarray,
              rng: np.random.Generator, typical: np.ndarray | None = None) -> np.ndarray:
    """A random start near ``p`` within the bounds: positive parameters scaled by a
    log-uniform factor in [1/3, 3], others moved by up to half their size (at least a
    tenth of their ``typical`` magnitude, default 1)."""
    typical = np.ones_like(p) if typical is None else typical
    q = p.copy()
    for k in np.flatnonzero(free):
        if lo[k] >= 0 and p[k] > 0:
            q[k] = p[k] * np.exp(rng.uniform(np.log(1 / 3), np.log(3)))
        else:
            q[k] = p[k] + rng.uniform(-0.5, 0.5) * max(abs(p[k]), 0.1 * typical[k])
    return np.clip(q, lo, hi)
