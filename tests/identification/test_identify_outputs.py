"""One model of several outputs (issue 55): the virtual catheter's tip arc recovered against its truth, each
output's own map, each output over its own scale, and the refusals."""

from dataclasses import replace

import numpy as np
import pytest

from hybrid.virtual import DecayingSinusoid, TipArc, VirtualCatheter
from identification import IdentificationError, identify_outputs
from physics import Lag, OutputMaps, Series
from physics.data import Trajectory

POSE = ["Angle x", "Pos x", "Pos y"]


@pytest.fixture(scope="module")
def catheter_runs():
    cath = VirtualCatheter(seed=4, tip=TipArc())
    signals = [DecayingSinusoid(frequency_hz=f, baseline=b) for f, b in ((0.2, "zero"), (0.5, "mid"), (0.3, "end"))]
    return cath, [cath.run(s) for s in signals]


def test_the_tips_arc_is_recovered_from_the_angle_and_the_position(catheter_runs):
    cath, runs = catheter_runs
    fit = identify_outputs("backlash+boucwen+linear+arc", runs, POSE)
    truth = cath.truth_model(pose=True).param_dict()
    length, se = fit.parameters["arc.length"], fit.standard_errors["arc.length"]
    assert length == pytest.approx(truth["arc.length"], rel=0.02)  # the target; measured 0.01 %
    assert abs(length - truth["arc.length"]) < 5 * se
    for name in ("arc.base_x", "arc.base_y", "linear.gain", "linear.offset", "backlash.width"):
        assert abs(fit.parameters[name] - truth[name]) < 5 * fit.standard_errors[name] + 1e-3 * abs(truth[name]), name
    # each output down to its own noise (0.15 deg, 0.1 mm)
    assert fit.train_rmse["Angle x"] == pytest.approx(cath.noise_std_deg, rel=0.1)
    assert fit.train_rmse["Pos x"] == pytest.approx(0.1, rel=0.1)
    assert fit.train_rmse["Pos y"] == pytest.approx(0.1, rel=0.1)
    assert fit.series.blocks[-1].mirrored is False
    held = cath.run(DecayingSinusoid(frequency_hz=0.4, baseline="mid"))
    assert all(v < 1.3 * noise for v, noise in zip(fit.rmse(held).values(), (0.15, 0.1, 0.1)))


def test_a_turned_over_tracker_frame_is_found(catheter_runs):
    _, runs = catheter_runs
    flipped = [replace(r, extra={**r.extra, "Pos y": -r.extra["Pos y"]}) for r in runs]
    fit = identify_outputs("backlash+boucwen+linear+arc", flipped, POSE)
    assert fit.series.blocks[-1].mirrored is True
    assert fit.parameters["arc.length"] == pytest.approx(75.0, rel=0.02)


def _two_output_runs(seed=0):
    """A lag read by two outputs in units a thousand times apart: an angle (deg) and a length (m)."""
    truth = Series(Lag(time_constant_s=0.2), OutputMaps(outputs=2, gain_1=10.0, offset_1=30.0, gain_2=-2e-3,
                                                         offset_2=0.05), dt=0.04)
    rng = np.random.default_rng(seed)
    runs = []
    for i, f in enumerate((0.3, 0.7, 1.1)):
        t = np.arange(300) * 0.04
        u = 3 - 3 * np.cos(2 * np.pi * f * t)
        y = truth.simulate(u) + rng.normal(0, 1, (300, 2)) * [0.1, 2e-5]
        runs.append(Trajectory(t, u, y[:, 0], output_name="angle", source=f"run{i}", extra={"length": y[:, 1]}))
    return truth, runs


def test_each_output_has_its_own_map_and_counts_over_its_own_scale():
    truth, runs = _two_output_runs()
    fit = identify_outputs("lag+linear", runs, ["angle", "length"])
    assert fit.series.spec == "lag+maps" and fit.series.blocks[-1].cubic  # each output its own cubic
    for name, value in truth.param_dict().items():
        assert fit.parameters[name] == pytest.approx(value, rel=0.01), name
        assert abs(fit.parameters[name] - value) < 5 * fit.standard_errors[name], name
    for name in ("maps.c2_1", "maps.c3_1", "maps.c2_2", "maps.c3_2"):  # the truth bends neither
        assert abs(fit.parameters[name]) < 5 * fit.standard_errors[name], name
    # each output's error at its noise: the metres were not drowned by the degrees
    assert fit.train_rmse["angle"] == pytest.approx(0.1, rel=0.1)
    assert fit.train_rmse["length"] == pytest.approx(2e-5, rel=0.1)
    assert fit.predict(runs[0]).shape == (300, 2)


def test_auto_chooses_the_chain_on_the_first_output_as_the_selection_does():
    from identification.discovery import select_outputs_chain

    truth, runs = _two_output_runs()
    spec = select_outputs_chain(runs, ["angle", "length"])
    assert spec == "lag+linear"
    fit = identify_outputs(spec, runs, ["angle", "length"])
    assert fit.series.spec == "lag+maps"  # a cubic map per output
    assert fit.parameters["lag.time_constant_s"] == pytest.approx(0.2, rel=0.01)
    assert fit.train_rmse["length"] == pytest.approx(2e-5, rel=0.1)


def test_the_outputs_are_checked_before_any_fit():
    _, runs = _two_output_runs()
    with pytest.raises(IdentificationError, match=r"no output column 'width'; its columns besides the input are: "
                                                  r"angle, length"):
        identify_outputs("lag+linear", runs, ["angle", "width"])
    flat = [replace(r, extra={"length": np.full(r.n, 0.05)}) for r in runs]
    with pytest.raises(IdentificationError, match="Output 'length' is constant"):
        identify_outputs("lag+linear", flat, ["angle", "length"])
    copied = [replace(r, extra={"length": r.u.copy()}) for r in runs]
    with pytest.raises(IdentificationError, match="Output 'length' of run 'run0' is a copy of the input"):
        identify_outputs("lag+linear", copied, ["angle", "length"])
    with pytest.raises(IdentificationError, match="two or more distinct output columns"):
        identify_outputs("lag+linear", runs, ["angle"])
    with pytest.raises(IdentificationError, match="has 3 output"):
        identify_outputs(Series(Lag(), OutputMaps(outputs=3)), runs, ["angle", "length"])
    with pytest.raises(IdentificationError, match="with the tip's angle measured beside it"):
        identify_outputs("lag+linear+arc", [replace(r, extra={**r.extra, "x": r.y}) for r in runs], ["length", "x"])


def test_runs_that_start_inside_a_loop_set_their_state_from_their_warm_up(catheter_runs):
    """Cut 150 samples into each run, the catheter is mid-loop where the record starts: from rest the fit would
    bend its parameters to the first samples; the warm-up window's state (fitted on the angle) starts it where
    it was."""
    cath, runs = catheter_runs
    cut = [r.segment(150, r.n) for r in runs]
    fit = identify_outputs("backlash+boucwen+linear+arc", cut, POSE, warmup=10)
    assert fit.parameters["arc.length"] == pytest.approx(75.0, rel=0.02)
    assert fit.train_rmse["Angle x"] == pytest.approx(cath.noise_std_deg, rel=0.15)
    assert fit.predict(cut[0]).shape == (cut[0].n - 10, 3)
    assert fit.rmse(cut)["Pos y"] == pytest.approx(fit.train_rmse["Pos y"])


def test_the_exported_init_fits_the_state_on_any_subset_of_the_outputs():
    """``export_model(model, warmup=K, init_outputs=(1, 2))``: the state from the position's window alone (a
    camera), each output over its own scale. Against the truth: the play starts 0.4 mm from its rest, and from
    the position's window (or the angle's, or one coordinate's) every output is predicted as the truth runs,
    where the rest state misses by degrees. A model of one output or indices out of range are refused."""
    from hybrid.export import ExportError, export_model

    chain = Series.from_spec("lag+backlash+linear").set_params(
        **{"backlash.width": 0.5, "linear.gain": 10.0, "linear.offset": 20.0})
    pose = Series(*chain.blocks, TipArc().block(), dt=chain.dt, input_range=(0.0, 6.0))
    u = np.r_[np.full(20, 3.0), 3.0 + np.sin(2 * np.pi * 0.3 * np.arange(100) * 0.04)]
    x_true = export_model(pose).x0(u[0])
    x_true[list(pose.state_names).index("backlash.position")] += 0.4
    truth = np.asarray(pose.simulate(u, x0=x_true))
    k = 15
    rest = np.sqrt(np.mean((pose.simulate(u[k:]) - truth[k:]) ** 2, axis=0))
    assert rest[0] > 0.5 and np.all(rest[1:] > 0.2), rest
    for outputs in ((1, 2), (2,), (0,)):
        exported = export_model(pose, warmup=k, init_outputs=outputs)
        assert exported.meta["init_outputs"] == list(outputs) and "init_output" not in exported.meta
        predicted = exported.simulate(u[k:], warmup=(u[:k], truth[:k]))
        np.testing.assert_allclose(predicted, truth[k:], atol=1e-3)
    # the rows not read do not matter; the step of the one output read keeps the init, on its window alone
    exported = export_model(pose, warmup=k, init_outputs=(2,))
    blind = truth[:k].copy()
    blind[:, :2] = np.nan
    np.testing.assert_allclose(exported.simulate(u[k:], warmup=(u[:k], blind)), truth[k:], atol=1e-3)
    y_only = exported.output(2)
    assert y_only.init is not None and exported.output(1).init is None
    np.testing.assert_allclose(y_only.simulate(u[k:], warmup=(u[:k], truth[:k, 2])), truth[k:, 2], atol=1e-3)
    for bad in ((3,), (1, 1), ()):
        with pytest.raises(ExportError, match="by index, each once"):
            export_model(pose, warmup=k, init_outputs=bad)
    with pytest.raises(ExportError, match="give warmup= too"):
        export_model(pose, init_outputs=(1,))
    with pytest.raises(ExportError, match="a physics model of several"):
        export_model(chain, warmup=k, init_outputs=(0,))


def test_the_exported_init_sets_the_state_from_a_window_as_the_fits_predictions_do(catheter_runs):
    """``export_model(fit, warmup=K)`` of a model of several outputs: ``init(u_w, y_w)`` reads every output's
    window (n_y x K) and fits the state on the angle's, so the step predicts a run after its window exactly as
    the fit does (the numbers a model card reports)."""
    from hybrid.export import export_model
    from identification import output_columns, predict_outputs

    cath, runs = catheter_runs
    fit = identify_outputs("backlash+boucwen+linear+arc", runs, POSE, warmup=10)
    exported = export_model(fit.series, warmup=10)
    assert exported.meta["init_output"] == 0 and exported.init.size_in(1) == (3, 10)
    held = cath.run(DecayingSinusoid(frequency_hz=0.35, baseline="mid"))
    measured = output_columns(held, POSE)
    ours = exported.simulate(held.u[10:], warmup=(held.u[:10], measured[:10]))
    np.testing.assert_allclose(ours, predict_outputs(fit.series, held.u, measured, 10), rtol=1e-10, atol=1e-9)
    # the angle's step alone keeps the init, on the angle's window alone; a position's has none to offer
    angle = exported.output(0)
    np.testing.assert_allclose(angle.simulate(held.u[10:], warmup=(held.u[:10], measured[:10, 0])), ours[:, 0],
                               rtol=1e-12, atol=1e-12)
    assert exported.output(2).init is None and "warmup" not in exported.output(2).meta
    # the window's state does at least as well as rest at the window's first input, on every output
    from_rest = exported.simulate(held.u[10:])
    assert all(np.sqrt(np.mean((ours[:, j] - measured[10:, j]) ** 2))
               <= np.sqrt(np.mean((from_rest[:, j] - measured[10:, j]) ** 2)) for j in range(3))
