"""Models with several outputs from one chain (issue 55): the arc's closed form against the integrated arc,
the shapes, and the paths that take one output refusing a wider model."""

import numpy as np
import pytest

from hybrid.virtual import DecayingSinusoid, TipArc, VirtualCatheter
from physics import Arc, Backlash, Lag, LinearMap, OutputMaps, PhysicsError, Poly, Series, arc_points


@pytest.mark.parametrize("mirrored", [False, True])
@pytest.mark.parametrize("unit", ["deg", "rad"])
def test_the_arcs_closed_form_is_the_integrated_arc(mirrored, unit):
    turn = 360.0 if unit == "deg" else 2 * np.pi
    base_angle, heading = 0.1 * turn, -0.2 * turn
    angles = base_angle + np.array([-0.6, -0.25, -1e-7, 0.0, 1e-7, 0.1, 0.45]) * turn
    arc = Arc(length=72.0, base_x=200.0, base_y=-15.0, base_angle=base_angle, heading=heading,
              outputs=("x", "y", "angle"), mirrored=mirrored, angle_unit=unit)
    out = Series(arc, dt=0.04).simulate(angles)
    ref = arc_points(angles, 72.0, 200.0, -15.0, base_angle, heading, mirrored=mirrored, angle_unit=unit)
    np.testing.assert_allclose(out[:, :2], ref, rtol=0, atol=1e-6)  # the trapezoids' error, 20001 points: 2e-7
    np.testing.assert_array_equal(out[:, 2], angles)
    # straight: the base plus the length along the heading, exactly
    h = np.radians(heading) if unit == "deg" else heading
    np.testing.assert_allclose(out[3, :2], [200 + 72 * np.cos(h), -15 + (-1 if mirrored else 1) * 72 * np.sin(h)],
                               rtol=0, atol=1e-12)


def test_a_model_with_several_outputs_simulates_them_side_by_side():
    u = np.r_[0.0, np.ones(9)]
    model = Series(Lag(time_constant_s=0.1), OutputMaps(outputs=3, gain_1=2.0, gain_2=-1.0, offset_2=5.0,
                                                        gain_3=0.5, offset_3=-1.0), dt=0.04)
    y = model.simulate(u)
    lag = Series(Lag(time_constant_s=0.1), dt=0.04).simulate(u)
    assert model.n_y == 3 and y.shape == (10, 3)
    np.testing.assert_allclose(y, np.column_stack([2 * lag, 5 - lag, 0.5 * lag - 1]), rtol=0, atol=1e-14)
    assert model.param_names[1:3] == ["maps.gain_1", "maps.offset_1"]
    assert Series.from_dict(model.to_dict()).simulate(u) == pytest.approx(y)


def test_each_output_bends_with_its_own_cubic_about_the_centre():
    maps = OutputMaps(outputs=2, cubic=True, center=3.0, gain_1=2.0, offset_1=1.0, c2_1=0.5, c3_1=-0.1,
                      gain_2=-1.0, c3_2=0.2)
    u = np.linspace(0.0, 6.0, 7)
    y = Series(maps, dt=0.04).simulate(u)
    d = u - 3.0
    np.testing.assert_allclose(y, np.column_stack([2 * u + 1 + 0.5 * d**2 - 0.1 * d**3, -u + 0.2 * d**3]),
                               rtol=0, atol=1e-12)
    assert [p.name for p in maps.parameters][:4] == ["gain_1", "offset_1", "c2_1", "c3_1"]


def test_one_output_paths_refuse_a_model_with_several():
    model = Series(Lag(), OutputMaps(outputs=2), dt=0.04)
    with pytest.raises(PhysicsError, match=r"one output; 'lag\+maps' has 2"):
        model.inverse(np.ones(5))
    with pytest.raises(PhysicsError, match="A warm-up window takes a model with one output"):
        model.simulate(np.ones(5), warmup=(np.ones(3), np.ones(3)))
    with pytest.raises(PhysicsError, match="must be the model's last block; 'lag' follows it"):
        Series(OutputMaps(outputs=2), Lag())
    with pytest.raises(PhysicsError, match="outputs >= 2"):
        OutputMaps(outputs=1)
    with pytest.raises(PhysicsError, match="distinct names among angle, x, y"):
        Arc(outputs=("x", "x"))


def test_the_virtual_catheters_tip_leaves_its_angle_as_it_was():
    signal = DecayingSinusoid(frequency_hz=0.5, baseline="end")
    plain = VirtualCatheter(seed=2).run(signal)
    tip = TipArc(length_mm=60.0, noise_std_mm=0.05)
    run = VirtualCatheter(seed=2, tip=tip).run(signal)
    np.testing.assert_array_equal(run.y, plain.y)
    true = arc_points(run.extra["y_true"][::40], 60.0, tip.base_x_mm, tip.base_y_mm, tip.base_angle_deg,
                      tip.heading_deg)
    np.testing.assert_allclose(np.column_stack([run.extra["pos_x_true"], run.extra["pos_y_true"]])[::40], true,
                               rtol=0, atol=1e-5)
    noise = run.extra["Pos x"] - run.extra["pos_x_true"]
    assert np.std(noise) == pytest.approx(0.05, rel=0.1)
    assert run.meta["tip"]["length_mm"] == 60.0
    pose = VirtualCatheter(seed=2, tip=tip).truth_model(pose=True)
    assert pose.spec.endswith("+linear+arc") and pose.n_y == 3


@pytest.mark.parametrize("index", [0, 1, 2])
def test_the_inverse_follows_the_output_it_is_given(index):
    """The tendon path that makes one output of the pose follow a wanted path (issue 55, item 5): the angle, or a
    coordinate of the tip; a coordinate along the heading is the same at a bend either way, so the arc looks for
    the angle among those it was fitted on."""
    pose = VirtualCatheter(effects="hysteresis,backlash", tip=TipArc()).truth_model(pose=True)
    model = Series(*pose.blocks[:-1], pose.blocks[-1].with_settings(angle_range=[30.0, 95.0]), dt=pose.dt)
    u = 3 - 2.5 * np.cos(2 * np.pi * 0.2 * np.arange(300) * 0.04)
    wanted = model.simulate(u)[:, index]
    view = model.output_view(index)
    assert view.n_y == 1 and view.param_names == model.param_names
    u_back = view.inverse(wanted, bounds=(0.0, 6.0))
    np.testing.assert_allclose(model.simulate(u_back)[:, index], wanted, rtol=0, atol=1e-9)
    assert np.max(np.abs(u_back - u)) <= 0.1 + 1e-9  # the play's half-width: the tendon anywhere in its slack


def test_a_cubic_maps_inverse_finds_the_root_inside_the_bounds():
    """-2 u + 100 + 0.02 (u - 3)^3 turns back beyond the bounds: the rest input is the root inside them."""
    model = Series(Lag(time_constant_s=0.1), OutputMaps(outputs=2, cubic=True, center=3.0, gain_1=10.0,
                                                        offset_1=30.0, gain_2=-2.0, offset_2=100.0, c3_2=0.02))
    u = 3 - 2.5 * np.cos(2 * np.pi * 0.2 * np.arange(100) * 0.04)
    wanted = model.simulate(u)[:, 1]
    np.testing.assert_allclose(model.output_view(1).inverse(wanted, bounds=(0.0, 6.0)), u, rtol=0, atol=1e-9)


def test_a_memoryless_blocks_root_solve_inverts_after_a_one_state_chain():
    """backlash (one state) + poly: the poly's empty slice of a one-entry state came as 1 x 0, and the default
    Newton inverse could not stack it (the arc's view after a backlash hit the same)."""
    model = Series(Backlash(smoothing=0.0), Poly(c3=0.01), LinearMap(), dt=0.04)
    u = 3 - 2.5 * np.cos(2 * np.pi * 0.2 * np.arange(100) * 0.04)
    wanted = model.simulate(u)
    np.testing.assert_allclose(model.simulate(model.inverse(wanted)), wanted, rtol=0, atol=1e-9)
