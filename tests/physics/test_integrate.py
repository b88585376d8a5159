"""The one RK4 (physics.rk_step): both tableaux match their textbook formulas and converge at order 4."""

import numpy as np
import pytest

from physics import CLASSIC, THREE_EIGHTHS, rk_step


def f(t, y):
    return np.array([y[1], -4.0 * y[0] + np.sin(t)]) * (1 + 0.1 * np.cos(y[0]))


def classic(t, y, h):
    k1 = f(t, y)
    k2 = f(t + h / 2, y + h / 2 * k1)
    k3 = f(t + h / 2, y + h / 2 * k2)
    k4 = f(t + h, y + h * k3)
    return y + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


def three_eighths(t, y, h):  # torchdiffeq's rk4_alt_step_func
    k1 = f(t, y)
    k2 = f(t + h / 3, y + h * k1 / 3)
    k3 = f(t + 2 * h / 3, y + h * (k2 - k1 / 3))
    k4 = f(t + h, y + h * (k1 - k2 + k3))
    return y + (k1 + 3 * (k2 + k3) + k4) * h * 0.125


@pytest.mark.parametrize("tableau, reference", [(CLASSIC, classic), (THREE_EIGHTHS, three_eighths)])
def test_tableau_matches_the_textbook_step(tableau, reference):
    y = np.array([0.3, -1.2])
    for h in (0.5, 0.05, 0.001):
        np.testing.assert_allclose(rk_step(f, 0.7, y, h, tableau), reference(0.7, y, h), rtol=0, atol=1e-12)


@pytest.mark.parametrize("tableau", [CLASSIC, THREE_EIGHTHS])
def test_convergence_order_is_four(tableau):
    def solve(n):
        y, h = np.array([1.0]), 1.0 / n
        for i in range(n):
            y = rk_step(lambda t, v: -2.0 * t * v, i * h, y, h, tableau)
        return y[0]

    exact = np.exp(-1.0)
    errors = [abs(solve(n) - exact) for n in (16, 32, 64, 128)]
    order = np.polyfit(np.log([16, 32, 64, 128]), np.log(errors), 1)[0]
    assert -order == pytest.approx(4.0, abs=0.3)
