"""Features of an input path and the exact residual shapes of the blocks a model may miss.

Each ``*_shapes`` function is what adding that block (lag, delay, backlash,
Bouc-Wen) would change in the output, for a grid of its parameters, in numpy so
that a grid of hundreds costs one pass over the data. They follow the blocks'
CasADi equations (``physics``) and are checked against them in
``tests/test_discover_signatures.py``.
"""

from __future__ import annotations

import numpy as np

__all__ = ["direction", "since_reversal", "lag_shapes", "delay_shapes", "backlash_shapes", "boucwen_shapes"]


def direction(v: np.ndarray) -> np.ndarray:
    """Sign of the motion of ``v``; held through rests; the first move fills the start."""
    s = np.sign(np.diff(v, prepend=v[0]))
    idx = np.where(s != 0, np.arange(s.size), 0)
    np.maximum.accumulate(idx, out=idx)
    s = s[idx]
    first = np.flatnonzero(s != 0)
    if first.size:
        s[: first[0]] = s[first[0]]
    return s


def since_reversal(v: np.ndarray) -> np.ndarray:
    """Distance ``|v - v_rev|`` travelled since the last reversal (or the start)."""
    s = direction(v)
    start = np.r_[True, s[1:] != s[:-1]]
    # the reversal point is the sample before the direction changes
    anchor = np.where(start, np.arange(v.size) - 1, 0).clip(min=0)
    anchor[0] = 0
    idx = np.where(start, np.arange(v.size), 0)
    np.maximum.accumulate(idx, out=idx)
    return np.abs(v - v[anchor[idx]])


def lag_shapes(v: np.ndarray, dt: float, taus: np.ndarray) -> np.ndarray:
    """``LF_T(v) - v`` for each time constant: the exact first-order-hold lag of the block."""
    a = np.exp(-dt / taus)
    g = 1 - (taus / dt) * (1 - a)
    x = np.full(taus.size, v[0])
    out = np.empty((v.size, taus.size))
    prev = v[0]
    for k, uk in enumerate(v):
        x = a * x + (1 - a) * prev + g * (uk - prev)
        prev = uk
        out[k] = x
    return out - v[:, None]


def delay_shapes(v: np.ndarray, dt: float, delays: np.ndarray) -> np.ndarray:
    """``v(t - d) - v(t)`` for each delay (linear interpolation; ``v[0]`` before the start)."""
    t = np.arange(v.size) * dt
    return np.stack([np.interp(t - d, t, v, left=v[0]) for d in delays], axis=1) - v[:, None]


def backlash_shapes(v: np.ndarray, widths: np.ndarray) -> np.ndarray:
    """``P_w(v) - v`` for each total width: the sharp play operator, centred at rest."""
    y = np.full(widths.size, v[0])
    half = widths / 2
    out = np.empty((v.size, widths.size))
    for k, uk in enumerate(v):
        y = np.maximum(uk - half, np.minimum(uk + half, y))
        out[k] = y
    return out - v[:, None]


def boucwen_shapes(v: np.ndarray, beta: np.ndarray, gamma: np.ndarray) -> np.ndarray:
    """Bouc-Wen ``-z`` (A = 1, n = 1) for each ``(beta, gamma)``: the block's ``y - u``.

    Along a monotone input step ``dz/dh = s - (beta + s gamma sgn z) z`` is
    linear in ``z`` and is integrated exactly (two halves per sample so that a
    crossing of ``z = 0`` is followed).
    """
    z = np.zeros(beta.size)
    out = np.empty((v.size, beta.size))
    prev = v[0]
    for k, uk in enumerate(v):
        du = uk - prev
        prev = uk
        if du != 0.0:
            s, h = np.sign(du), abs(du) / 2
            for _ in range(2):
                b = beta + s * gamma * np.sign(z)
                safe = np.where(np.abs(b) > 1e-12, b, 1.0)
                zinf = s / safe
                z = np.where(np.abs(b) > 1e-12, zinf + (z - zinf) * np.exp(-safe * h), z + s * h)
        out[k] = -z
    return out
