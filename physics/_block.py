"""The block contract: a small discrete-time state-space piece written in CasADi.

Every block follows one convention. At sample ``k`` it receives its state ``x_k``
(memory of samples ``< k``) and the input ``u_k`` and returns ``(x_{k+1}, y_k)``;
``y_k`` may depend on ``u_k`` (direct feed-through), which is what exact
discretisation of a continuous block with the input interpolated linearly between
samples requires.
"""

from __future__ import annotations

import abc
import inspect
import math
from dataclasses import dataclass
from typing import Any, ClassVar

import casadi as ca
import numpy as np

from ._errors import PhysicsError
from ._signature import Signature
from ._traits import _Structural, _Traits


@dataclass(frozen=True)
class Parameter:
    """A named physical parameter with unit, bounds and a default value."""

    name: str
    default: float
    lower: float
    upper: float
    unit: str = ""
    doc: str = ""
    fit: bool = True  # fitted by default; False: held at its value unless asked
    #: Powers ``(a, b)`` of the block's input and output signal scales the parameter goes
    #: with: a backlash width ``(1, 0)``, a gain ``(-1, 1)``, a time constant ``(0, 0)``.
    #: ``default``, ``lower`` and ``upper`` are for signals of unit scale; identification
    #: multiplies them by ``s_in**a * s_out**b`` of the data, so that fits work in any units.
    scaling: tuple[float, float] = (0.0, 0.0)
    #: A position on the block's input axis (an envelope's centre), not a size: where the input
    #: lies far from zero (motor steps 1360-2801), identification solves for it as its distance
    #: from the input's level, as it does for the output map's offset.
    location: bool = False


@dataclass(frozen=True)
class DataSummary:
    """What identification reads off the data before fitting, for the blocks' starting grids.

    ``gain`` and ``offset`` are those of the straight line ``y = gain u + offset``
    through all samples; ``loop_width`` is the mean gap between the falling and
    the rising branches at equal input, in input units (signed: positive when
    the output lags); ``loop_share`` the part of it each block that
    ``takes_loop_width`` should explain; ``input_scale`` the input's order of magnitude;
    ``input_center`` the middle of the input's range; ``dt`` the model's sample step (s).
    """

    gain: float
    offset: float
    loop_width: float
    loop_share: float
    input_scale: float = 1.0
    input_center: float = 0.0
    dt: float | None = None


class AbstractBlock(abc.ABC):
    """Abstract base of all blocks; concrete blocks are final (never subclassed).

    Parameter values are keyword arguments of ``__init__`` and are stored as
    attributes of the same name. Structural settings (grid sizes, delay length,
    smoothing) are the other keyword arguments of ``__init__``, stored as
    attributes of the same name, and are not identified.

    Besides its equations a block declares what the rest of the package needs
    to know about it (nothing elsewhere lists blocks by name): its ``effect``
    (the one vocabulary of the simulator, discovery and reports) and other
    spellings of it (``aliases``), its ``rank`` in signal order, its
    :class:`~physics._signature.Signature` for discovery, the starting grid of
    its parameters (:meth:`initial_grid`), how it reads in words
    (:meth:`describe`) and its structural settings (:meth:`get_settings`).
    A new block is one file plus ``physics.register_block(MyBlock)``.
    """

    name: ClassVar[str]
    #: All the declarations below, frozen in one :class:`~physics.BlockTraits`; a block whose
    #: ``parameters``, ``identity``, ``continuous_states`` or ``smooth_in_input`` follow its structural
    #: settings sets its own once, in ``__init__``: ``self.traits = BlockTraits.of(type(self), ...)``.
    traits = _Traits()
    #: The parameters, in the order of the parameter vector ``p``.
    parameters = _Structural(())
    #: True when ``step`` is differentiable in ``u`` (Newton may invert it).
    smooth_in_input = _Structural(True)
    #: The effect the block models (None: not an effect, e.g. the output map).
    effect: ClassVar[str | None] = None
    #: Other spellings of ``effect`` accepted from users (the block's name is always one).
    aliases: ClassVar[tuple[str, ...]] = ()
    #: Position in signal order (lag 0, delay 1, backlash 2, hysteresis 3, static 4,
    #: linear 5, drift 6); None: the block cannot be placed by discovery.
    rank: ClassVar[int | None] = None
    #: How discovery recognises the effect in a residual; None: discovery never adds it.
    signature: ClassVar[Signature | None] = None
    #: Names of (gain, offset) when the output is ``gain * u + offset``: the line
    #: fit starts them, and a last affine block is eliminated by least squares.
    affine_output: ClassVar[tuple[str, str] | None] = None
    #: True for blocks that explain part of the data's loop width (backlash, Bouc-Wen).
    takes_loop_width: ClassVar[bool] = False
    #: Starts ``identify`` runs by default for a spec with this block: more than 1 where the
    #: fit is prone to local minima (a near-zero time constant, a flipped or collapsed loop).
    starts: ClassVar[int] = 1
    #: A whole-number structural setting that discovery searches by its neighbours.
    searched_setting: ClassVar[str | None] = None
    #: True for a block whose output equals its input at rest (a lag): ``Series.inverse``
    #: with ``quasi_static=True`` passes the wanted signal through it rather than inverting
    #: its dynamics, whose inverse amplifies the wanted path's noise by the time constant over
    #: the sample time.
    unit_static_gain: ClassVar[bool] = False
    #: False for a hysteresis law whose minor loops need not close (Bouc-Wen: input cycles at an
    #: offset its fit never saw make its output drift from cycle to cycle, where Preisach-type
    #: operators, plays and GPI, return to the same branch). ``select_physics`` asks such a spec
    #: to beat the best one without such a block by ``UNCLOSED_MARGIN`` before choosing it.
    closes_minor_loops: ClassVar[bool] = True
    #: True for a pure shift of whole samples (no causal inverse step): ``Series.inverse``
    #: removes it and advances the wanted path by ``delay_samples`` instead.
    pure_delay: ClassVar[bool] = False
    #: Whether ``select_physics``'s greedy search tries adding the block when no ``blocks=`` are
    #: given. Only a block with an ``effect`` and a ``rank`` that refines no other is tried; False
    #: opts out (a pure delay, whose length counts samples; a costly or rarely needed law).
    selectable: ClassVar[bool] = True
    #: Place among the blocks the greedy search tries, lower first; ties (a new block's default)
    #: keep registration order, after the built-in blocks.
    selection_order: ClassVar[float] = math.inf
    #: Names of blocks this one refines: once the greedy search stops, a chosen block named here
    #: whose fits show its effect (:meth:`shows_effect`) is tried replaced by this one. A refining
    #: block is only tried that way, never added on its own.
    refines: ClassVar[tuple[str, ...]] = ()
    #: Effects a refining block may hold itself: it is also tried with each block of the spec
    #: that models one of them removed (the hysteretic oscillator holds a loop).
    holds_effects: ClassVar[tuple[str, ...]] = ()
    #: Parameter values that make the block pass its input through unchanged (a nested simpler
    #: model: identification checks a fit is no worse than the output map alone); None: none do.
    identity = _Structural(None)
    #: Powers of the block's input signal scale its states go with (None: each state is a
    #: signal in input units, power 1); see ``Parameter.scaling``.
    state_scaling: ClassVar[tuple[float, ...] | None] = None

    def for_scale(self, s_in: float) -> "AbstractBlock":
        """The block for an input of scale ``s_in``: settings left to the data (``None``) resolved
        in its units. Default: the block itself."""
        return self

    def for_range(self, lo: float, hi: float) -> "AbstractBlock":
        """The block for data whose input spans ``lo``..``hi``: settings left to the data's
        location (``None``, e.g. a static map's centre) resolved there. Default: the block itself."""
        return self

    def for_input_range(self, lo: float, hi: float) -> "AbstractBlock":
        """This block given the range its own input had on the fitted data (after the fit; e.g.
        ``poly`` continues along its tangent beyond it); ``None, None`` clears it (before a fit).
        Default: unchanged."""
        return self

    def output_scale(self, s_in: float, s_y: float) -> float:
        """Scale of the block's output for an input of scale ``s_in`` (``s_y``: the measured
        output's); in input units unless the block maps to the output's units."""
        return s_in

    @property
    def delay_samples(self) -> int:
        """Samples the block shifts its input by (0 unless ``pure_delay``)."""
        return 0

    def _init_parameters(self, values: dict) -> None:
        for par in self.parameters:
            value = values.pop(par.name, None)
            value = par.default if value is None else float(value)
            if not np.isfinite(value) or not par.lower <= value <= par.upper:
                raise PhysicsError(
                    f"The '{par.name}' parameter of {type(self).__name__} must be in "
                    f"[{par.lower}, {par.upper}] {par.unit}. Got {value} instead."
                )
            setattr(self, par.name, value)
        if values:
            known = ", ".join(p.name for p in self.parameters) or "none"
            raise PhysicsError(
                f"{type(self).__name__} has no parameter(s) {sorted(values)}; "
                f"its parameters are: {known}."
            )

    # -- structure -------------------------------------------------------
    @property
    def state_names(self) -> tuple[str, ...]:
        return ()

    @property
    def n_x(self) -> int:
        return len(self.state_names)

    @property
    def n_p(self) -> int:
        return len(self.parameters)

    @property
    def output_size(self) -> int:
        """How many signals the block outputs: 1, or several for the last block of a model with several
        outputs (:class:`~physics.OutputMaps`, :class:`~physics.Arc`)."""
        return 1

    def param_values(self) -> np.ndarray:
        return np.array([getattr(self, p.name) for p in self.parameters], dtype=float)

    def set_param_values(self, values) -> None:
        for par, value in zip(self.parameters, np.asarray(values, dtype=float).ravel()):
            setattr(self, par.name, float(value))

    # -- equations -------------------------------------------------------
    @abc.abstractmethod
    def step(self, x, u, p, dt: float):
        """Symbolic step: ``(x_next, y)`` from state, input and parameters."""

    def steady_state(self, u0, p):
        """State after the input has rested at ``u0`` for a long time."""
        return ca.DM.zeros(self.n_x, 1)

    # -- continuous time (neural-ODE hybrids) ---------------------------------
    #: Names of the continuous-time states; None: the block has no ODE form.
    continuous_states = _Structural(())

    def derivative(self, xc, u, udot, p):
        """Continuous-time form: ``(xc_dot, y, y_dot)`` from state, input and its rate.

        Memoryless blocks have no state; ``y_dot`` lets the next block in a
        chain see the rate of its own input.
        """
        raise NotImplementedError(f"{type(self).__name__} has no continuous-time form")

    def constraints(self, p) -> list:
        """Extra constraints ``(expr, lower, upper)`` on the parameters for fitting."""
        return []

    def inverse_output(self, x, y, p, dt: float):
        """Input ``u_k`` that makes the block output ``y`` from state ``x``.

        The default is a Newton root solve (CasADi ``rootfinder``) on the block's
        own step equation; blocks with an explicit inverse override this.
        """
        x = ca.reshape(x, self.n_x, 1)  # a memoryless block's slice of a one-entry state comes as 1 x 0
        u = ca.SX.sym("u")
        xs = ca.SX.sym("x", self.n_x)
        ys = ca.SX.sym("y")
        ps = ca.SX.sym("p", self.n_p)
        _, yhat = self.step(xs, u, ps, dt)
        residual = ca.Function("residual", [u, ca.vertcat(xs, ys, ps)], [yhat - ys])
        solver = ca.rootfinder(
            f"{self.name}_inverse", "newton", residual,
            {"abstol": 1e-12, "max_iter": 50, "error_on_fail": False},
        )
        return solver(self.inverse_guess(x, y, p), ca.vertcat(x, y, p))

    def inverse_guess(self, x, y, p):
        return y

    @classmethod
    def shows_effect(cls, values: dict[str, float]) -> bool:
        """Whether a fit with these values (own names) shows the block's effect, so that a richer
        block of the same effect is worth trying in its place (``select_physics``'s
        refinements). Default True."""
        return True

    # -- starting values and reports ----------------------------------------------
    def initial_grid(self, data: DataSummary, values: dict[str, float],
                     free: dict[str, bool]) -> list[dict[str, float]]:
        """Starting points of the block's parameters (own names) for identification to score.

        ``values`` are the current values, ``free`` says which are fitted. Default: none.
        """
        return []

    def summary(self, dt: float) -> dict[str, float]:
        """The block's fitted values for a report, by their own names."""
        return {p.name: float(getattr(self, p.name)) for p in self.parameters}

    def describe(self, dt: float) -> str:
        """The block's values in words, e.g. ``"time constant 0.12 s"``."""
        return ", ".join(f"{k} {v:.3g}" for k, v in self.summary(dt).items())

    # -- serialization -------------------------------------------------------------
    def get_settings(self) -> dict[str, Any]:
        """Structural settings, JSON-ready: the ``__init__`` arguments that are not parameters.

        ``type(block)(**block.get_settings())`` rebuilds the block's structure.
        """
        own = {p.name for p in self.parameters}
        out = {}
        for key, arg in inspect.signature(type(self).__init__).parameters.items():
            if key == "self" or key in own or arg.kind in (arg.VAR_POSITIONAL, arg.VAR_KEYWORD):
                continue
            if not hasattr(self, key):
                raise PhysicsError(f"{type(self).__name__}.__init__ takes '{key}' but the block does not "
                                   f"store it as self.{key}; store it, or override get_settings().")
            out[key] = _json_ready(getattr(self, key), f"setting '{key}' of {type(self).__name__}")
        return out

    def with_settings(self, **changes) -> "AbstractBlock":
        """A copy with some structural settings changed and the same parameter values."""
        out = type(self)(**{**self.get_settings(), **changes})
        if out.n_p == self.n_p:
            out.set_param_values(self.param_values())
        return out

    def __repr__(self) -> str:
        args = ", ".join(f"{p.name}={getattr(self, p.name):.6g}" for p in self.parameters)
        return f"{type(self).__name__}({args})"


def clip_to_bounds(cls: type[AbstractBlock], values: dict[str, float]) -> dict[str, float]:
    """Values of ``cls``'s parameters (own names) moved into their bounds."""
    bounds = {p.name: (p.lower, p.upper) for p in cls.parameters}
    return {k: float(np.clip(v, *bounds[k])) for k, v in values.items()}


def _json_ready(value, what: str):
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_json_ready(v, what) for v in np.asarray(value, dtype=object).tolist()] \
            if isinstance(value, np.ndarray) else [_json_ready(v, what) for v in value]
    raise PhysicsError(f"The {what} is a {type(value).__name__}; a structural setting must be a number, "
                       "string, bool or a list of them. Override get_settings() to store it otherwise.")


def smooth_abs(x, eps: float = 1e-6):
    """|x| smoothed near zero so that gradients exist: sqrt(x^2 + eps^2)."""
    return ca.sqrt(x * x + eps * eps)
