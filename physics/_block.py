"""The block contract: a small discrete-time state-space piece written in CasADi.

Every block follows one convention. At sample ``k`` it receives its state ``x_k``
(memory of samples ``< k``) and the input ``u_k`` and returns ``(x_{k+1}, y_k)``;
``y_k`` may depend on ``u_k`` (direct feed-through), which is what exact
discretisation of a continuous block with the input interpolated linearly between
samples requires.
"""

from __future__ import annotations

import abc
from dataclasses import dataclass
from typing import ClassVar

import casadi as ca
import numpy as np

from ._errors import PhysicsError


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


class AbstractBlock(abc.ABC):
    """Abstract base of all blocks; concrete blocks are final (never subclassed).

    Parameter values are keyword arguments of ``__init__`` and are stored as
    attributes of the same name. Structural settings (grid sizes, delay length,
    smoothing) are plain attributes and are not identified.
    """

    name: ClassVar[str]
    parameters: ClassVar[tuple[Parameter, ...]] = ()
    #: True when ``step`` is differentiable in ``u`` (Newton may invert it).
    smooth_in_input: ClassVar[bool] = True

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
    continuous_states: ClassVar[tuple[str, ...] | None] = ()

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

    def __repr__(self) -> str:
        args = ", ".join(f"{p.name}={getattr(self, p.name):.6g}" for p in self.parameters)
        return f"{type(self).__name__}({args})"


def smooth_abs(x, eps: float = 1e-6):
    """|x| smoothed near zero so that gradients exist: sqrt(x^2 + eps^2)."""
    return ca.sqrt(x * x + eps * eps)
