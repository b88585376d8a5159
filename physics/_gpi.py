"""Generalized Prandtl-Ishlinskii hysteresis: weighted play operators on a saturating envelope."""

from __future__ import annotations

import itertools

import casadi as ca
import numpy as np

from ._backlash import SMOOTHING, START_DOC, _ramp, start_points
from ._block import AbstractBlock, Parameter
from ._traits import BlockTraits

#: Total widths of the play operators for an input of unit scale (``GPI.widths=None``).
GPI_WIDTHS = (0.1, 0.25, 0.5, 1.0, 2.0)
#: Envelope saturations tried as starting points, for an input of unit scale.
GPI_SATURATIONS = (0.0, 0.15, 0.4)


def envelope(v, center, sat):
    """``c + (v - c) / sqrt(1 + (a (v - c))^2)``: the identity at ``a = 0``, saturating and
    rising for ``a > 0`` (slope ``(1 + (a (v - c))^2)^-1.5``)."""
    d = v - center
    return center + d / ca.sqrt(1 + (sat * d) ** 2)


class GPI(AbstractBlock):
    """Generalized Prandtl-Ishlinskii operator: ``y = (1 - sum w) g(u) + sum_i w_i P_{r_i}[g(u)]``.

    ``P_r`` is the play operator of total width ``r`` (:class:`~physics.Backlash`'s, with its
    smooth ramp) and ``g`` the envelope :func:`envelope` with centre ``center`` and saturation
    ``saturation``: the generalized PI model of Al Janaideh et al., whose loops may narrow or
    saturate at the ends of the input range, unlike the classical PI model (``saturation = 0``).
    The weights are non-negative and sum to at most one, so the output rises with the input,
    the block is invertible (Newton on its smooth step) and maps a large excursion onto itself
    (a following ``linear`` block keeps the gain). ``widths`` (input units) are structural;
    ``None`` takes :data:`GPI_WIDTHS` times the input's order of magnitude when fitted.
    The state is each play's output; ``start`` places every play in its band at the first
    input, as :class:`~physics.Backlash`'s (0 centred, 1 at the rising edge; held unless freed).
    """

    name = "gpi"
    effect = "hysteresis"
    aliases = ("prandtl-ishlinskii", "pi")
    rank = 3
    selection_order = 40
    takes_loop_width = True
    continuous_states = None

    def __init__(self, weights=None, center: float | None = None, saturation: float | None = None,
                 widths=None, smoothing: float | None = None, start: float | None = None):
        if widths is not None:
            w = np.atleast_1d(np.asarray(widths, dtype=float))
            if w.ndim != 1 or w.size < 1 or not np.all(np.isfinite(w) & (w > 0)):
                raise ValueError(f"GPI widths must be one or more widths > 0. Got {widths} instead.")
            widths = tuple(float(x) for x in w)
        if smoothing is not None and not smoothing >= 0:
            raise ValueError(f"GPI smoothing must be >= 0 (or None). Got {smoothing} instead.")
        self.widths, self.smoothing = widths, None if smoothing is None else float(smoothing)
        k = len(self._widths)
        parameters = (
            *(Parameter(f"w_{i + 1}", 0.5 / k, 0.0, 1.0, "-", f"weight of the play of width {r:g}")
              for i, r in enumerate(self._widths)),
            Parameter("center", 0.0, -1e3, 1e3, "input unit", "centre of the envelope", scaling=(1, 0),
                      location=True),
            Parameter("saturation", 0.0, 0.0, 10.0, "1/input unit", "curvature of the envelope", scaling=(-1, 0)),
            Parameter("start", 0.0, -1.0, 1.0, "-", START_DOC, fit=False),
        )
        self.traits = BlockTraits.of(GPI, parameters=parameters, identity={
            **{f"w_{i + 1}": 0.0 for i in range(k)}, "center": 0.0, "saturation": 0.0, "start": 0.0})
        names = [p.name for p in self.parameters]
        values = dict(zip(names, np.ravel(weights))) if weights is not None else {}
        values.update({"center": center, "saturation": saturation, "start": start})
        self._init_parameters(values)

    @property
    def _widths(self) -> tuple[float, ...]:
        return GPI_WIDTHS if self.widths is None else self.widths

    def for_scale(self, s_in):
        if self.widths is not None and self.smoothing is not None:
            return self
        return self.with_settings(widths=list(self.widths or np.array(GPI_WIDTHS) * s_in),
                                  smoothing=SMOOTHING * s_in if self.smoothing is None else self.smoothing)

    @property
    def state_names(self):
        return tuple(f"play_{i + 1}" for i in range(len(self._widths)))

    def _split(self, p):
        k = len(self._widths)
        return [p[i] for i in range(k)], p[k], p[k + 1], p[k + 2]

    def step(self, x, u, p, dt):
        w, center, sat, _ = self._split(p)
        g = envelope(u, center, sat)
        s = SMOOTHING if self.smoothing is None else self.smoothing
        plays = [x[i] + _ramp(g - r / 2 - x[i], s) - _ramp(x[i] - g - r / 2, s) for i, r in enumerate(self._widths)]
        y = (1 - sum(w)) * g + sum(wi * q for wi, q in zip(w, plays))
        return ca.vertcat(*plays), y

    def steady_state(self, u0, p):
        _, center, sat, start = self._split(p)
        g = envelope(u0, center, sat)
        return ca.vertcat(*(g - start * r / 2 for r in self._widths))

    def constraints(self, p):
        w = self._split(p)[0]
        return [(sum(w), 0.0, 1.0)]

    def initial_grid(self, data, values, free):
        k = len(self._widths)
        if not all(free[f"w_{i + 1}"] for i in range(k)):
            return []
        profiles = (np.ones(k), np.arange(1.0, k + 1), np.arange(k, 0.0, -1))  # flat, wide or narrow plays heavier
        sats = [f / data.input_scale for f in GPI_SATURATIONS] if free["saturation"] else [None]
        out = []
        for share, prof, sat, start in itertools.product((0.3, 0.6, 0.9), profiles, sats, start_points(free)):
            point = {**{f"w_{i + 1}": float(share * prof[i] / prof.sum()) for i in range(k)}, **start}
            if free["center"]:
                point["center"] = data.input_center
            out.append(point if sat is None else {**point, "saturation": sat})
        return out

    def get_settings(self):
        return {"widths": None if self.widths is None else list(self.widths), "smoothing": self.smoothing}

    def describe(self, dt):
        w = ", ".join(f"{getattr(self, f'w_{i + 1}'):.2g}@{r:.3g}" for i, r in enumerate(self._widths))
        return (f"plays {w}; envelope centre {self.center:.3g}, saturation {self.saturation:.3g}, "
                f"start {self.start:.2g}")

    def __repr__(self):
        return (f"GPI(weights={[float(f'{v:.6g}') for v in self.param_values()[:-3]]}, center={self.center:.6g}, "
                f"saturation={self.saturation:.6g}, start={self.start:.6g}, widths={list(self._widths)})")
