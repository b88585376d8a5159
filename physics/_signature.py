"""How discovery recognises a block's effect in a model's residual: declared by the block, numpy only.

A block that discovery may add declares a :class:`Signature`: the family of
effects it competes in, the generic library terms of that family, and, for a
block whose residual shape has a parameter, a grid and the exact shapes over
it (numpy, so a grid of hundreds costs one pass over the data). The shapes
follow the block's CasADi ``step`` and are checked against it in
``tests/identification/test_discover_signatures.py``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

__all__ = ["Signature", "Estimate", "direction", "since_reversal"]

#: How a shape enters the residual fit: with a coefficient of one times the
#: model's gain ("fixed"), with one free coefficient ("free"), or through the
#: family's own library terms with free coefficients ("linear").
SCALES = ("fixed", "free", "linear")
#: Which internal signal of the model a new block sees: the command after the
#: model's lag and delay ("drive"), after its backlash ("hysteresis"), or after
#: its hysteresis ("static").
SIGNALS = ("drive", "hysteresis", "static")


@dataclass(frozen=True)
class Estimate:
    """What a residual fit gives to turn a shape into first parameter estimates."""

    coef: np.ndarray  # fitted coefficients (one per shape, or one per library term)
    grid: dict | None  # the best grid point, None for "linear" signatures
    gain: float  # output units per input unit at the model's static map
    center: float  # centre and half-range of the static map's input
    half: float
    dt: float


@dataclass(frozen=True)
class Signature:
    """A block's discovery signature (see the module docstring).

    Attributes
    ----------
    family : str
        Effects of one family share library terms and compete for one step.
    terms : tuple of str
        Names of discovery's generic library terms that signal the family
        (``"dv/dt"``, ``"sgn(dv)"``, ``"x^2"``, ``"t"``, ...); may be empty.
    estimate : callable
        ``Estimate -> (parameters, settings)`` of the new block, or None when
        the fit gives no usable block.
    describe : callable
        ``(parameters, settings) -> str``: the candidate in words.
    scale : str
        One of :data:`SCALES`.
    signal : str
        One of :data:`SIGNALS`.
    grid : callable, optional
        ``(dt, span) -> list of dict``: parameter grid of the shapes, for a step ``dt`` (s)
        and the drive's range ``span``; a grid that takes a third argument also gets the
        longest trajectory's ``duration`` (s).
    shapes : callable, optional
        ``(v, dt, grid) -> array (n, len(grid))``: what adding the block
        changes in the output along the signal ``v``, for each grid point.
    build : callable, optional
        ``(parameters, settings, max_step) -> block``; default: the block's
        class called with the parameters and those settings it takes.
    positive : bool
        ``"free"`` scale only: the shape counts only with a coefficient of the
        sign of the model's gain (a creep draws the output towards where the
        input has been, never away from it).
    timescale : str, optional
        The grid key of a time in seconds that the effect keeps whatever the
        speed of the input (a creep's time constant). Discovery then names the
        effect only if it shows within each run (each run's own offset and
        gain projected out: a slow mode at a steady start is otherwise just a
        per-run offset) and if the best time fitted on each run alone does not
        follow the runs' own time scales (a rate-independent loop, seen on runs
        of one shape at several speeds, looks like a relaxation whose time
        constant scales with each run's duration).
    """

    family: str
    terms: tuple[str, ...]
    estimate: Callable[[Estimate], tuple[dict, dict] | None]
    describe: Callable[[dict, dict], str]
    scale: str = "fixed"
    signal: str = "drive"
    grid: Callable[[float, float], list[dict]] | None = None
    shapes: Callable[[np.ndarray, float, list[dict]], np.ndarray] | None = None
    build: Callable | None = None
    positive: bool = False
    timescale: str | None = None

    def __post_init__(self) -> None:
        if self.scale not in SCALES:
            raise ValueError(f"Signature scale must be one of {', '.join(SCALES)}. Got {self.scale!r} instead.")
        if self.signal not in SIGNALS:
            raise ValueError(f"Signature signal must be one of {', '.join(SIGNALS)}. Got {self.signal!r} instead.")
        if (self.scale == "linear") != (self.shapes is None) or (self.grid is None) != (self.shapes is None):
            raise ValueError("A 'linear' signature has neither grid nor shapes; any other has both.")
        if self.positive and self.scale != "free":
            raise ValueError(f"Only a 'free' signature can be positive. Got scale {self.scale!r}.")


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
