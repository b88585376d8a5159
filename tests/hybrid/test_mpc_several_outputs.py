"""A model of several outputs in the MPC (issue 55): one output tracked while another is kept inside bounds, with
the full NLP (IPOPT) and with the fixed-iteration SQP the C controller runs; and the refusals."""

import numpy as np
import pytest

from hybrid.control import MPCSettings, TrackingMPC
from hybrid.export import ExportError, export_model
from hybrid.virtual import TipArc
from physics import Series

N = 15


@pytest.fixture(scope="module")
def pose():
    """A tendon's chain read by the virtual catheter's arc: outputs the tip's angle (deg) and position (mm)."""
    chain = Series.from_spec("lag+backlash+linear").set_params(
        **{"backlash.width": 0.5, "linear.gain": 10.0, "linear.offset": 20.0})
    series = Series(*chain.blocks, TipArc().block(), dt=chain.dt, input_range=(0.0, 6.0))
    return series, export_model(series)


def _closed_loop(model, settings, ref, u0=0.0):
    """The MPC on the model itself from rest at ``u0``: every output of every sample."""
    mpc = TrackingMPC(model, settings)
    x, u, ys = model.x0(u0), u0, []
    for k in range(ref.size):
        u = mpc.solve(x, ref[k:k + N], u_prev=u)
        x, y = model.step(x, u)
        ys.append(np.asarray(y, dtype=float).ravel())
    return np.array(ys)


@pytest.mark.parametrize("solver, slack", [("ipopt", 1e-4), ("fixed-sqp", 0.05)])
def test_the_position_is_tracked_while_the_angle_stays_under_its_bound(pose, solver, slack):
    """The position's reference ramps across what the input reaches (the angle from 20 to 74 deg): unbounded, the
    position follows it to the end; with the angle bounded at 60 deg, the angle stops there (a soft bound with the
    fixed SQP: within a few hundredths) and the position follows until the angle reaches the bound, then waits."""
    series, model = pose
    reach = np.asarray(series.simulate(np.linspace(0.0, 6.0, 50)))
    ref = np.interp(np.arange(150) * 0.04, [0.0, 6.0], [reach[0, 2], reach[-1, 2]])
    options = {} if solver == "ipopt" else {"solver_options": {"compile": False}}
    common = dict(track=2, solver=solver, horizon=N, u_bounds=(0.0, 6.0), **options)
    free = _closed_loop(model, MPCSettings(**common), ref)
    bounded = _closed_loop(model, MPCSettings(y_bounds={0: (None, 60.0)}, **common), ref)
    assert free[:, 0].max() > 70 and np.sqrt(np.mean((free[:, 2] - ref) ** 2)) < 0.05
    assert 59.9 < bounded[:, 0].max() <= 60.0 + slack
    early = bounded[:, 0] < 55  # where the bound is not near, the position is tracked as without it
    assert early.sum() > 30 and np.max(np.abs(bounded[early, 2] - free[early, 2])) < 0.05
    assert np.sqrt(np.mean((bounded[:, 2] - ref) ** 2)) > 1.0  # and then stops short


@pytest.mark.parametrize("solver, slack", [("ipopt", 1e-4), ("fixed-sqp", 0.05)])
def test_the_bounded_outputs_own_interval_is_kept_inside_its_bound(pose, solver, slack):
    """``tighten=True`` with the bounds on another output than the tracked one: the bounded output's interval (set
    on the model of them all for that output, ``meta["interval_output"]``) is what stays inside the bound. A 3 deg
    half-width on the angle: it stops at 57 deg where its bound is 60, while the position is tracked."""
    import casadi as ca
    from dataclasses import replace

    series, model = pose
    u, u_prev, y = (ca.SX.sym(n) for n in ("u", "u_prev", "y"))
    width = ca.Function("half_width", [u, u_prev, y], [3.0 + 0 * u, 0 * u])  # (half-width, outside)
    banded = replace(model, half_width=width, meta={**model.meta, "interval_output": 0})
    assert banded.output(0).half_width is width and banded.output(2).half_width is None
    reach = np.asarray(series.simulate(np.linspace(0.0, 6.0, 50)))
    ref = np.interp(np.arange(150) * 0.04, [0.0, 6.0], [reach[0, 2], reach[-1, 2]])
    options = {} if solver == "ipopt" else {"solver_options": {"compile": False}}
    common = dict(track=2, solver=solver, horizon=N, u_bounds=(0.0, 6.0), y_bounds={0: (None, 60.0)}, **options)
    tight = _closed_loop(banded, MPCSettings(tighten=True, **common), ref)
    assert 56.9 < tight[:, 0].max() <= 57.0 + slack


def test_the_settings_of_several_outputs_are_checked(pose):
    _, model = pose
    with pytest.raises(ExportError, match="name the one to track"):
        TrackingMPC(model, MPCSettings(u_bounds=(0.0, 6.0)))
    with pytest.raises(ExportError, match="is not an output of this model"):
        TrackingMPC(model, MPCSettings(track=3, u_bounds=(0.0, 6.0)))
    with pytest.raises(ExportError, match="one output's limits"):
        MPCSettings(track=2, y_bounds={0: (0.0, 60.0), 1: (0.0, 90.0)})
    with pytest.raises(ExportError, match="carries its prediction interval"):  # the bounded output's, absent
        TrackingMPC(model, MPCSettings(track=2, y_bounds={0: (0.0, 60.0)}, tighten=True, u_bounds=(0.0, 6.0)))
    with pytest.raises(ExportError, match="index of an output"):
        MPCSettings(track=-1)
    with pytest.raises(ExportError, match="index of an output"):
        MPCSettings(track=2, y_bounds={"Angle x": (0.0, 60.0)})
    # the output bounded is kept beside the pair through the settings' copies
    from dataclasses import replace

    settings = replace(MPCSettings(track=2, y_bounds={0: (20, 60)}), horizon=10)
    assert settings.bound == 0 and tuple(settings.y_bounds) == (20.0, 60.0) and MPCSettings().bound is None
    one = export_model(Series.from_spec("lag+linear"))
    with pytest.raises(ExportError, match="is not an output of this model"):
        TrackingMPC(one, MPCSettings(track=1, u_bounds=(0.0, 6.0)))
    # the tracked output alone is the MPC's model: its bounds as before
    mpc = TrackingMPC(model, MPCSettings(track=2, y_bounds={2: (50.0, 70.0)}, u_bounds=(0.0, 6.0)))
    assert mpc.problem.bounded is None and mpc.model.n_y == 1


@pytest.mark.parametrize("outputs, offset", [((), None), ((0,), None), ((2,), 2.0), (None, 2.0)])
def test_the_estimator_of_every_output_feeds_the_tracked_ones_mpc(pose, outputs, offset):
    """The plant's tracker reads the tip's y 2 mm high (the arc's base moved); the MPC tracks y, the estimator of
    every output reads those named (every 5th sample): with y among them its offset is recovered and the true y
    tracked; with the angle alone, or nothing, the 2 mm stay (the angle says nothing of the tracker's offset)."""
    from hybrid.control import Feedback, MovingHorizonEstimator, reference_signal, run_closed_loop

    series, model = pose
    plant = Series(*series.blocks[:-1], TipArc(base_y_mm=2.0).block(), dt=series.dt, input_range=(0.0, 6.0))
    mpc = TrackingMPC(model, MPCSettings(track=2, u_bounds=(0.0, 6.0), solver="fixed-sqp", horizon=N,
                                         solver_options={"compile": False}))
    mhe = MovingHorizonEstimator(model, u_bounds=(0.0, 6.0), compile=False)
    ref = reference_signal("sine", 58.0, 70.0, duration_s=6.0)
    result = run_closed_loop(mpc, plant, ref, noise_std_deg=[0.15, 0.1, 0.1],
                             feedback=Feedback(measure_every=5, estimator=mhe, outputs=outputs))
    late = slice(50, None)
    error = np.sqrt(np.mean((result.y_true[late] - ref[late]) ** 2))
    if offset is None:
        assert 1.5 < error < 2.5 and mhe.offset_[2] == 0.0
    else:
        assert error < 0.3 and mhe.offset_[2] == pytest.approx(offset, abs=0.1)
        assert abs(mhe.offset_[0]) < 0.1  # the angle read as it is
    with pytest.raises(ExportError, match="A plant of 3 outputs"):
        run_closed_loop(mpc, plant, ref, feedback=Feedback(measure_every=5))
    with pytest.raises(ExportError, match="by index in 0..2"):
        run_closed_loop(mpc, plant, ref, feedback=Feedback(measure_every=5, estimator=mhe, outputs=(3,)))
    with pytest.raises(ExportError, match="one per output"):
        run_closed_loop(mpc, plant, ref, noise_std_deg=[0.1, 0.1], feedback=Feedback(measure_every=5, estimator=mhe))


def test_the_inverse_of_a_pose_follows_the_output_named(pose):
    """``ModelInverse(model, output=j)``: the tendon path that makes output ``j`` follow its wanted path, the others
    going where it takes them; the position alone cannot tell which side the tip bends to (an arc's y is even in
    its angle), so the inverse keeps to the inputs the model was fitted on. Without ``output`` it says to name one."""
    from hybrid import ModelInverse
    from physics.data import DataError

    series, _ = pose
    u = 3 - 2 * np.cos(np.linspace(0, 6, 120))
    wanted = np.asarray(series.simulate(u))
    for j in (0, 2):
        inverse = ModelInverse(series, window=20, commit=10, output=j).fit()
        assert inverse.u_bounds_ == (0.0, 6.0) and inverse.name.endswith(f"[output {j}]")
        found = inverse.predict(wanted[:, j])
        np.testing.assert_allclose(np.asarray(series.simulate(found))[20:], wanted[20:], atol=0.3)  # every output
    with pytest.raises(DataError, match="name the one to follow"):
        ModelInverse(series).fit()
    with pytest.raises(DataError, match="Leave it out"):
        ModelInverse(Series.from_spec("boucwen+linear"), output=1).fit()
