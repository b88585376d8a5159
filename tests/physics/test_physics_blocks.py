"""Physics blocks against exact solutions and their documented behaviour."""

import numpy as np
import pytest

from physics import (
    Backlash, BoucWen, Delay, Drift, Lag, LinearMap, PhysicsError, Poly, Preisach, Series,
    model_from_spec,
)


def test_lag_is_exact_for_a_ramp():
    # T x' = u - x with u = r t from rest: x(t) = r (t - T (1 - exp(-t/T)))
    T, r, dt = 0.12, 2.0, 0.04
    t = np.arange(0, 2, dt)
    y = Series(Lag(time_constant_s=T), dt=dt).simulate(r * t)
    np.testing.assert_allclose(y, r * (t - T * (1 - np.exp(-t / T))), atol=1e-12)


def test_lag_phase_grows_with_frequency():
    dt, T = 0.04, 0.12
    model = Series(Lag(time_constant_s=T), dt=dt)
    lags = []
    for f in (0.1, 0.5):
        t = np.arange(0, 20 / f, dt)
        u = np.sin(2 * np.pi * f * t)
        y = model.simulate(u)
        half = t.size // 2  # after the transient
        ref = np.exp(-2j * np.pi * f * t[half:])
        phase = np.angle(np.sum(y[half:] * ref) / np.sum(u[half:] * ref))
        lags.append(-phase)
        np.testing.assert_allclose(-phase, np.arctan(2 * np.pi * f * T), atol=0.01)
    assert lags[1] > 3 * lags[0]


def test_boucwen_matches_the_loading_curve_and_is_rate_independent():
    # n = 1, monotone loading from z = 0: z = A/(b+g) (1 - exp(-(b+g) u))
    A, b, g = 0.5, 1.0, 0.5
    u = np.linspace(0, 2, 201)
    bw = Series(BoucWen(A=A, beta=b, gamma=g, substeps=4))
    z = u - bw.simulate(u)
    np.testing.assert_allclose(z, A / (b + g) * (1 - np.exp(-(b + g) * u)), atol=1e-6)
    # the same path sampled at another rate gives the same output at the same inputs
    coarse = Series(BoucWen(A=A, beta=b, gamma=g, substeps=4), dt=0.5).simulate(u[::4])
    np.testing.assert_allclose(coarse, bw.simulate(u)[::4], atol=1e-3)
    assert np.max(np.abs(z)) > 0.25


def test_boucwen_loop_saturates_and_opens():
    t = np.arange(0, 30, 0.04)
    u = 3 - 3 * np.cos(2 * np.pi * 0.1 * t)
    y = Series(BoucWen(A=0.5, beta=1.0, gamma=0.5)).simulate(u)
    z = u - y
    assert np.max(np.abs(z)) <= 0.5 / 1.5 + 1e-6
    rising = np.gradient(u) > 0
    mid = np.abs(u - 3) < 0.05
    assert np.mean(z[mid & rising]) > 0.2 > -0.2 > np.mean(z[mid & ~rising])
    assert np.mean(y[mid & rising]) < np.mean(y[mid & ~rising])  # tip lags the tendon


def test_backlash_flat_zone_and_smooth_error_bound():
    rng = np.random.default_rng(0)
    t = np.arange(0, 60, 0.04)
    worst = 0.0
    for _ in range(10):
        u = 3 + sum(rng.uniform(0.2, 1.2) * np.sin(2 * np.pi * rng.uniform(0.05, 2) * t
                                                   + rng.uniform(0, 6)) for _ in range(4))
        u[500:900] = u[500]  # a long hold must not make the smooth output drift
        for s in (0.001, 0.01, 0.05):
            w = rng.uniform(0, 1)
            smooth = Series(Backlash(width=w, smoothing=s)).simulate(u)
            sharp = Series(Backlash(width=w, smoothing=0)).simulate(u)
            worst = max(worst, np.max(np.abs(smooth - sharp)) / s)
    assert worst <= 0.5 + 1e-9
    # after a reversal the output stays put until the input has moved the width
    u = np.concatenate([np.linspace(0, 2, 50), np.linspace(2, 0, 50)])
    y = Series(Backlash(width=0.4, smoothing=0)).simulate(u)
    back = (u[50:] > 2 - 0.4 + 1e-9)
    np.testing.assert_allclose(y[50:][back], y[49])


def test_delay_shifts_by_whole_samples():
    u = np.arange(10.0)
    np.testing.assert_array_equal(Series(Delay(samples=3)).simulate(u),
                                  [0, 0, 0, 0, 1, 2, 3, 4, 5, 6])
    np.testing.assert_array_equal(Series(Delay(samples=0)).simulate(u), u)


def test_drift_poly_linear():
    dt = 0.5
    y = Series(Drift(rate=2.0), dt=dt).simulate(np.zeros(4))
    np.testing.assert_allclose(y, [0, 1, 2, 3])
    u = np.array([1.0, 3.0, 5.0])
    y = Series(Poly(c2=0.1, c3=0.01, center=3.0), LinearMap(gain=2, offset=1)).simulate(u)
    np.testing.assert_allclose(y, 2 * (u + 0.1 * (u - 3) ** 2 + 0.01 * (u - 3) ** 3) + 1)


def test_poly_continues_along_its_tangent_beyond_the_range_it_was_fitted_on():
    """Inside ``[lo, hi]`` the cubic; beyond it, the cubic's value and slope at the edge (the
    ODE form's output rate too); ``identify`` sets the range to what the poly's own input (here
    a lag's output, not the model's input) spanned on the data."""
    from identification import identify
    from physics.data import Trajectory

    cubic = Poly(c2=0.1, c3=0.05, center=1.0)
    held = Poly(c2=0.1, c3=0.05, center=1.0, lo=0.0, hi=2.0)
    u = np.array([-1.0, 0.0, 0.5, 2.0, 3.0])
    f = lambda v: v + 0.1 * (v - 1) ** 2 + 0.05 * (v - 1) ** 3  # noqa: E731
    slope = lambda v: 1 + 0.2 * (v - 1) + 0.15 * (v - 1) ** 2  # noqa: E731
    np.testing.assert_allclose(Series(cubic).simulate(u), f(u))
    np.testing.assert_allclose(Series(held).simulate(u), [f(0.0) - slope(0.0), f(0.0), f(0.5), f(2.0), f(2.0) + slope(2.0)])
    _, y, ydot = held.derivative(None, 3.0, 2.0, held.param_values())
    assert float(y) == pytest.approx(f(2.0) + slope(2.0)) and float(ydot) == pytest.approx(2.0 * slope(2.0))
    with pytest.raises(ValueError, match="lo and hi"):
        Poly(lo=1.0)
    dt = 0.05
    t = np.arange(0, 20, dt)
    x = 1 + np.sin(2 * np.pi * 0.2 * t)
    truth = Series(Lag(time_constant_s=0.5), Poly(c2=0.1, c3=0.05, center=1.0), LinearMap(gain=2.0, offset=1.0), dt=dt)
    run = Trajectory(time=t, u=x, y=truth.simulate(x))
    fitted = identify(Series.from_spec("lag+poly+linear", dt=dt), [run]).model().blocks[1]
    seen = Series(Lag(time_constant_s=0.5), dt=dt).simulate(x)
    assert fitted.lo == pytest.approx(seen.min(), abs=2e-3) and fitted.hi == pytest.approx(seen.max(), abs=2e-3)
    assert Series.from_dict(Series(fitted).to_dict()).blocks[0].get_settings()["lo"] == fitted.lo
    # fitted again on a wider run (discovery refits fitted models): the range is measured afresh
    wide = 1 + 1.5 * np.sin(2 * np.pi * 0.2 * t)
    again = identify(Series(*[b for b in identify(Series.from_spec("lag+poly+linear", dt=dt), [run]).model().blocks],
                            dt=dt), [Trajectory(time=t, u=wide, y=truth.simulate(wide))])
    assert again.model().blocks[1].lo < seen.min() - 0.3 and again.train_rmse < 1e-3


def test_preisach_output_range_memory_and_monotone():
    model = Series(Preisach(levels=8, lower=0, upper=6))
    t = np.arange(0, 20, 0.04)
    u = 3 - 3.5 * np.cos(2 * np.pi * 0.1 * t)
    y = model.simulate(u)
    assert y.min() >= 0 - 1e-12 and y.max() <= 6 + 1e-12
    assert np.isclose(y.max(), 6) and np.isclose(y[u <= u.min() + 1e-9].min(), 0)
    rising = np.gradient(u) > 0
    mid = np.abs(u - 3) < 0.1
    assert y[mid & rising].mean() < y[mid & ~rising].mean()  # a loop opens


@pytest.mark.parametrize("spec", [
    "lag+boucwen+linear", "lag+linear", "boucwen+linear", "lag+poly+drift+linear",
    "delay+lag+boucwen+linear",
])
def test_inverse_of_forward_returns_the_input_on_held_out_paths(spec):
    rng = np.random.default_rng(1)
    t = np.arange(0, 40, 0.04)
    u = 3 + sum(rng.uniform(0.3, 0.8) * np.sin(2 * np.pi * rng.uniform(0.05, 0.6) * t
                                               + rng.uniform(0, 6)) for _ in range(3))
    model = model_from_spec(spec)
    u_back = model.inverse(model.simulate(u))
    d = sum(b.samples for b in model.blocks if isinstance(b, Delay))
    np.testing.assert_allclose(u_back[: u.size - d], u[: u.size - d], atol=1e-8)


@pytest.mark.parametrize("blocks", [
    (Backlash(width=0.3, smoothing=0), LinearMap()),
    (Lag(), Backlash(width=0.3, smoothing=0), BoucWen(), LinearMap()),
    (Preisach(levels=10), LinearMap()),
])
def test_forward_of_inverse_follows_the_wanted_path(blocks):
    # backlash and Preisach are not one-to-one: the inverse is a right inverse
    model = Series(*blocks)
    t = np.arange(0, 40, 0.04)
    u = 3 - 2.5 * np.cos(2 * np.pi * 0.2 * t) * np.exp(-0.02 * t)
    y = model.simulate(u)
    u0 = model.steady_input(y[0])
    u_back = model.inverse(y)
    y_back = model.simulate(u_back, x0=model.steady_state(u0))
    tol = 1e-8 if not isinstance(blocks[0], Preisach) else 1e-6
    np.testing.assert_allclose(y_back, y, atol=tol)


def test_step_function_agrees_with_simulate():
    model = model_from_spec("lag+backlash+boucwen+linear")
    u = 3 - 3 * np.cos(np.linspace(0, 12, 300))
    step = model.step_function()
    x, ys = model.steady_state(u[0]), []
    for uk in u:
        x, yk = step(x, uk, model.params)
        ys.append(float(yk))
    y, states = model.simulate(u, return_states=True)
    np.testing.assert_allclose(ys, y, atol=1e-12)
    assert states.shape == (u.size, model.n_x)


def test_names_params_and_spec():
    model = model_from_spec("lag+boucwen+linear")
    assert model.spec == "lag+boucwen+linear"
    assert model.param_names[0] == "lag.time_constant_s"
    assert model.state_names == ["lag.position", "lag.u_prev", "boucwen.z", "boucwen.u_prev"]
    model.set_params(**{"linear.gain": 5.0})
    assert model.param_dict()["linear.gain"] == 5.0
    assert model_from_spec("boucwen+boucwen").param_names[4] == "boucwen2.A"


@pytest.mark.parametrize("call, match", [
    (lambda: model_from_spec("lag+foo"), "Unknown block 'foo'. Must be one of"),
    (lambda: model_from_spec("lag++linear"), "Bad model spec"),
    (lambda: BoucWen(n=0.5), "'n' parameter of BoucWen must be in"),
    (lambda: Series(Lag(), dt=0), "dt must be > 0"),
    (lambda: Series(Lag()).simulate([0.0, np.nan]), "non-finite value at index 1"),
    (lambda: Series(Lag()).simulate(np.zeros(3), x0=[0.0]), "x0 must have 2 entries"),
    (lambda: Series(Lag()).set_params(foo=1), "Unknown parameter"),
    (lambda: Series(Lag()).set_params(**{"lag.time_constant_s": np.nan}), "'lag.time_constant_s' parameter .* "
     "must be a finite number. Got nan"),  # was stored, and every simulation was NaN
    (lambda: Series(Lag()).set_params(**{"lag.time_constant_s": "fast"}), "finite number. Got 'fast'"),
])
def test_clear_errors(call, match):
    with pytest.raises(PhysicsError, match=match):
        call()


@pytest.mark.parametrize("spec, tol", [("lag+boucwen+linear", 0.02),
                                       ("backlash+boucwen+poly+linear+drift", 0.05)])
def test_continuous_form_integrates_to_the_discrete_model(spec, tol):
    # RK4 on the ODE form with a fine step agrees with the exact discrete model
    # (first order only across the sharp backlash's switches: a looser bound)
    import casadi as ca
    model = model_from_spec(spec)
    for b in model.blocks:
        if isinstance(b, Backlash):
            b.smoothing = 0.0
    dt, sub = 0.04, 10
    t = np.arange(0, 5, dt)
    u = 3 - 2.5 * np.cos(2 * np.pi * 0.3 * t)
    ode = model.ode_function()
    p = model.params
    xc = model.continuous_steady_state(u[0])
    y_ode = [float(ode(xc, u[0], 0.0, p)[1])]
    h = dt / sub
    for k in range(1, t.size):
        rate = (u[k] - u[k - 1]) / dt
        for j in range(sub):
            uk = u[k - 1] + rate * j * h
            f = lambda x, s: np.asarray(ode(x, uk + rate * s, rate, p)[0]).ravel()
            k1 = f(xc, 0); k2 = f(xc + h / 2 * k1, h / 2); k3 = f(xc + h / 2 * k2, h / 2)
            k4 = f(xc + h * k3, h)
            xc = xc + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        y_ode.append(float(ode(xc, u[k], rate, p)[1]))
    np.testing.assert_allclose(y_ode, model.simulate(u), atol=tol)


def test_blocks_without_a_continuous_form_are_named():
    with pytest.raises(PhysicsError, match="delay have no continuous-time form"):
        model_from_spec("delay+linear").ode_function()


def test_boucwen_follows_input_jumps_far_larger_than_its_substeps_were_set_for(monkeypatch):
    """RK4 along a jump of 10 input units with a loop that saturates within 0.3 of them blew up
    (1e125, or NaN); the exponential substep keeps the block on the fine solution."""
    import physics._boucwen as bw

    def model(substeps, beta=2.0, gamma=1.0, n=1.0):
        return Series(BoucWen(A=0.6, beta=beta, gamma=gamma, n=n, substeps=substeps), LinearMap(gain=1.0, offset=0.0))

    rng = np.random.default_rng(0)
    u = np.repeat(rng.uniform(-5, 5, 40), 5)
    for n in (1.0, 2.0):
        for beta, gamma in ((1.7, -1.3), (2.0, 1.0), (5.0, 0.0), (0.0, 3.0), (0.5, 1.5), (0.2, 2.0)):
            # RK4 at 1/200 of each jump: within 2e-5 of the span of 4000 substeps on every case
            fine = model(200, beta, gamma, n).simulate(u)
            coarse = model(2, beta, gamma, n).simulate(u)
            # gamma > beta (z runs back to 0 faster than it left): first order through the crossing
            share = 0.05 if beta >= abs(gamma) else 0.1
            assert np.max(np.abs(coarse - fine)) < share * np.ptp(fine), (n, beta, gamma)
    # the reference is converged: doubling its substeps moves it by far less than the tolerance
    finer = model(400, 0.0, 3.0, 1.0).simulate(u)
    assert np.max(np.abs(finer - model(200, 0.0, 3.0, 1.0).simulate(u))) < 1e-3 * np.ptp(finer)
    # steps as small as those a block is fitted on stay plain RK4: the same numbers as before
    slow = 3 - 3 * np.cos(np.linspace(0, 12, 600))
    assert np.max(np.abs(np.diff(slow))) * (2.0 + 1.0) / 2 < bw.LARGE_DECAY
    default = model(2).simulate(slow)
    monkeypatch.setattr(bw, "LARGE_DECAY", np.inf)
    np.testing.assert_array_equal(model(2).simulate(slow), default)
