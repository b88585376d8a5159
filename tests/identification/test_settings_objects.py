"""Settings travel as frozen objects validated when built (issue 44), and the physics policy carries the
neural ODE's fallback: ``requires`` and ``max_tries`` (``physics_fits``)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from hybrid.experiments import Columns, fit_model_dir
from identification import (DiscoveryThresholds, FitResult, IdentificationError, PhysicsPolicy, PhysicsReport,
                            Ranking, SelectionSettings, SolverSettings, Workers, discover, fit_physics,
                            fitted_series, identify, physics_fits, select_physics)
from physics import Series
from physics.data import DataError, Trajectory

DT = 0.04
TRUTH = {"lag.time_constant_s": 0.3, "linear.gain": 2.0, "linear.offset": 1.0}


def _run(f=0.5, n=200, seed=0):
    truth = Series.from_spec("lag+linear", dt=DT).set_params(**TRUTH)
    t = np.arange(n) * DT
    u = np.sin(2 * np.pi * f * t)
    return Trajectory(t, u, truth.simulate(u) + 0.01 * np.random.default_rng(seed).normal(size=n), source=f"f{f}")


@pytest.mark.parametrize("build, match", [
    (lambda: SolverSettings(max_iter=0), "max_iter must be an integer >= 1"),
    (lambda: SolverSettings(max_wall_time=-1.0), "max_wall_time must be None or > 0"),
    (lambda: SolverSettings(method="multiple"), "method must be one of single"),
    (lambda: SolverSettings(ipopt_options=[("tol", 1e-8)]), "ipopt_options must be a dict"),
    (lambda: SolverSettings(jit="yes"), "jit must be True, False or None"),
    (lambda: SelectionSettings(margin=1.0), r"margin must be in \[0, 1\)"),
    (lambda: SelectionSettings(max_folds=1), "max_folds must be >= 2"),
    (lambda: SelectionSettings(max_samples=10.5), "max_samples must be a whole number"),
    (lambda: SelectionSettings(group_by=""), "group_by must be a meta key"),
    (lambda: Workers(n_jobs=0), "n_jobs must be a whole number"),
    (lambda: Workers(scheduler=3), "scheduler must be a Dask scheduler's address"),
    (lambda: Workers(device="gpu"), "The 'device' setting must be one of cpu, auto, cuda"),
    (lambda: PhysicsPolicy("linear", max_tries=0), "'max_tries' of a PhysicsPolicy"),
    (lambda: PhysicsPolicy("linear", requires="ode"), "'requires' of a PhysicsPolicy"),
])
def test_settings_refuse_a_bad_value_when_built(build, match):
    with pytest.raises(IdentificationError, match=match):
        build()


def test_other_settings_refuse_a_bad_value_when_built():
    with pytest.raises(ValueError, match="'z' of DiscoveryThresholds must be a number >= 0"):
        DiscoveryThresholds(z=-1.0)
    with pytest.raises(ValueError, match=r"'ambiguity' of DiscoveryThresholds must be a number in \[0, 1\]"):
        DiscoveryThresholds(ambiguity=1.5)
    with pytest.raises(DataError, match="measured_inputs must be distinct column names"):
        Columns(measured=("volt", "volt"))
    with pytest.raises(IdentificationError, match="solver must be an identification.SolverSettings"):
        identify("lag+linear", [_run()], solver={"max_iter": 5})
    with pytest.raises(IdentificationError, match="settings must be an identification.discovery.SelectionSettings"):
        select_physics([_run(), _run(0.3)], candidates=["linear"], settings={"margin": 0.1})
    with pytest.raises(DataError, match="columns must be a hybrid.experiments.Columns"):
        fit_model_dir([_run()], "never_written", physics="linear", residual="none", columns={"time": "t"})


def test_settings_are_frozen_and_a_copy_of_the_options_given():
    options = {"tol": 1e-10}
    solver = SolverSettings(max_iter=50, ipopt_options=options)
    options["tol"] = 1.0
    assert solver.options() == {"max_iter": 50, "tol": 1e-10}
    assert solver.with_budget(12).options() == {"max_iter": 12, "tol": 1e-10} and solver.max_iter == 50
    with pytest.raises(dataclasses.FrozenInstanceError):
        solver.max_iter = 10
    assert Columns("t", "u", "y", measured="current").manifest() == {"time": "t", "input": "u,current", "output": "y"}
    assert Columns(measured=("current",)).manifest() is None  # runs not read from files: nothing kept
    assert Workers(n_jobs=2, scheduler="tcp://h:8786").to_dict() == {"n_jobs": 2, "scheduler": "tcp://h:8786",
                                                                     "device": "cpu"}


def test_the_solver_settings_give_the_fit_the_old_keywords_gave():
    """One IPOPT iteration through ``ipopt_options`` wins over ``max_iter``, as the keyword did: the fit
    stops after one iteration, flagged."""
    fit = identify(Series.from_spec("lag+linear", dt=DT), [_run()], allow_failure=True,
                   solver=SolverSettings(max_iter=3000, ipopt_options={"max_iter": 1}))
    assert not fit.success and fit.status == "Maximum_Iterations_Exceeded" and fit.iterations == 1
    full = identify(Series.from_spec("lag+linear", dt=DT), [_run()], solver=SolverSettings(max_iter=200))
    assert full.parameters["lag.time_constant_s"] == pytest.approx(0.3, rel=0.05)


def test_physics_fits_skips_what_requires_refuses_and_hands_on_at_most_max_tries():
    """``requires`` refuses a spec without a lag (skipped, with why); a spec that cannot fit is listed in
    ``failed``; a fitted model named first is handed on as it is; ``max_tries`` caps what is handed on."""
    runs = [_run()]
    given = identify(Series.from_spec("lag+linear", dt=DT), runs, solver=SolverSettings(max_iter=200))

    def needs_a_lag(series):
        return None if any(b.name == "lag" for b in series.blocks) else f"'{series.spec}' has no lag"

    report = PhysicsReport("", "none")
    policy = PhysicsPolicy([given, "linear", "lag+backlash+boucwen+linear", "lag+poly+linear"], requires=needs_a_lag,
                           identify_options={"solver": SolverSettings(max_iter=5), "starts": 1}, max_tries=2)
    handed = list(physics_fits(policy, runs, report=report))
    assert handed[0][1] is given and len(handed) == 2 and handed[1][1].spec == "lag+poly+linear"
    assert report.skipped == {"linear": "'linear' has no lag"}
    assert list(report.failed) == ["lag+backlash+boucwen+linear"]  # five iterations are too few for it
    assert report.tried == ["lag+linear", "lag+poly+linear"] and report.spec == "lag+poly+linear"
    assert list(physics_fits(dataclasses.replace(policy, max_tries=1), runs))[0][1] is given
    # fit_physics applies the same requirement: the first spec it lets through that fits
    _, fit, first = fit_physics(PhysicsPolicy(["linear", "lag+linear"], requires=needs_a_lag), runs)
    assert fit.spec == "lag+linear" and first.skipped == {"linear": "'linear' has no lag"}
    assert first.how == "ranking" and first.to_dict()["skipped"] == first.skipped
    with pytest.raises(IdentificationError, match="No physics spec can carry the model"):
        fit_physics(PhysicsPolicy(["linear"], requires=needs_a_lag), runs)
    with pytest.raises(IdentificationError, match="physics_fits takes specs and fitted models"):
        physics_fits(PhysicsPolicy("auto"), runs)  # refused when called, before any fit


def test_a_ranking_is_a_declared_protocol():
    """``fitted_series`` tries a Ranking's specs in order, starting each from its fold parameters; any
    object that declares ``ranked()`` and ``fold_parameters`` is one, a spec string is not."""

    class Ranked:
        fold_parameters = {"lag+linear": [dict(TRUTH)]}

        def ranked(self):
            return ["lag+linear", "linear"]

    assert isinstance(Ranked(), Ranking) and not isinstance("lag+linear", Ranking)
    series, fit = fitted_series(Ranked(), [_run()], DT, {"solver": SolverSettings(max_iter=200)})
    assert isinstance(fit, FitResult) and fit.spec == series.spec == "lag+linear"
    assert fit.parameters["lag.time_constant_s"] == pytest.approx(0.3, rel=0.05)
