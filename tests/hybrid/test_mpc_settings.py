"""MPCSettings and the solver registry: checked settings, one class per solver name, each with its cost."""

import numpy as np
import pytest

from hybrid.control import (COST_SCALE, SOLVERS, MPCSettings, MPCSolution, MPCSolver, TrackingMPC, register_solver,
                            rest_output)
from hybrid.export import ExportError, export_model
from physics import Series


@pytest.fixture(scope="module")
def model():
    series = Series.from_spec("lag+boucwen+linear")
    series.input_range = (0.0, 6.0)
    return export_model(series)


def test_settings_and_keywords_make_the_same_controller(model):
    x, ref = model.x0(2.0), np.linspace(rest_output(model, 2.0), rest_output(model, 3.0), 10)
    by_settings = TrackingMPC(model, MPCSettings(horizon=10, u_bounds=(0.0, 6.0), solver="sqp"))
    by_keywords = TrackingMPC(model, horizon=10, u_bounds=(0.0, 6.0), solver="sqp")
    assert by_settings.solve(x, ref, u_prev=2.0) == by_keywords.solve(x, ref, u_prev=2.0)
    np.testing.assert_array_equal(by_settings.predicted_output(), by_keywords.predicted_output())
    # a keyword given replaces the settings' field; the others stay
    mpc = TrackingMPC(model, MPCSettings(horizon=10, w_du=1e-2, solver="sqp"), horizon=5)
    assert (mpc.horizon, mpc.settings.w_du) == (5, 1e-2)


def test_the_settings_an_mpc_runs_with_are_resolved_on_its_model(model):
    mpc = TrackingMPC(model, horizon=5)
    s = mpc.settings
    assert s.u_bounds == (0.0, 6.0) and s.du_max == 0.5 and s.u_ref == 3.0  # the range fitted on, a twelfth, the middle
    assert s.solver == mpc.solver_name == "sqp" and isinstance(mpc.solver, SOLVERS["sqp"])
    assert TrackingMPC(model, horizon=5, y_bounds=(None, 60.0)).settings.solver == "ipopt"  # output bounds: the full NLP


@pytest.mark.parametrize("fields, message", [
    ({"horizon": 2.5}, "'horizon' must be a whole number >= 1"),
    ({"horizon": np.inf}, "'horizon' must be a whole number >= 1"),
    ({"u_bounds": (1.0, 2.0, 3.0)}, "'u_bounds' must be \\(low, high\\)"),
    ({"du_max": -0.1}, "'du_max' must be > 0"),
    ({"w_du": -1.0}, "'w_du' must be a finite weight >= 0"),
    ({"w_track": "1"}, "'w_track' must be a number"),
    ({"u_ref": np.nan}, "'u_ref' must be a finite input"),
    ({"solver": "magic"}, "Must be one of: auto, adjoint-sqp, fixed-sqp, ipopt, sqp"),
    ({"solver_options": [("max_iter", 3)]}, "'solver_options' must be a dict"),
    ({"tighten": True}, "give them"),
    ({"y_bounds": (1.0, 1.0)}, "'y_bounds' must be \\(low, high\\) with low < high"),
    ({"y_bounds": (0.0, 1.0), "solver": "adjoint-sqp"}, "bounds the inputs only. Use solver='fixed-sqp' or 'ipopt' or 'sqp'"),
])
def test_settings_are_checked_when_they_are_made(fields, message):
    with pytest.raises(ExportError, match=message):
        MPCSettings(**fields)


def test_output_bounds_open_on_either_side():
    assert MPCSettings(y_bounds=(0.0, None)).y_bounds == (0.0, np.inf)
    assert MPCSettings(y_bounds=(None, 5)).y_bounds == (-np.inf, 5.0)


def test_a_solvers_options_are_its_own(model):
    with pytest.raises(ExportError, match="hessian must be"):
        TrackingMPC(model, horizon=5, solver="sqp", solver_options={"hessian": "newton"})
    with pytest.raises(ExportError, match="ipopt solver does not know an option"):
        TrackingMPC(model, horizon=5, solver="ipopt", solver_options={"hessian": "exact"})
    with pytest.raises(ExportError, match="Unknown adjoint-sqp option\\(s\\) \\['shooting'\\]"):
        TrackingMPC(model, horizon=5, solver="adjoint-sqp", solver_options={"shooting": "single"})
    with pytest.raises(ExportError, match="Unknown fixed-sqp option"):
        TrackingMPC(model, horizon=5, solver="fixed-sqp", solver_options={"shooting": "single"})
    with pytest.raises(ExportError, match="settings must be an MPCSettings"):
        TrackingMPC(model, {"horizon": 5})


@pytest.mark.parametrize("solver", ["sqp", "ipopt", "adjoint-sqp", "fixed-sqp"])
def test_each_solvers_cost_is_the_scaled_objective(model, solver):
    """``solver.cost`` is ``COST_SCALE`` times the weighted squares of the scaled error, rate and level,
    computed here from the model's own simulation."""
    mpc = TrackingMPC(model, MPCSettings(horizon=8, u_bounds=(0.0, 6.0), w_du=1e-2, w_u=1e-3, u_ref=2.5, solver=solver,
                                         solver_options={"compile": False} if solver == "fixed-sqp" else None))
    x, U, u_prev = model.x0(2.0), np.linspace(2.0, 3.4, 8), 1.9
    ref = np.linspace(rest_output(model, 2.0), rest_output(model, 4.0), 8)
    sc = mpc.problem.scale
    error, rate = (model.simulate(U, x0=x) - ref) / sc.y_span, np.diff(np.r_[u_prev, U]) / sc.u_span
    expected = COST_SCALE * (np.sum(error ** 2) + 1e-2 * np.sum(rate ** 2) + 1e-3 * np.sum(((U - 2.5) / sc.u_span) ** 2))
    assert mpc.solver.cost(x, U, ref, u_prev) == pytest.approx(expected, rel=1e-9)
    with pytest.raises(ExportError, match="U must hold 8 inputs"):
        mpc.solver.cost(x, U[:3], ref, u_prev)


@pytest.fixture
def registry():
    yield SOLVERS
    SOLVERS.pop("hold", None)  # the toy leaves the registry as it found it


def test_a_registered_solver_is_a_solver_choice(model, registry):
    class Hold(MPCSolver):
        """Holds the input applied last (a toy: no optimisation)."""

        name, title = "hold", "hold"

        def solve(self, x, ref, u_prev, D, last, half_widths=None):
            return MPCSolution((np.full(self.problem.horizon, u_prev),), np.nan, 0, True, u_prev, x)

        def _cost(self, x, U, ref, u_prev, D):
            return 0.0

        def predicted_output(self, solution):
            return self.problem.model.simulate(solution.guess[0], x0=solution.p)

    assert register_solver(Hold) is Hold
    assert "auto, adjoint-sqp, fixed-sqp, hold, ipopt, sqp" in _message(lambda: MPCSettings(solver="magic"))
    mpc = TrackingMPC(model, horizon=4, solver="hold")
    assert mpc.solve(model.x0(1.5), [50.0], u_prev=1.5) == 1.5 and mpc.stats.iterations == [0]
    np.testing.assert_allclose(mpc.predicted_output(), np.full(4, rest_output(model, 1.5)), atol=1e-9)
    with pytest.raises(ExportError, match="taken by Hold"):
        register_solver(type("Other", (Hold,), {}))
    with pytest.raises(ExportError, match="not 'auto'"):
        register_solver(type("Auto", (Hold,), {"name": "auto"}))
    with pytest.raises(ExportError, match="takes an MPCSolver subclass"):
        register_solver(object)


def _message(make) -> str:
    with pytest.raises(ExportError) as info:
        make()
    return str(info.value)
