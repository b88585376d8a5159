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
