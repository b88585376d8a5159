"""Backlash (tendon slack): a play operator of width ``width``."""

from __future__ import annotations

import casadi as ca
import numpy as np

from ._block import AbstractBlock, Parameter
from ._traits import BlockTraits
from ._signature import Signature

#: Starting widths tried by identification, as multiples of the data's loop width.
BACKLASH_FACTORS = (0.5, 1.0, 1.5)


def backlash_shapes(v: np.ndarray, widths: np.ndarray) -> np.ndarray:
    """``P_w(v) - v`` for each total width: the sharp play operator, centred at rest."""
    y = np.full(widths.size, v[0])
    half = widths / 2
    out = np.empty((v.size, widths.size))
    for k, uk in enumerate(v):
        y = np.maximum(uk - half, np.minimum(uk + half, y))
        out[k] = y
    return out - v[:, None]


def _ramp(v, s):
    """max(v, 0), or a C2 smooth version of it for s > 0 that is exactly 0 for v <= 0.

    Between 0 and s it is v^3/s^2 - v^4/(2 s^3); above s it is v - s/2, so it lags the
    sharp ramp by at most s/2 and never moves a held output.
    """
    if s == 0:
        return ca.fmax(v, 0)
    cubic = v**3 / s**2 - v**4 / (2 * s**3)
    return ca.if_else(v <= 0, 0, ca.if_else(v >= s, v - s / 2, cubic))


#: What a play's ``start`` parameter means (Backlash and GPI).
START_DOC = "where the play rests in its band at the first input: -1 falling edge, 0 centred, 1 rising edge"


#: Places in the band a play's ``start`` is tried from when fitted (centred, rising, falling edge).
START_GRID = (0.0, 1.0, -1.0)


def start_points(free: dict) -> list[dict]:
    """The starting grid's entries for a play's ``start``: :data:`START_GRID` when it is fitted,
    else one entry that leaves it at its value."""
    return [{"start": s} for s in START_GRID] if free["start"] else [{}]


#: Smoothing of the ramp for an input of unit scale (``Backlash.smoothing=None``).
SMOOTHING = 0.01


class Backlash(AbstractBlock):
    """Play operator: the output stays put until the input has moved ``width``.

    ``y_k = y_{k-1} + ramp(u_k - width/2 - y_{k-1}) - ramp(y_{k-1} - u_k - width/2)``

    with ``ramp(v) = max(v, 0)``, which is ``max(u - w/2, min(u + w/2, y_prev))``.
    ``smoothing`` (input units) > 0 uses a C2 smooth ramp for gradient-based
    fitting that is exactly zero inside the dead band (a held output never
    drifts) and lags the sharp ramp by at most ``smoothing/2``; the smooth
    output stays within ``smoothing/2`` of the sharp one on any path (tested).
    ``smoothing=0`` is the sharp operator; ``None`` (the default) is 1 % of the input's order
    of magnitude, set when the block is fitted (:meth:`for_scale`), 0.01 until then.
    The state is ``y_{k-1}``.

    ``start`` is where the play rests in its band at the first input ``u0`` (its steady state,
    so simulation, identification, export and MPC share it): ``u0 - start * width / 2``. At 0
    it is centred; at 1 it sits at the rising edge, so the output follows a rising input at
    once (a relaxed actuator about to be loaded, as a catheter whose tendon has been slack);
    at -1 at the falling edge. Any place in the band is a rest state; only a run's first
    traverse of the band depends on it. It is held at its value unless asked
    (``identify(..., free=["backlash.start"])``, which tries 0, 1 and -1 as starting points).
    """

    name = "backlash"
    parameters = (
        Parameter("width", 0.3, 0.0, 100.0, "input unit", "total play (dead band)", scaling=(1, 0)),
        Parameter("start", 0.0, -1.0, 1.0, "-", START_DOC, fit=False),
    )
    effect = "backlash"
    rank = 2
    selection_order = 20
    starts = 3  # prone to local minima: multi-start by default
    takes_loop_width = True
    identity = {"width": 0.0}
    signature = Signature(
        family="reversal", terms=("sgn(dv)", "sgn(dv)*exp(-d/w)"),
        grid=lambda dt, span: [{"width": float(g)} for g in np.geomspace(0.003, 0.5, 48) * span],
        shapes=lambda v, dt, grid: backlash_shapes(v, np.array([g["width"] for g in grid])),
        estimate=lambda e: (dict(e.grid), {}),
        describe=lambda p, s: f"width {p['width']:.3g}",
    )

    def __init__(self, width: float | None = None, smoothing: float | None = None, start: float | None = None):
        self._init_parameters({"width": width, "start": start})
        if smoothing is not None and not smoothing >= 0:
            raise ValueError(f"Backlash smoothing must be >= 0 (or None). Got {smoothing} instead.")
        self.smoothing = None if smoothing is None else float(smoothing)
        if self.smoothing == 0.0:  # a sharp play: its output has corners in the input
            self.traits = BlockTraits.of(Backlash, smooth_in_input=False)

    @property
    def _smoothing(self) -> float:
        return SMOOTHING if self.smoothing is None else self.smoothing

    def for_scale(self, s_in):
        return self if self.smoothing is not None else self.with_settings(smoothing=SMOOTHING * s_in)

    @property
    def state_names(self):
        return ("position",)

    def step(self, x, u, p, dt):
        half, s = p[0] / 2, self._smoothing
        y = x[0] + _ramp(u - half - x[0], s) - _ramp(x[0] - u - half, s)
        return y, y

    def steady_state(self, u0, p):
        return ca.vertcat(u0 - p[1] * p[0] / 2)

    continuous_states = ("position",)

    def derivative(self, xc, u, udot, p):
        # the output follows the input only where the play is taken up, in the
        # direction of motion; a smooth switch (the smooth ramp's slope) for s > 0
        half, s = p[0] / 2, self._smoothing
        def engaged(v):
            if s == 0:
                return ca.if_else(v >= 0, 1, 0)
            return ca.if_else(v <= 0, 0, ca.if_else(v >= s, 1, 3 * v**2 / s**2 - 2 * v**3 / s**3))
        up = ca.if_else(udot > 0, 1, 0)
        ydot = udot * (up * engaged(u - half - xc[0]) + (1 - up) * engaged(xc[0] - u - half))
        return ydot, xc[0], ydot

    def initial_grid(self, data, values, free):
        if not free["width"]:
            return []
        base = max(abs(data.loop_width) * data.loop_share, 1e-3 * data.input_scale)
        return [{"width": base * f, **s} for f in BACKLASH_FACTORS for s in start_points(free)]

    def describe(self, dt):
        return f"width {self.width:.3g}, start {self.start:.2g}"

    def inverse_output(self, x, y, p, dt):
        # Exact for the sharp operator; inside the dead band any input in
        # [y - width/2, y + width/2] keeps the output: the centre is returned.
        half = p[0] / 2
        tol = 1e-12
        return ca.if_else(y > x[0] + tol, y + half, ca.if_else(y < x[0] - tol, y - half, x[0]))
