"""One objective: with a warm-up window, identification minimises the error every model is scored on
(each run's state set by its first K samples, then simulated free), and reports that error."""

import numpy as np
import pytest

from identification import IdentificationError, SolverSettings, identify
from physics import Series
from physics.data import Trajectory

DT = 0.05
TRUE = {"lag.time_constant_s": 0.5, "backlash.width": 0.6, "linear.gain": 8.0, "linear.offset": 20.0}


def _runs():
    """Runs that do not start at rest: the play starts at one edge of its band, the lag mid-way."""
    truth = Series.from_spec("lag+backlash+linear", dt=DT).set_params(**TRUE)
    rng = np.random.default_rng(0)
    runs = []
    for i, f in enumerate((0.2, 0.3, 0.45)):
        t = np.arange(300) * DT
        u = 2.0 + 1.5 * np.sin(2 * np.pi * f * t + i)
        x0 = truth.steady_state(u[0])
        x0[0] += 0.8 * (-1) ** i  # the lag's position away from its input
        runs.append(Trajectory(t, u, truth.simulate(u, x0=x0) + rng.normal(0, 0.02, u.size), source=f"r{i}"))
    return runs


def _scored(model, runs, k):
    e = np.concatenate([model.simulate(r.u[k:], warmup=(r.u[:k], r.y[:k])) - r.y[k:] for r in runs])
    return float(np.sqrt(np.mean(e**2)))


def test_the_fit_minimises_the_scored_error_and_reports_it():
    runs = _runs()
    rest = identify(Series.from_spec("lag+backlash+linear", dt=DT), runs, solver=SolverSettings(max_iter=200)).model()  # from rest
    for k in (10, 20):
        warm = identify(Series.from_spec("lag+backlash+linear", dt=DT), runs, warmup=k, solver=SolverSettings(max_iter=200))
        assert warm.train_rmse == pytest.approx(_scored(warm.model(), runs, k), rel=1e-9)  # what the card shows
        assert warm.train_rmse < (0.9 if k == 10 else 0.5) * _scored(rest, runs, k)
    # a window long enough to show the state: the truth, at the noise (0.02)
    assert warm.train_rmse < 0.025
    for name, value in TRUE.items():
        assert warm.parameters[name] == pytest.approx(value, rel=0.02), name


def test_a_warm_up_needs_a_steady_x0_and_room_to_fit():
    runs = _runs()
    with pytest.raises(IdentificationError, match="not both"):
        identify(Series.from_spec("lag+linear", dt=DT), runs, warmup=5, x0="estimate")
    with pytest.raises(IdentificationError, match="whole number"):
        identify(Series.from_spec("lag+linear", dt=DT), runs, warmup=-1)
    with pytest.raises(IdentificationError, match="leaves too little"):
        identify(Series.from_spec("lag+linear", dt=DT), runs, warmup=299)


@pytest.mark.parametrize("spec", ["lag+backlash+linear", "lag+gpi+poly+linear", "gpi+poly+creep+linear"])
def test_the_fits_expanded_window_state_and_its_jacobian_equal_the_written_ones(spec):
    # identify(warmup=) differentiates the window's state at every iterate through the expanded window
    # fit (scalar operations, several times as fast); predictions and scores use it as written
    import casadi as ca

    from physics._warmup import init_function, scales

    model = Series.from_spec(spec, dt=DT)
    u_w = 2.0 + np.sin(np.linspace(0.0, 2.0, 10))
    y_w = model.simulate(u_w) + 0.05 * np.cos(np.arange(10.0))
    s_x, s_y = scales(model, u_w, y_w, model.params)
    P = ca.MX.sym("p", model.n_p)
    values = []
    for expanded in (False, True):
        x = init_function(model, 10, False, expanded=expanded)(u_w[None, :], y_w[None, :], P, s_x, s_y)[0]
        values.append([np.asarray(v, dtype=float) for v in ca.Function("f", [P], [x, ca.jacobian(x, P)])(model.params)])
    (x_written, J_written), (x_expanded, J_expanded) = values
    assert np.abs(J_written).max() > 0  # the state does move with the parameters
    np.testing.assert_allclose(x_expanded, x_written, rtol=1e-10, atol=1e-12 * np.abs(x_written).max())
    np.testing.assert_allclose(J_expanded, J_written, rtol=1e-8, atol=1e-10 * np.abs(J_written).max())


def test_only_short_windows_are_differentiated_through_the_expanded_fit(monkeypatch):
    # the expanded window fit's scalar graph grows about 3 MB a sample: longer windows use it as written
    from identification._problem import EXPANDED_WINDOW
    from physics import _warmup

    asked = []
    written = _warmup.init_function

    def spy(*args, **kwargs):
        asked.append((args[1], kwargs.get("expanded", False)))
        return written(*args, **kwargs)

    monkeypatch.setattr(_warmup, "init_function", spy)
    runs = _runs()
    for k in (10, EXPANDED_WINDOW + 8):
        asked.clear()
        identify(Series.from_spec("lag+backlash+linear", dt=DT), runs, warmup=k, solver=SolverSettings(max_iter=5),
                 allow_failure=True)
        assert asked and {n for n, _ in asked} == {k}
        # the problem's window state (scores and predictions always use the function as written)
        assert any(expanded for _, expanded in asked) == (k <= EXPANDED_WINDOW)
