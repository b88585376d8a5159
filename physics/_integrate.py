"""One explicit Runge-Kutta scheme, from a Butcher tableau: classic RK4 and the 3/8 rule.

Used by the Bouc-Wen block (along the input path) and the neural-ODE hybrid's
CasADi export (torchdiffeq's
``'rk4'`` is the 3/8 rule). Works on CasADi SX/MX/DM, numpy arrays or floats.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

__all__ = ["Tableau", "CLASSIC", "THREE_EIGHTHS", "rk_step"]


@dataclass(frozen=True)
class Tableau:
    """Butcher tableau of an explicit method: stage weights ``a`` (lower triangle), ``b``, nodes ``c``."""

    a: tuple[tuple[float, ...], ...]
    b: tuple[float, ...]
    c: tuple[float, ...]


#: Classic fourth-order Runge-Kutta.
CLASSIC = Tableau(a=((), (0.5,), (0.0, 0.5), (0.0, 0.0, 1.0)),
                  b=(1 / 6, 1 / 3, 1 / 3, 1 / 6), c=(0.0, 0.5, 0.5, 1.0))

#: Kutta's 3/8 rule (torchdiffeq's ``method='rk4'``).
THREE_EIGHTHS = Tableau(a=((), (1 / 3,), (-1 / 3, 1.0), (1.0, -1.0, 1.0)),
                        b=(1 / 8, 3 / 8, 3 / 8, 1 / 8), c=(0.0, 1 / 3, 2 / 3, 1.0))


def rk_step(f: Callable, t, y, h, tableau: Tableau = CLASSIC):
    """One step of ``dy/dt = f(t, y)`` from ``(t, y)`` over ``h``."""
    ks = []
    for ai, ci in zip(tableau.a, tableau.c):
        yi = y
        for aij, kj in zip(ai, ks):
            if aij != 0.0:
                yi = yi + (h * aij) * kj
        ks.append(f(t + ci * h, yi))
    incr = 0
    for bi, ki in zip(tableau.b, ks):
        incr = incr + bi * ki
    return y + h * incr
