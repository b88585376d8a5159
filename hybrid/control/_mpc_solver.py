"""What a solver of the tracking MPC is: what it returns, what it implements, and the registry.

One class per ``solver`` name (torchdiffeq's ``SOLVERS``), each a subclass of :class:`MPCSolver`
registered with :func:`register_solver`: built on an :class:`~hybrid.control.MPCProblem` and its
own options, it declares what it supports (``output_bounds``, ``measured_inputs``), solves from the
last solution (:meth:`MPCSolver.solve`) and states its objective (:meth:`MPCSolver.cost`).
``TrackingMPC`` reads the class from :data:`SOLVERS` and never branches on the name.
"""

from __future__ import annotations

import abc
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any, Callable, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from hybrid.export._model import ExportError

__all__ = ["MPCSolution", "MPCSolver", "SOLVERS", "register_solver"]

#: Registry name -> solver class (``TrackingMPC(solver=NAME)``; ``"auto"`` picks one of them).
SOLVERS: dict[str, type["MPCSolver"]] = {}


def register_solver(cls: type["MPCSolver"]) -> type["MPCSolver"]:
    """Add a solver class to :data:`SOLVERS` under its ``name`` (usable as a class decorator)."""
    if not (isinstance(cls, type) and issubclass(cls, MPCSolver)):
        raise ExportError(f"register_solver takes an MPCSolver subclass. Got {cls!r} instead.")
    name = getattr(cls, "name", None)
    if not isinstance(name, str) or not name or name == "auto":
        raise ExportError(f"{cls.__name__} needs a class attribute 'name' (its registry name, not 'auto').")
    if SOLVERS.get(name, cls) is not cls:
        raise ExportError(f"The MPC solver name {name!r} is taken by {SOLVERS[name].__name__}; choose another name.")
    SOLVERS[name] = cls
    return cls


@dataclass(frozen=True)
class MPCSolution:
    """One solve: ``guess`` (the solver's own variables, the next solve's warm start), the ``cost``
    reached (the scaled problem's; nan where the solver does not evaluate it), ``iterations``,
    ``success``, the input ``u`` to apply (input units) and the parameters ``p`` it was solved for."""

    guess: tuple
    cost: float
    iterations: int
    success: bool
    u: float = np.nan
    p: Any = None


class MPCSolver(abc.ABC):
    """A way to solve the tracking problem of :class:`~hybrid.control.TrackingMPC`.

    A subclass sets ``name`` (its :data:`SOLVERS` key), ``title`` (for messages) and what it
    supports: ``output_bounds`` (``y_bounds`` and ``tighten``) and ``measured_inputs`` (a step with
    inputs besides the command), and which option caps its iterations (``iterations_option``); it builds itself in ``__init__(problem, options)`` and implements
    :meth:`solve`, :meth:`_cost` (the objective on the scaled problem) and :meth:`predicted_output`.
    """

    name: ClassVar[str]
    title: ClassVar[str]
    output_bounds: ClassVar[bool] = True
    measured_inputs: ClassVar[bool] = True
    #: The option that caps its iterations per control step (``hyst mpc --max-iter``).
    iterations_option: ClassVar[str] = "max_iter"

    def __init__(self, problem: "MPCProblem", options: Mapping[str, Any] | None = None):  # noqa: F821  (no import: no circle)
        if problem.n_d and not self.measured_inputs:
            able = " or ".join(f"'{n}'" for n in sorted(SOLVERS) if SOLVERS[n].measured_inputs)
            raise ExportError(f"The {self.title} steps a model with one input; this one also reads {problem.n_d} "
                              f"measured input(s). Use solver={able}.")
        self.problem = problem

    @property
    def shooting(self) -> str:
        """``"multiple"`` or ``"single"``: whether the states are decision variables."""
        return "single"

    @property
    def expand(self) -> bool:
        """Whether the problem is expanded to SX (the NLP solvers decide by size)."""
        return False

    @abc.abstractmethod
    def solve(self, x: np.ndarray, ref: np.ndarray, u_prev: float, D: np.ndarray, last: MPCSolution | None,
              half_widths: np.ndarray | None = None) -> MPCSolution:
        """Solve from state ``x`` (checked) for the reference ``ref`` over the horizon, ``u_prev`` the
        input applied last, ``D`` the measured inputs (``n_d x horizon``), all in the model's units;
        ``last`` the previous solution (the warm start, None at first); ``half_widths`` the interval's
        half-widths given by the caller (scaled; ``tighten``)."""

    def cost(self, x: ArrayLike, U: ArrayLike, ref: ArrayLike, u_prev: float, measured: ArrayLike | None = None) -> float:
        """The objective this solver minimises, of the inputs ``U`` over the horizon from state ``x``
        (``ref``, ``u_prev`` and ``measured`` as :meth:`TrackingMPC.solve` takes them; model units):
        the scaled problem's, so values of two solvers on one problem compare."""
        pb, sc = self.problem, self.problem.scale
        U = np.asarray(U, dtype=float).ravel()
        if U.size != pb.horizon:
            raise ExportError(f"U must hold {pb.horizon} inputs (the horizon); got {U.size}.")
        return float(self._cost(sc.x(pb.state(x)), sc.u(U), sc.y(pb.reference(ref)), float(sc.u(u_prev)),
                                pb.measured(measured)))

    @abc.abstractmethod
    def _cost(self, x: np.ndarray, U: np.ndarray, ref: np.ndarray, u_prev: float, D: np.ndarray) -> float:
        """:meth:`cost` on the scaled problem (``D`` unscaled, as the scaled step takes it)."""

    @abc.abstractmethod
    def predicted_output(self, solution: MPCSolution) -> NDArray[np.float64]:
        """Outputs ``solution`` predicts over the horizon, in output units."""

    def _from_rest(self, best: MPCSolution, x, ref, u_prev_phys: float, u_prev: float, D: np.ndarray,
                   solve_from: Callable[[np.ndarray], MPCSolution]) -> MPCSolution:
        """A flat region (a backlash's dead band: dy/du = 0) holds a gradient method where it starts;
        where the inputs whose rest outputs are the reference cost less, start again from them
        (``solve_from(U)``) and keep the clearly better solution. All scaled but ``u_prev_phys``."""
        if self.problem.model is None:
            return best
        sc = self.problem.scale
        U = sc.u(self.problem.static_inputs(sc.y_back(ref), u_prev_phys, D[:, 0]))
        if _clearly_less(float(self._cost(x, U, ref, u_prev, D)), best.cost):
            other = solve_from(U)
            if _clearly_less(other.cost, best.cost):
                best = replace(other, iterations=best.iterations + other.iterations)
        return best


def _clearly_less(a: float, b: float) -> bool:
    """``a < b`` by more than rounding: a restart replaces a solution only where it is really better."""
    return a < b - 1e-6 * abs(b) - 1e-12
