"""NeuralODEHybrid: the physics ODE plus a network in the state derivative."""

import numpy as np
import pytest
import torch

from hybrid import NeuralODEHybrid
from physics.data import NotFittedError, rmse
from physics.virtual import VirtualCatheter, paper_protocol
from physics import PhysicsError, Series


@pytest.fixture(scope="module")
def split():
    return paper_protocol(VirtualCatheter(seed=0), frequencies=(0.5,), tests=(0.45,), baselines=("mid",))


@pytest.fixture(scope="module")
def truth():
    return VirtualCatheter().truth_model()


def rk4_reference(series: Series, u: np.ndarray) -> np.ndarray:
    """The physics ODE integrated with torchdiffeq's 'rk4' (the 3/8 rule), one step per sample."""
    ode, p, dt = series.ode_function(), series.params, series.dt

    def f(x, v, vdot):
        return np.asarray(ode(x, v, vdot, p)[0], dtype=float).ravel()

    x, ys, u_prev = series.continuous_steady_state(u[0]), [], u[0]
    for v in u:
        d = (v - u_prev) / dt
        k1 = f(x, u_prev, d)
        k2 = f(x + dt * k1 / 3, u_prev + dt / 3 * d, d)
        k3 = f(x + dt * (k2 - k1 / 3), u_prev + 2 * dt / 3 * d, d)
        k4 = f(x + dt * (k1 - k2 + k3), u_prev + dt * d, d)
        x = x + dt * (k1 + 3 * k2 + 3 * k3 + k4) / 8
        ys.append(float(ode(x, v, 0.0, p)[1]))
        u_prev = v
    return np.array(ys)


def test_zero_network_is_the_physics_ode_integrated_with_rk4(split, truth):
    model = NeuralODEHybrid(truth, epochs=0, threads=1).fit(split.train)
    u = split.test[0].u[:200]
    y = model.predict(u)
    np.testing.assert_allclose(y, rk4_reference(truth, u), atol=1e-9)
    # and close to the discrete model: measured 0.34 deg RMS over a 50 deg swing. The continuous
    # play has no restoring term, so the part of a sample interval RK4 misses at each engagement
    # stays as an offset until the next reversal (the discrete play is exact).
    assert rmse(truth.simulate(u), y) < 0.5


def test_training_lowers_the_loss_and_checkpoints_round_trip(split, truth, tmp_path):
    model = NeuralODEHybrid(truth, hidden=8, epochs=2, segment_len=25, batch_size=8, threads=1,
                            progress=False).fit(split.train)
    assert len(model.loss_) == 2 and np.all(np.isfinite(model.loss_))
    again = NeuralODEHybrid.load(model.save(tmp_path / "ode.pt"))
    np.testing.assert_array_equal(again.predict(split.test[0]), model.predict(split.test[0]))
    state, steps = model.initial_state(split.test[0].u[0]), []
    for v in split.test[0].u[:60]:
        state, y = model.step(state, v)
        steps.append(y)
    np.testing.assert_allclose(steps, model.predict(split.test[0])[:60], atol=1e-10)


def test_clear_errors(split):
    with pytest.raises(PhysicsError, match="continuous-time form"):
        NeuralODEHybrid("preisach+linear").fit(split.train)
    with pytest.raises(PhysicsError, match="'poly\+linear' has no state"):  # a static map: nothing to correct
        NeuralODEHybrid("poly+linear").fit(split.train)
    with pytest.raises(NotFittedError, match="not fitted"):
        NeuralODEHybrid().predict(split.test[0])


def test_a_physics_too_stiff_for_one_rk4_step_per_sample_takes_more_or_is_refused(tmp_path):
    """A Bouc-Wen loop that saturates within a sample: the discrete block (substeps) follows it,
    the ODE form under one RK4 step per sample blows up. The neural ODE takes the fewest steps per
    sample that follow the discrete physics (its export and checkpoint too), and says so before
    training where even 8 do not (a 10 kHz MEMS fit, beta 1e9 per metre, scored NaN in ``hyst compare``)."""
    from hybrid.export import export_model
    from physics import BoucWen, LinearMap, Resonance
    from physics.data import Trajectory

    dt = 0.04
    t = np.arange(0, 20, dt)
    u = 1 + np.sin(2 * np.pi * 0.5 * t)
    # the resonance's discrete form is exact at any rate; 100 Hz at 25 Hz needs about 9 RK4 steps
    fast = Resonance(natural_frequency_hz=100.0, damping_ratio=0.5)
    for name, block, substeps in (("3", BoucWen(A=1.0, beta=3.0, gamma=0.0, substeps=8), 1),
                                  ("30", BoucWen(A=1.0, beta=30.0, gamma=0.0, substeps=8), 2),
                                  ("fast", fast, None)):
        series = Series(block, LinearMap(gain=2.0, offset=0.0), dt=dt)
        run = Trajectory(time=t, u=u, y=series.simulate(u))
        if substeps is None:
            with pytest.raises(PhysicsError, match="diverges under RK4 even at 8 steps per sample at 25 Hz"):
                NeuralODEHybrid(series, epochs=1, progress=False).fit([run])
            continue
        model = NeuralODEHybrid(series, epochs=1, progress=False).fit([run])
        y = model.predict(run)
        assert model.module_.substeps == substeps and rmse(run.y, y) < 0.02  # measured 0.0043 of 3.1, 0.0027 of 3.9
        np.testing.assert_allclose(export_model(model).simulate(u), y, rtol=0, atol=1e-9)
        np.testing.assert_array_equal(NeuralODEHybrid.load(model.save(tmp_path / f"{name}.pt")).predict(run), y)


def test_inputs_faster_than_any_trained_are_integrated_in_finer_steps():
    """Bouc-Wen's stiffness grows with the rate: steps 16x the fastest trained input blow the ODE up
    at the trained RK4 step count (measured 5.9e3 and 3e37 times the span); a fitted model takes
    proportionally finer steps there and follows the discrete physics. Its export (fixed steps)
    records the largest input change it equals the prediction for, and the MPC's default rate limit
    stays under it (a friction stage's random steps were scored NaN in ``hyst compare``)."""
    from hybrid.control import TrackingMPC
    from hybrid.experiments._compare import _ViaExport
    from hybrid.export import export_model
    from physics import BoucWen, LinearMap
    from physics.data import Trajectory

    dt = 0.04
    t = np.arange(0, 20, dt)
    u = 1 + np.sin(2 * np.pi * 0.5 * t)
    steps = np.repeat([0.0, 2.0, 0.5, 1.8, 0.0, 1.0], 40)
    for beta in (3.0, 30.0):
        series = Series(BoucWen(A=1.0, beta=beta, gamma=0.0, substeps=8), LinearMap(gain=2.0, offset=0.0), dt=dt)
        model = NeuralODEHybrid(series, epochs=0, progress=False).fit([Trajectory(time=t, u=u, y=series.simulate(u))])
        ref = series.simulate(steps)
        assert np.max(np.abs(model.predict(steps) - ref)) < 1e-3 * np.ptp(ref)  # measured 4.3e-5, 1.9e-5
        stepped = Trajectory(time=dt * np.arange(steps.size), u=steps, y=ref)  # compare scores through the
        np.testing.assert_array_equal(_ViaExport(model).predict(stepped), model.predict(steps))  # model here
        assert model.module_.refinement(torch.zeros(1, 1), torch.zeros(1), torch.full((1,), 2.0 / dt)) == 16
        model.module_.refine = False  # the trained step count alone
        plain = model.predict(steps)
        assert not np.all(np.abs(plain - ref) < np.ptp(ref))
        exported = export_model(model)
        assert exported.meta["max_input_step"] == pytest.approx(np.abs(np.diff(u)).max(), rel=1e-12)
        assert TrackingMPC(exported, horizon=5).du_max == pytest.approx(exported.meta["max_input_step"], rel=1e-12)


def test_training_moves_each_parameter_in_proportion_to_the_data_units():
    """The same play in volts -> metres and in volts -> 10 um units: the same relative error. The
    physics' step sizes had a floor of 1e-2 in any units, so one Adam step took a 1e-7 m/V gain to
    1e-5 and the rollout left the data by 17 times its span."""
    from _synthetic import piezo_runs

    errors = []
    for sy in (1.0, 1e5):
        runs = piezo_runs((2.0, 5.0, 8.0, 3.5), rate=250.0, y_unit=sy)
        model = NeuralODEHybrid("backlash+linear", epochs=1, segment_len=25, batch_size=64, progress=False,
                                seed=0).fit(runs[:3])
        errors.append(rmse(runs[3].y, model.predict(runs[3])) / np.ptp(runs[3].y))
    assert errors[0] < 0.02 and errors[0] == pytest.approx(errors[1], rel=1e-3)
