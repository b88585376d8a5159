"""One physics policy (``PhysicsPolicy``, ``fit_physics``): the spec in use, what was tried and why, the
same rule for ``hyst fit``, ``hyst compare`` and ``HybridModel.fit``."""

import numpy as np
import pytest

from identification import IdentificationError, PhysicsFitError, PhysicsPolicy, SolverSettings, fit_physics
from physics import Series
from physics.data import Trajectory

DT = 0.04
TRUTH = {"lag.time_constant_s": 0.3, "linear.gain": 2.0, "linear.offset": 1.0}
#: Too few iterations for the Bouc-Wen spec, enough for a lag: the first fails, the second fits.
FEW = {"solver": SolverSettings(max_iter=5)}


def _run(f=0.5, n=200, seed=0):
    truth = Series.from_spec("lag+linear", dt=DT).set_params(**TRUTH)
    t = np.arange(n) * DT
    u = np.sin(2 * np.pi * f * t)
    return Trajectory(t, u, truth.simulate(u) + 0.01 * np.random.default_rng(seed).normal(size=n), source=f"f{f}")


def test_the_first_spec_that_fits_is_used_and_the_failures_are_reported():
    series, fit, report = fit_physics(PhysicsPolicy("backlash+boucwen+linear", fallback=("lag+linear",),
                                                    identify_options=FEW), [_run()])
    assert series.spec == fit.spec == report.spec == "lag+linear" and report.how == "fallback"
    assert report.tried == ["backlash+boucwen+linear", "lag+linear"] and list(report.failed) == report.tried[:1]
    assert "Maximum_Iterations_Exceeded" in report.failed["backlash+boucwen+linear"]
    assert fit.parameters["lag.time_constant_s"] == pytest.approx(0.3, rel=0.05)
    assert fit.parameters["linear.gain"] == pytest.approx(2.0, rel=0.02)
    _, _, ranked = fit_physics(PhysicsPolicy(["backlash+boucwen+linear", "lag+linear"], identify_options=FEW),
                               [_run()])
    assert ranked.how == "ranking" and ranked.spec == "lag+linear"


def test_none_fits_raises_with_the_report():
    with pytest.raises(PhysicsFitError, match="No physics spec could be fitted") as info:
        fit_physics(PhysicsPolicy(["backlash+boucwen+linear"], fallback=("lag+backlash+linear",),
                                  identify_options={"solver": SolverSettings(max_iter=1)}), [_run()])
    assert info.value.report.tried == ["backlash+boucwen+linear", "lag+backlash+linear"]
    assert set(info.value.report.failed) == set(info.value.report.tried)


def test_auto_falls_back_where_the_selection_itself_fails():
    short = [_run(n=40)]  # one run too short to cut into held-out pieces
    with pytest.raises(IdentificationError, match="at least two runs"):
        fit_physics(PhysicsPolicy("auto"), short)
    _, fit, report = fit_physics(PhysicsPolicy("auto", if_selection_fails=("lag+linear", "linear")), short)
    assert report.how == "fallback" and report.spec == "lag+linear" and report.selection is None
    assert "at least two runs" in report.selection_error and report.candidates == ["lag+linear", "linear"]
    assert fit.parameters["linear.gain"] == pytest.approx(2.0, rel=0.05)


def test_a_model_is_used_as_given_and_bad_settings_are_refused():
    model = Series.from_spec("lag+linear", dt=DT).set_params(**TRUTH)
    series, fit, report = fit_physics(PhysicsPolicy(model), [_run()])
    assert fit is None and report.how == "given" and series.param_dict() == model.param_dict()
    with pytest.raises(IdentificationError, match="fallback.*must be a tuple of specs"):
        PhysicsPolicy("linear", fallback="linear")


def test_the_policys_own_fits_solve_their_starts_on_the_selections_local_workers():
    """The final fit runs while the selection's workers idle: its starts use as many threads (the same
    answer: ``SolverSettings.threads``); a solver the user set is kept as it is, serial stays serial."""
    from identification.discovery import Workers
    from identification.discovery._policy import _options

    assert _options(PhysicsPolicy("auto", select_options={"workers": Workers(n_jobs=3)}))["solver"].threads == 3
    mine = SolverSettings(max_iter=50, threads=2)
    assert _options(PhysicsPolicy("auto", identify_options={"solver": mine},
                                  select_options={"workers": Workers(n_jobs=4)}))["solver"] == mine
    kept = _options(PhysicsPolicy("auto", identify_options={"solver": SolverSettings(max_iter=50)},
                                  select_options={"workers": Workers(n_jobs=4)}))["solver"]
    assert kept == SolverSettings(max_iter=50)  # threads=1 the user's: not raised behind their back
    assert _options(PhysicsPolicy("auto", select_options={"workers": Workers(n_jobs=1)})) is None
    assert _options(PhysicsPolicy("auto")) is None
