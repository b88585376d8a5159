"""The speed-ups of a fit change no number: the compiled rollouts equal the interpreted ones bit for bit,
and the residuals' Jacobian read from bound buffers equals a call's."""

import numpy as np
import pytest

from identification import _sensitivity
from identification._problem import _LastPoint
from physics import BLOCKS, Series

DT = 0.04
SPECS = ["lag+backlash+linear", "boucwen+linear", "gpi+poly+linear", "resonance+creep+linear",
         "hysteretic_oscillator+linear", "preisach+linear"]


@pytest.mark.skipif(not _sensitivity.jit_available(), reason="needs a C compiler")
@pytest.mark.parametrize("spec", SPECS)
def test_a_compiled_rollout_is_the_interpreted_one_bit_for_bit(spec):
    assert all(name in BLOCKS for name in spec.split("+"))
    model = Series.from_spec(spec, dt=DT)
    n = 400
    t = np.arange(n) * DT
    u = (1.5 + np.sin(2 * np.pi * 0.3 * t) * np.exp(-0.1 * t))[None, :]
    rng = np.random.default_rng(0)
    for p in (model.params, np.clip(model.params * (1 + 0.2 * rng.standard_normal(model.n_p)),
                                    model.lower_bounds, model.upper_bounds)):
        x0 = model.steady_state(u[0, 0], p)
        compiled = _sensitivity.plain_rollout(model, n, jit=True)(x0, u, p)
        interpreted = model.rollout(n)(x0, u, p)
        for a, b in zip(compiled, interpreted):
            assert np.array_equal(np.asarray(a), np.asarray(b), equal_nan=True)


def test_the_jacobian_read_from_bound_buffers_is_the_calls():
    import casadi as ca

    w = ca.MX.sym("w", 3)
    sparse_block = ca.horzcat(ca.sin(w[0]) * ca.DM.ones(5, 1), ca.MX(5, 1), w[1] * w[2] * ca.DM.ones(5, 1))
    f = ca.Function("residuals", [w], [ca.vertcat(w[0] - 1, w[1] ** 2, ca.exp(w[2])), sparse_block])
    point = _LastPoint(f)
    for value in ([0.3, -1.2, 2.0], [1.0, 0.5, -0.25]):
        r, J = point(np.array(value))
        assert np.array_equal(r, f(value)[0].full()) and np.array_equal(J, f(value)[1].full())
        assert J.shape == (5, 3) and not np.shares_memory(J, point._out[1])  # a copy of its own
