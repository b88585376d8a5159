"""Constant-curvature kinematics: a bending angle to the tip's position in the bending plane."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from ._block import AbstractBlock, Parameter
from ._errors import PhysicsError

#: The coordinates an :class:`Arc` can output, in the order it computes them.
ARC_OUTPUTS = ("angle", "x", "y")


def _sinc(t):
    """``sin(t) / t``, 1 at 0 (its Taylor series near 0, where the quotient loses its digits)."""
    return ca.if_else(ca.fabs(t) < 1e-4, 1 - t * t / 6, ca.sin(t) / t)


class Arc(AbstractBlock):
    """A continuum robot's section as a constant-curvature arc: the tip's angle in, its position out.

    The section leaves its base at ``(base_x, base_y)`` pointing along ``heading`` and bends at
    constant curvature to the tip, whose angle (in the bending plane) is the block's input; the
    tip's angle is ``base_angle`` where the section is straight. With ``theta = angle - base_angle``
    (radians) the tip lies at::

        x = base_x + length (cos(h) S - sin(h) C)
        y = base_y + handed length (sin(h) S + cos(h) C)

    where ``h = heading``, ``S = sin(theta) / theta`` and ``C = (1 - cos(theta)) / theta``: the
    arc's chord, turned by the base's heading. The angle and the position may come from different
    instruments, so the angle's zero (``base_angle``) and the base's direction in the position's
    frame (``heading``) are two parameters. ``handed = -1`` (``mirrored=True``) is a position frame
    turned over (a tracker's ``y`` axis pointing the other way), in which the tip turns clockwise
    as its angle grows.

    Parameters
    ----------
    length : float
        Arc length of the section, in the position's unit.
    base_x, base_y : float
        The base's position, in the position's unit.
    base_angle : float
        The angle the tip has when the section is straight, in the input's unit.
    heading : float
        The straight section's direction in the position's frame, in the input's unit.
    outputs : tuple of {"angle", "x", "y"}, default ("angle", "x", "y")
        What the block outputs, in this order: the angle it was given (so a model of the angle and
        the position reads one state) and either coordinate.
    mirrored : bool, default False
        The position frame's handedness (above).
    angle_unit : {"deg", "rad"}, default "deg"
        The unit of the input angle and of ``base_angle``.
    angle_range : (float, float) or None
        The angles the arc was fitted on (set by identification): where an inverse looks for the angle
        that puts the tip at a wanted coordinate (a coordinate along the heading is the same at a bend
        either way). None: half a turn either side of the straight section.

    Examples
    --------
    >>> import numpy as np
    >>> from physics import Series, LinearMap, Arc
    >>> model = Series(LinearMap(gain=90.0, offset=0.0), Arc(length=50.0, base_x=0.0, base_y=0.0,
    ...                                                        base_angle=0.0, heading=0.0), dt=0.04)
    >>> np.round(model.simulate(np.array([0.0, 1.0])), 6)  # straight, then a quarter circle
    array([[ 0.      , 50.      ,  0.      ],
           [90.      , 31.830989, 31.830989]])
    """

    name = "arc"
    rank = 7  # reads the output's angle: after the output map and a drift of it

    parameters = (
        Parameter("length", 50.0, 1e-9, 1e9, "position unit", "arc length of the section", scaling=(0, 1)),
        Parameter("base_x", 0.0, -1e9, 1e9, "position unit", "base position, x", scaling=(0, 1)),
        Parameter("base_y", 0.0, -1e9, 1e9, "position unit", "base position, y", scaling=(0, 1)),
        Parameter("base_angle", 0.0, -1e4, 1e4, "angle unit", "tip angle of the straight section", scaling=(1, 0)),
        Parameter("heading", 0.0, -1e4, 1e4, "angle unit", "the straight section's direction in the "
                  "position's frame", scaling=(1, 0)),
    )
    selectable = False

    def __init__(self, length: float | None = None, base_x: float | None = None, base_y: float | None = None,
                 base_angle: float | None = None, heading: float | None = None, outputs=ARC_OUTPUTS,
                 mirrored: bool = False, angle_unit: str = "deg", angle_range=None):
        self._init_parameters({"length": length, "base_x": base_x, "base_y": base_y, "base_angle": base_angle,
                               "heading": heading})
        outputs = (outputs,) if isinstance(outputs, str) else tuple(outputs)
        if not outputs or any(o not in ARC_OUTPUTS for o in outputs) or len(set(outputs)) != len(outputs):
            raise PhysicsError(f"An Arc's outputs must be distinct names among {', '.join(ARC_OUTPUTS)}. "
                               f"Got {outputs!r} instead.")
        if angle_unit not in ("deg", "rad"):
            raise PhysicsError(f"An Arc's angle_unit must be 'deg' or 'rad'. Got {angle_unit!r} instead.")
        if angle_range is not None:
            lo, hi = (float(v) for v in angle_range)
            if not (np.isfinite(lo) and np.isfinite(hi) and lo <= hi):
                raise PhysicsError(f"An Arc's angle_range must be (low, high), finite, or None. Got {angle_range!r}.")
            angle_range = [lo, hi]
        self.outputs = outputs
        self.mirrored = bool(mirrored)
        self.angle_unit = angle_unit
        self.angle_range = angle_range

    @property
    def output_size(self) -> int:
        return len(self.outputs)

    def output_scale(self, s_in, s_y):
        return s_y

    def position(self, angle, p):
        """``(x, y)`` of the tip at ``angle`` (symbolic or numbers) for parameters ``p``."""
        to_rad = math.pi / 180.0 if self.angle_unit == "deg" else 1.0
        theta = (angle - p[3]) * to_rad
        psi = p[4] * to_rad
        s, c = _sinc(theta), ca.sin(theta / 2) * _sinc(theta / 2)
        handed = -1.0 if self.mirrored else 1.0
        return (p[1] + p[0] * (ca.cos(psi) * s - ca.sin(psi) * c),
                p[2] + handed * p[0] * (ca.sin(psi) * s + ca.cos(psi) * c))

    def output_guess(self, index: int, y, p, points: int = 73):
        """The angle whose coordinate ``self.outputs[index]`` is nearest ``y`` on a grid of ``points`` over the
        fitted angles and a quarter of their span beyond (``angle_range``; else half a turn either side of
        the straight section): an inverse's start (the angle output: ``y`` itself)."""
        role = self.outputs[index]
        if role == "angle":
            return y
        if self.angle_range is not None:
            lo, hi = self.angle_range
            grid = [ca.DM(a) for a in np.linspace(lo - (hi - lo) / 4, hi + (hi - lo) / 4, points)]
        else:
            half = 180.0 if self.angle_unit == "deg" else math.pi
            grid = [p[3] + a for a in np.linspace(-half, half, points)]
        best, best_err = grid[0], ca.inf
        for a in grid:
            err = ca.fabs(self.position(a, p)["xy".index(role)] - y)
            best, best_err = ca.if_else(err < best_err, a, best), ca.fmin(err, best_err)
        return best

    def step(self, x, u, p, dt):
        x_pos, y_pos = self.position(u, p)
        values = {"angle": u, "x": x_pos, "y": y_pos}
        return ca.DM.zeros(0, 1), ca.vertcat(*(values[o] for o in self.outputs))

    def describe(self, dt):
        return (f"arc length {self.length:.4g}, base ({self.base_x:.4g}, {self.base_y:.4g}) heading "
                f"{self.heading:.4g} {self.angle_unit}, straight at {self.base_angle:.4g} {self.angle_unit}"
                f"{', mirrored' if self.mirrored else ''}")


def arc_points(angle, length: float, base_x: float, base_y: float, base_angle: float, heading: float,
               mirrored: bool = False, angle_unit: str = "deg", samples: int = 20001) -> np.ndarray:
    """The tip of a constant-curvature arc found by integrating its tangent along its length
    (trapezoids over ``samples`` points): a check of :class:`Arc`'s closed form that shares no formula
    with it. Returns ``(len(angle), 2)``."""
    to_rad = math.pi / 180.0 if angle_unit == "deg" else 1.0
    s = np.linspace(0.0, length, samples)
    out = []
    for a in np.atleast_1d(np.asarray(angle, dtype=float)):
        direction = heading * to_rad + (a - base_angle) * to_rad * s / length
        x = base_x + np.trapezoid(np.cos(direction), s)
        y = np.trapezoid(np.sin(direction), s)
        out.append((x, base_y + (-y if mirrored else y)))
    return np.array(out)
