"""The CasADi graphs identification differentiates: step vs rollout, Jacobians vs finite
differences, and the sensitivity rollouts identify() builds on them."""

import casadi as ca
import numpy as np
import pytest

from identification._sensitivity import SensitivityRollouts
from physics import (
    Backlash, BoucWen, Delay, Drift, Lag, LinearMap, Poly, Preisach, Series,
)

DT = 0.04
BLOCKS = {
    "lag": lambda: Lag(time_constant_s=0.2),
    "delay": lambda: Delay(samples=3),
    "backlash": lambda: Backlash(width=0.5),
    "boucwen": lambda: BoucWen(A=0.5, beta=1.0, gamma=0.4, n=1.5),
    "preisach": lambda: Preisach(levels=4),
    "poly": lambda: Poly(c2=0.05, c3=-0.01, center=3.0),
    "linear": lambda: LinearMap(gain=10.0, offset=30.0),
    "drift": lambda: Drift(rate=0.1),
}


def _input(n=120):
    t = np.arange(n) * DT
    return 3 + 2.5 * np.sin(2 * np.pi * 0.4 * t) * np.exp(-0.1 * t) + 0.3 * np.sin(7 * t)


@pytest.mark.parametrize("name", sorted(BLOCKS))
def test_step_in_a_python_loop_matches_rollout_and_simulate(name):
    model = Series(BLOCKS[name](), LinearMap(gain=2.0, offset=1.0), dt=DT)
    u = _input()
    step = model.step_function()
    x = model.steady_state(u[0])
    ys = []
    for uk in u:
        x_next, y = step(x, uk, model.params)
        ys.append(float(y))
        x = np.asarray(x_next, dtype=float).ravel()
    np.testing.assert_allclose(ys, model.simulate(u), rtol=0, atol=1e-12)


def _central(f, v, h):
    cols = []
    for k in range(v.size):
        e = np.zeros_like(v)
        e[k] = h
        cols.append((f(v + e) - f(v - e)) / (2 * h))
    return np.column_stack(cols) if cols else np.zeros((f(v).size, 0))


@pytest.mark.parametrize("name", sorted(BLOCKS))
def test_step_jacobians_match_central_differences(name):
    model = Series(BLOCKS[name](), dt=DT)
    step = model.step_function()
    u = _input()
    x = np.asarray(model.simulate(u, return_states=True)[1][60], dtype=float)
    uk, p = float(u[60]), model.params
    if name == "preisach":  # keep u away from the relay thresholds, where it is a step
        uk = float(np.round(uk / 1.5) * 1.5)  # cell edges lie midway between thresholds
    xs, us, ps = ca.SX.sym("x", model.n_x), ca.SX.sym("u"), ca.SX.sym("p", model.n_p)
    xn, y = step(xs, us, ps)
    out = ca.vertcat(xn, y)
    jac = ca.Function("step_jacobians", [xs, us, ps], [ca.jacobian(out, v) for v in (xs, us, ps)])
    analytic = [np.asarray(J, dtype=float) for J in jac(x, uk, p)]

    def value(x_, u_, p_):
        xn_, y_ = step(x_, u_, p_)
        return np.r_[np.asarray(xn_, dtype=float).ravel(), float(y_)]

    h = 1e-6
    numeric = [
        _central(lambda v: value(v, uk, p), x, h),
        _central(lambda v: value(x, v[0], p), np.array([uk]), h),
        _central(lambda v: value(x, uk, v), p, h),
    ]
    for what, a, n in zip(("x", "u", "p"), analytic, numeric):
        np.testing.assert_allclose(a, n, rtol=1e-5, atol=1e-6, err_msg=f"d/d{what} of {name}")


@pytest.mark.parametrize("spec, jit", [("lag+boucwen+linear", False), ("lag+boucwen+linear", None),
                                       ("backlash+linear", False), ("preisach+linear", False)])
def test_sensitivity_rollout_matches_finite_differences(spec, jit):
    model = Series.from_spec(spec, dt=DT)
    u = _input(80)
    free = model.fit_mask
    sens = SensitivityRollouts(model, free, with_x0=True, jit=jit)
    x0 = model.steady_state(u[0])
    y, dy = (np.asarray(v, dtype=float) for v in sens(u.size)(x0, u[None, :], model.params))
    np.testing.assert_allclose(y.ravel(), model.simulate(u, x0=x0), atol=1e-12)
    idx = np.flatnonzero(free)
    p0 = model.params

    def sim_p(v):
        p = p0.copy()
        p[idx] = v
        return model.simulate(u, x0=x0, p=p)

    fd = np.hstack([_central(sim_p, p0[idx], 1e-6),
                    _central(lambda v: model.simulate(u, x0=v, p=p0), np.asarray(x0, float), 1e-6)])
    if spec.startswith("preisach"):  # relay states do not move continuously with x0
        fd, dy = fd[:, : idx.size], dy[: idx.size]
    np.testing.assert_allclose(dy.T, fd, rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("spec", ["lag+gpi+poly+linear", "resonance+backlash+gpi+poly+linear",
                                  "resonance+backlash+gpi+poly+creep+linear"])
@pytest.mark.parametrize("with_x0", [False, True])
def test_sparse_sensitivities_match_forward_mode_over_the_rollout(spec, with_x0):
    """Only the sensitivities that can be nonzero are propagated (a play's state does not move with the
    weights that read it); the Jacobian is CasADi's own forward mode over the whole rollout's. The
    limit counts those entries: the creep spec with x0 (13 states x 30 directions, 390 dense) used to
    fall back to forward mode, 20 times as slow per fit."""
    model = Series.from_spec(spec, dt=DT)
    u = _input(120)
    free = model.fit_mask
    sens = SensitivityRollouts(model, free, with_x0=with_x0, jit=False)
    assert sens.augmented and sens._pattern.nnz() < model.n_x * sens.d
    rng = np.random.default_rng(3)
    p = model.params * (1 + 0.05 * rng.standard_normal(model.n_p))
    x0 = model.steady_state(u[0], p)
    y, dy = (np.asarray(v, dtype=float) for v in sens(u.size)(x0, u[None, :], p))
    X0, P = ca.MX.sym("x0", model.n_x), ca.MX.sym("p", model.n_p)
    _, ys = model.rollout(u.size)(X0, ca.DM(u[None, :]), P)
    parts = [ca.jacobian(ys.T, P)[:, np.flatnonzero(free).tolist()]] + ([ca.jacobian(ys.T, X0)] if with_x0 else [])
    reference = ca.Function("reference", [X0, P], [ys, ca.horzcat(*parts)])
    y_ref, J_ref = (np.asarray(v, dtype=float) for v in reference(x0, p))
    np.testing.assert_allclose(y, y_ref, rtol=0, atol=1e-12)
    np.testing.assert_allclose(dy.T, J_ref, rtol=1e-10, atol=1e-10 * np.abs(J_ref).max())


@pytest.mark.parametrize("spec", ["lag+gpi+poly+linear", "lag+backlash+boucwen+linear", "gpi+poly+creep+linear"])
def test_compiled_chunks_give_the_rollouts_numbers_bit_for_bit_at_any_length(spec):
    """Compiled rollouts run CHUNK steps per call, the input padded with its last value to whole chunks
    (what the padded steps give is dropped), and their steps compute each repeated subexpression once:
    the same numbers as the model's own rollout and the interpreted sensitivities, bit for bit, at lengths
    below, at and around a chunk's."""
    from identification import _sensitivity

    if not _sensitivity.jit_available():
        pytest.skip("needs a C compiler")
    model = Series.from_spec(spec, dt=DT)
    rng = np.random.default_rng(5)
    p = model.params * (1 + 0.05 * rng.standard_normal(model.n_p))
    compiled, interpreted = (SensitivityRollouts(model, model.fit_mask, with_x0=True, jit=jit) for jit in (True, False))
    for n in (1, _sensitivity.CHUNK - 1, _sensitivity.CHUNK, _sensitivity.CHUNK + 1, 2 * _sensitivity.CHUNK + 7):
        u = _input(n)[None, :]
        x0 = model.steady_state(u[0, 0], p)
        xs, ys = (np.asarray(v) for v in _sensitivity.plain_rollout(model, n, jit=True)(x0, u, p))
        xs_ref, ys_ref = (np.asarray(v) for v in model.rollout(n)(x0, u, p))
        assert ys.shape == (1, n) and xs.shape == (model.n_x, n)
        np.testing.assert_array_equal(ys, ys_ref)
        np.testing.assert_array_equal(xs, xs_ref)
        for a, b in zip(compiled(n)(x0, u, p), interpreted(n)(x0, u, p)):
            np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
