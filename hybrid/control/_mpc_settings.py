"""The settings of a tracking MPC, as one checked object (do-mpc's ``MPCSettings``).

``TrackingMPC(model, MPCSettings(horizon=25, solver="sqp", w_du=1e-2))``: every knob has a type and
is checked when the settings are made, with a message that says how to fix it. What needs the
model (the default input bounds, the rate limit a neural ODE allows, the solver ``"auto"`` picks)
is resolved by :meth:`hybrid.control.MPCProblem.build`; ``TrackingMPC.settings`` holds the result.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from hybrid.export._model import ExportError

from ._mpc_solver import SOLVERS

__all__ = ["MPCSettings"]


@dataclass(frozen=True)
class MPCSettings:
    """What a :class:`~hybrid.control.TrackingMPC` minimises and how it solves it.

    The MPC minimises ``sum_k w_track ((y_k - r_k)/s_y)^2 + w_du ((u_k - u_{k-1})/s_u)^2 +
    w_u ((u_k - u_ref)/s_u)^2`` over ``k = 0..horizon-1`` subject to the model, ``u_bounds``,
    ``|u_k - u_{k-1}| <= du_max`` (``u_{-1}`` is the input applied last) and ``y_bounds``.
    None means "from the model" (resolved when the MPC is built).

    Parameters
    ----------
    horizon : int
        Samples predicted (25 = 1 s at 25 Hz).
    u_bounds : (float, float) or None
        Input limits, in the model's input units (mm of tendon for the catheter). Default: the
        range of the input the model was fitted on (``ExportedModel.input_range``); a model that
        does not record it (a physics spec never identified) needs them given.
    du_max : float or None
        Largest change of ``u`` per sample, in input units. Default: a twelfth of the bounds'
        span (0.5 mm for the catheter's 0-6 mm), at most the model's ``meta["max_input_step"]``
        where it records one (a neural ODE: the fastest input it was trained on, beyond which its
        exported fixed-step RK4 no longer equals its prediction).
    w_track, w_du, w_u : float
        Weights (>= 0) of the tracking error, the input rate and the input level, each measured in
        the model's own scales: the error over the span ``s_y`` of the model's output across the
        input bounds, the input and its change over the bounds' span ``s_u`` (unit-free, so a model
        in metres and radians is controlled as one in mm and deg; on the catheter, ``w_du = 1e-3``
        is about 0.1 per mm^2 against 1 per deg^2). The solvers work on that scaled problem
        (:class:`hybrid.control.MPCProblem`), so their tolerances mean the same in any units too.
    u_ref : float or None
        Input the level weight ``w_u`` pulls towards (default: the middle of ``u_bounds``).
    solver : str
        A name of :data:`hybrid.control.SOLVERS` or ``"auto"`` (default): ``"adjoint-sqp"`` for a
        model with an ``approximation`` (a hybrid's physics) and one input, ``"ipopt"`` with
        ``y_bounds``, else ``"sqp"``. See each solver class for what it does and its options.
    solver_options : dict or None
        The solver's own options, checked by its class when the MPC is built:
        :class:`~hybrid.control.SQPSolver` and :class:`~hybrid.control.IpoptSolver` take
        ``shooting`` (``"multiple"``, ``"single"``), ``expand`` (to SX) and, for ``"sqp"``,
        ``hessian`` (``"gauss-newton"``, ``"exact"``) beside their CasADi plugin's options;
        :class:`~hybrid.control.AdjointSQPSolver` ``max_iter``, ``tol`` and ``compile``;
        :class:`~hybrid.control.FixedSQPSolver` ``iterations``, ``gradient`` and ``compile``.
    y_bounds : (float, float), {int: (float, float)} or None
        Output limits over the horizon, in the model's output units, None (or inf) for no limit on
        one side; stored as ``(low, high)`` floats. A model of several outputs takes ``{k: (low,
        high)}``, the limits of its output ``k`` (one output; stored as :class:`OutputBounds`), e.g.
        the tip's angle within limits while its position is tracked; a pair bounds the tracked one. Only solvers of the full NLP bound outputs
        (``"sqp"``, ``"ipopt"``; ``"auto"`` then means ``"ipopt"``: on a backlash's kinks, sqp with
        qrqp stalled with the constraints active).
    tighten : bool
        Keep the model's prediction interval, not only its prediction, inside ``y_bounds``: the
        constraints become ``y - h >= low`` and ``y + h <= high`` with ``h`` the half-width the
        model's export carries (:attr:`ExportedModel.half_width`, calibrated by ``hyst fit``),
        which grows where the inputs leave the training data. ``h`` is held fixed within a solve
        (a back-off: the half-widths along the warm start, then along the solution, the larger
        kept, solved again where they grew): the nearest-neighbour half-width is not smooth.
    track : int or None
        A model of several outputs (the tip's angle and position): the index of the output tracked;
        the others go where its inputs take them. None for a model of one output.

    Examples
    --------
    >>> from hybrid.control import MPCSettings
    >>> settings = MPCSettings(horizon=10, u_bounds=(0, 6), solver="sqp")
    >>> settings.u_bounds
    (0.0, 6.0)
    >>> MPCSettings(horizon=0)
    Traceback (most recent call last):
    ...
    hybrid.export._errors.ExportError: The MPC's 'horizon' must be a whole number >= 1. Got 0 instead.
    """

    horizon: int = 25
    u_bounds: tuple[float, float] | None = None
    du_max: float | None = None
    w_track: float = 1.0
    w_du: float = 1e-3
    w_u: float = 0.0
    u_ref: float | None = None
    solver: str = "auto"
    solver_options: Mapping[str, Any] | None = None
    y_bounds: tuple[float | None, float | None] | None = None
    tighten: bool = False
    track: int | None = None

    def __post_init__(self) -> None:
        h = self.horizon
        if (isinstance(h, bool) or not isinstance(h, (int, float, np.integer, np.floating)) or not np.isfinite(h)
                or int(h) != h or h < 1):
            raise ExportError(f"The MPC's 'horizon' must be a whole number >= 1. Got {h!r} instead.")
        self._set("horizon", int(h))
        if self.u_bounds is not None:
            self._set("u_bounds", check_u_bounds(self.u_bounds))
        if self.du_max is not None:
            self._set("du_max", check_du_max(self.du_max))
        for name in ("w_track", "w_du", "w_u"):
            w = _number(self, name)
            if not (np.isfinite(w) and w >= 0):
                raise ExportError(f"The MPC's '{name}' must be a finite weight >= 0. Got {getattr(self, name)!r} instead.")
            self._set(name, w)
        if self.u_ref is not None:
            u_ref = _number(self, "u_ref")
            if not np.isfinite(u_ref):
                raise ExportError(f"The MPC's 'u_ref' must be a finite input (or None: the middle of u_bounds). "
                                  f"Got {self.u_ref!r} instead.")
            self._set("u_ref", u_ref)
        if not isinstance(self.solver, str) or (self.solver != "auto" and self.solver not in SOLVERS):
            raise ExportError(f"Unknown MPC solver {self.solver!r}. Must be one of: auto, {', '.join(sorted(SOLVERS))}.")
        if self.solver_options is not None:
            if not isinstance(self.solver_options, Mapping):
                raise ExportError(f"The MPC's 'solver_options' must be a dict of the solver's options. "
                                  f"Got {type(self.solver_options).__name__} instead.")
            self._set("solver_options", dict(self.solver_options))
        if self.track is not None:
            self._set("track", _index(self.track, "track"))
        self._check_output_bounds()

    @property
    def bound(self) -> int | None:
        """The index of the output ``y_bounds`` limits where they name one (``{k: (low, high)}``), else None."""
        return getattr(self.y_bounds, "output", None)

    def _set(self, name: str, value) -> None:
        object.__setattr__(self, name, value)  # normalised once, at construction (frozen afterwards)

    def _check_output_bounds(self) -> None:
        """``y_bounds`` as ``(low, high)`` floats with low < high; ``tighten`` needs them; both need a
        solver that bounds outputs (the model's side is checked by :meth:`MPCProblem.build`)."""
        y_bounds, tighten = self.y_bounds, self.tighten
        if not isinstance(tighten, (bool, np.bool_)):
            raise ExportError(f"The MPC's 'tighten' must be True or False. Got {tighten!r} instead.")
        if tighten and y_bounds is None:
            raise ExportError("tighten=True keeps the model's interval inside the output bounds; give them: "
                              "TrackingMPC(..., y_bounds=(low, high), tighten=True).")
        self._set("tighten", bool(tighten))
        if y_bounds is None:
            return
        output = getattr(y_bounds, "output", None)
        if isinstance(y_bounds, Mapping):
            if len(y_bounds) != 1:
                raise ExportError(f"The MPC's 'y_bounds' as a dict names one output's limits, {{k: (low, high)}}. Got "
                                  f"{dict(y_bounds)!r}.")
            ((output, y_bounds),) = y_bounds.items()
            output = _index(output, "y_bounds' output")
        try:
            lo, hi = (-np.inf if v is None else float(v) for v in y_bounds)
        except (TypeError, ValueError):
            lo = hi = np.nan
        hi = np.inf if not np.isnan(hi) and y_bounds[1] is None else hi
        if not (lo < hi and (np.isfinite(lo) or np.isfinite(hi))) or np.isnan(lo) or np.isnan(hi):
            raise ExportError(f"The MPC's 'y_bounds' must be (low, high) with low < high (None or inf for no "
                              f"limit on one side). Got {y_bounds}.")
        cls = SOLVERS.get(self.solver)
        if cls is not None and not cls.output_bounds:
            full = " or ".join(f"'{n}'" for n in sorted(SOLVERS) if SOLVERS[n].output_bounds)
            raise ExportError(f"Output bounds need a solver that carries them; the {self.solver} solver bounds the inputs "
                              f"only. Use solver={full} (or 'auto').")
        self._set("y_bounds", (lo, hi) if output is None else OutputBounds((lo, hi), output))


class OutputBounds(tuple):
    """``(low, high)`` of the output ``output`` of a model of several, as :class:`MPCSettings` holds ``y_bounds={k:
    (low, high)}``: read as the pair everywhere a pair is, with the output it limits beside it."""

    def __new__(cls, bounds, output: int):
        out = super().__new__(cls, bounds)
        out.output = int(output)
        return out

    def __getnewargs__(self):
        return tuple(self), self.output

    def __repr__(self) -> str:
        return f"OutputBounds({tuple(self)!r}, output={self.output})"


def _index(value, name: str) -> int:
    """``value`` as the index of an output (a whole number >= 0), or an :class:`ExportError` naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
        raise ExportError(f"The MPC's '{name}' is the index of an output of the model (0, 1, ...). Got {value!r} "
                          "instead.")
    return int(value)


def check_u_bounds(u_bounds) -> tuple[float, float]:
    """``u_bounds`` as finite ``(low, high)`` floats with low < high."""
    try:
        lo, hi = (float(v) for v in u_bounds)
    except (TypeError, ValueError):
        lo = hi = np.nan
    if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
        raise ExportError(f"The MPC's 'u_bounds' must be (low, high) with low < high. Got {u_bounds}.")
    return lo, hi


def check_du_max(du_max) -> float:
    try:
        value = float(du_max)
    except (TypeError, ValueError):
        value = np.nan
    if not value > 0:
        raise ExportError(f"The MPC's 'du_max' must be > 0 input units per sample. Got {du_max} instead.")
    return value


def _number(settings: MPCSettings, name: str) -> float:
    value = getattr(settings, name)
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ExportError(f"The MPC's '{name}' must be a number. Got {value!r} instead.")
    return float(value)
