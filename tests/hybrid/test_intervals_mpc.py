"""Output bounds in the MPC, and ``tighten=True``: the model's interval, not only its prediction, inside them."""

import numpy as np
import pytest

from hybrid.control import TrackingMPC
from hybrid.export import ExportError, export_model
from hybrid.intervals import ConformalIntervals, HeldOut
from physics import Series
from physics.data import Trajectory

DT = 0.04


@pytest.fixture(scope="module")
def model():
    """A lag+backlash+linear step carrying a half-width calibrated on noisy runs of itself."""
    series = Series.from_spec("lag+backlash+linear", dt=DT)
    rng = np.random.default_rng(0)

    def run(i, f):
        t = np.arange(400) * DT
        u = 1.5 * (1 - np.cos(2 * np.pi * f * t))
        return Trajectory(t, u, series.simulate(u) + rng.normal(0, 0.5, t.size), source=f"r{i}")  # rates to 4.7 mm/s

    runs = [run(i, f) for i, f in enumerate((0.1, 0.2, 0.3, 0.4, 0.5, 0.15))]
    held = [HeldOut(r, series.simulate(r.u), runs[:2]) for r in runs[2:]]
    intervals = ConformalIntervals(0.9).fit(runs[:2], held)
    exported = export_model(series)
    exported.half_width = intervals.function()
    return exported, intervals


def _loop(mpc, exported, steps=30, half_widths=None):
    x, u, ys, hws = exported.x0(0.0), 0.0, [], []
    for _ in range(steps):
        u_new = mpc.solve(x, [80.0] * mpc.horizon, u_prev=u, half_widths=half_widths)  # far above the limit
        x, y = (np.asarray(v, dtype=float).ravel() for v in exported.step(x, u_new))
        hws.append(float(exported.half_width(u_new, u, y[0])[0]))
        u = u_new
        ys.append(y[0])
    return np.array(ys), np.array(hws)


def test_tighten_keeps_the_interval_inside_the_output_bound(model):
    exported, intervals = model
    y_max = float(exported.step(exported.x0(2.0), 2.0)[1])  # what 2 mm gives at rest
    plain = TrackingMPC(exported, horizon=15, u_bounds=(0.0, 3.0), y_bounds=(None, y_max), du_max=0.1)
    tight = TrackingMPC(exported, horizon=15, u_bounds=(0.0, 3.0), y_bounds=(None, y_max), tighten=True, du_max=0.1)
    assert plain.solver_name == tight.solver_name == "ipopt"  # auto: output constraints need the full NLP
    y_plain, _ = _loop(plain, exported)
    y_tight, hw = _loop(tight, exported)
    assert y_plain.max() <= y_max + 1e-3 and y_plain.max() > y_max - 0.05 * intervals.quantile()
    assert np.all(y_tight + hw <= y_max + 1e-3)
    assert y_tight.max() < y_plain.max() - 0.9 * intervals.quantile()  # it backs off by the half-width


def test_output_bounds_are_checked(model):
    exported, _ = model
    with pytest.raises(ExportError, match="give them"):
        TrackingMPC(exported, u_bounds=(0.0, 3.0), tighten=True)
    with pytest.raises(ExportError, match="low < high"):
        TrackingMPC(exported, u_bounds=(0.0, 3.0), y_bounds=(5.0, 1.0))
    with pytest.raises(ExportError, match="bounds the inputs only"):
        TrackingMPC(exported, u_bounds=(0.0, 3.0), y_bounds=(0.0, 1.0), solver="adjoint-sqp")
    bare = export_model(Series.from_spec("lag+backlash+linear", dt=DT))
    with pytest.raises(ExportError, match="carries its prediction interval"):
        TrackingMPC(bare, u_bounds=(0.0, 3.0), y_bounds=(0.0, 1.0), tighten=True)


def test_tighten_takes_an_online_band_the_caller_gives(model):
    """``solve(..., half_widths=)``: an online band replaces the exported offline one; the output backs off
    from the bound by that band instead (here half the offline one, as a band narrowed by measurements)."""
    from hybrid.intervals import AdaptiveIntervals

    exported, intervals = model
    online = AdaptiveIntervals(every=25).fit(intervals)  # white noise N(0, 0.5): a measurement tells nothing
    state = online.update(online.initial(), 0.3)
    widths = np.array([online.half_width(state, ahead=k) for k in range(1, 16)])
    assert np.all(np.abs(widths / (1.645 * 0.5) - 1) < 0.1), widths  # the noise's own 90 % half-width
    narrow = np.full(15, 0.5 * intervals.quantile())
    y_max = float(exported.step(exported.x0(2.0), 2.0)[1])
    tight = TrackingMPC(exported, horizon=15, u_bounds=(0.0, 3.0), y_bounds=(None, y_max), tighten=True, du_max=0.1)
    x, u, ys = exported.x0(0.0), 0.0, []
    for _ in range(30):
        u = tight.solve(x, [80.0] * 15, u_prev=u, half_widths=narrow)
        x, y = (np.asarray(v, dtype=float).ravel() for v in exported.step(x, u))
        ys.append(y[0])
    y_tight, _ = _loop(TrackingMPC(exported, horizon=15, u_bounds=(0.0, 3.0), y_bounds=(None, y_max),
                                   tighten=True, du_max=0.1), exported)
    assert max(ys) <= y_max - narrow[0] + 1e-3  # the first sample ahead keeps its band inside
    assert max(ys) > y_tight.max() + 0.5 * (intervals.quantile() - narrow.max())  # closer than the offline band
    with pytest.raises(ExportError, match="one or 15"):
        tight.solve(x, [80.0] * 15, u_prev=u, half_widths=np.ones(3))
    plain = TrackingMPC(exported, horizon=15, u_bounds=(0.0, 3.0), y_bounds=(None, y_max), du_max=0.1)
    with pytest.raises(ExportError, match="tighten=True"):
        plain.solve(x, [80.0] * 15, u_prev=u, half_widths=narrow)


FIXED = dict(horizon=15, u_bounds=(0.0, 3.0), du_max=0.1, solver="fixed-sqp")


def test_fixed_sqp_keeps_the_output_at_the_bound_by_its_penalty(model):
    """The fixed-iteration SQP (the C controller's) carries the output bound as a squared hinge: a
    reference 28 deg above the bound takes the output past it by about w_track / bound_weight of the
    gap (measured 0.035 deg at the default 1e3, 0.0064 at 1e4), where the same run without bounds
    overshoots by 5.9 deg."""
    from hybrid.control._fixed_sqp import BOUND_WEIGHT

    exported, _ = model
    y_max = float(exported.step(exported.x0(2.0), 2.0)[1])
    free, _ = _loop(TrackingMPC(exported, **FIXED), exported)
    bounded = TrackingMPC(exported, **FIXED, y_bounds=(None, y_max))
    y, _ = _loop(bounded, exported)
    stiff, _ = _loop(TrackingMPC(exported, **FIXED, y_bounds=(None, y_max), solver_options={"bound_weight": 1e4}),
                     exported)
    gap = 80.0 - y_max
    assert free.max() > y_max + 5.0
    assert y.max() <= y_max + 2 * gap / BOUND_WEIGHT  # 0.035 deg against a tolerance of 0.057
    assert y.max() - y_max < 0.01 * (free.max() - y_max)
    assert stiff.max() - y_max < 0.5 * (y.max() - y_max)  # a stiffer penalty, a smaller excess
    assert y.max() > y_max - 0.1  # it tracks up to the bound, not far below it
    with pytest.raises(ExportError, match="bound_weight must be"):
        TrackingMPC(exported, **FIXED, y_bounds=(None, y_max), solver_options={"bound_weight": 0.0})


def test_fixed_sqp_keeps_the_given_band_inside_the_bound(model):
    """``half_widths`` (an online band) reach the fixed SQP's control function as its input ``h``: a
    wider band keeps the output further from the bound, by the difference of the widths (measured:
    y + h past the bound by 0.040 and 0.047 deg for h = 0.5 and 1.0, the soft constraint's excess).
    Without a given band, ``tighten`` takes the model's own along the warm start, and backs off as
    IPOPT does (measured 2.71 and 2.69 deg)."""
    from hybrid.control._fixed_sqp import BOUND_WEIGHT

    exported, intervals = model
    y_max = float(exported.step(exported.x0(2.0), 2.0)[1])
    tight = TrackingMPC(exported, **FIXED, y_bounds=(None, y_max), tighten=True)
    ys = {h: _loop(tight, exported, half_widths=np.full(15, h))[0].max() for h in (0.5, 1.0)}
    for h, y in ys.items():
        assert y_max - h - 0.1 < y <= y_max - h + 2 * (80.0 - y_max + h) / BOUND_WEIGHT, (h, y)
    assert ys[0.5] - ys[1.0] > 0.45
    y_own, hw = _loop(TrackingMPC(exported, **FIXED, y_bounds=(None, y_max), tighten=True), exported)
    y_ipopt, _ = _loop(TrackingMPC(exported, **{**FIXED, "solver": "ipopt"}, y_bounds=(None, y_max), tighten=True),
                       exported)
    assert np.all(y_own + hw <= y_max + 0.06)  # the soft constraint's excess: 0.050 with its own band (q = 0.79)
    assert abs(y_own.max() - y_ipopt.max()) < 0.1, (y_own.max(), y_ipopt.max())
    assert y_own.max() < y_max - intervals.quantile() + 0.06  # backs off by the band, less the soft bound's excess


def test_the_c_controller_with_bounds_equals_its_casadi_function(model, tmp_path):
    """write_controller on a fixed-SQP MPC with output bounds: the generated control(x, u_prev, ref,
    U_guess, h), compiled, gives the CasADi function's u and U (to 1e-9; measured: equal), and main.c's
    closed loop, fed a constant half-width, equals the Python loop given that band and keeps y + h
    inside the bound. The loop's QPs are solved by DAQP from the last step's working set in C and from
    an empty one in the CasADi function: the same optimum, to DAQP's tolerances, so 1e-6 over the loop
    (measured: 1.2e-7)."""
    import re
    import shutil
    import subprocess

    import casadi as ca

    from hybrid.control import reference_signal, rest_output, write_controller

    if shutil.which("gcc") is None or shutil.which("make") is None:
        pytest.skip("gcc and make are needed to build the C controller")
    exported, _ = model
    y_max, h = 55.0, 0.5  # main.c's sine reaches 59.7
    mpc = TrackingMPC(exported, **{**FIXED, "u_bounds": (0.0, 3.0)}, y_bounds=(None, y_max), tighten=True,
                      solver_options={"compile": False})
    folder = write_controller(mpc, tmp_path / "ctrl", duration_s=4.0, half_width=h)
    assert "arg[4] = h;" in (folder / "main.c").read_text()
    # plain C99 and libm: nothing beyond the files it writes
    subprocess.run(["make", "-s", "-C", str(folder), "CFLAGS=-O2 -std=c99"], check=True, capture_output=True)
    c_control = ca.external("control", str(folder / "libcontroller.so"))
    rng = np.random.default_rng(1)
    for _ in range(10):
        u0 = rng.uniform(0.0, 3.0)
        args = (exported.x0(u0), u0, rng.uniform(40, 90, 15), np.clip(u0 + rng.normal(0, 0.2, 15), 0, 3),
                rng.uniform(0, 3, 15))
        for c, py in zip(c_control(*args), mpc.solver.control_function(*args)):
            np.testing.assert_allclose(np.asarray(c, dtype=float), np.asarray(py, dtype=float), rtol=0, atol=1e-9)
    ran = subprocess.run([str(folder / "closed_loop")], capture_output=True, text=True, check=True)
    c_loop = np.loadtxt(ran.stdout.splitlines())
    # the control call's time per sample, measured in C around each call
    timing = re.fullmatch(r"control us: median (\S+) p99 (\S+) worst (\S+) over (\d+) samples", ran.stderr.strip())
    assert timing, ran.stderr
    median, p99, worst = map(float, timing.groups()[:3])
    assert 0 < median <= p99 <= worst and int(timing.group(4)) == c_loop.shape[0]
    u0 = 0.25  # a twelfth inside the bounds, as main.c
    ref = reference_signal("sine", rest_output(exported, u0), rest_output(exported, 2.75), duration_s=4.6, dt=DT)
    x, u_prev, rows = exported.x0(u0), u0, []
    for k in range(c_loop.shape[0]):
        u = mpc.solve(x, ref[k:k + 15], u_prev=u_prev, half_widths=h)
        x, y = exported.step(x, u)
        x, u_prev = np.asarray(x, dtype=float).ravel(), u
        rows.append((k, u, float(y)))
    np.testing.assert_allclose(c_loop, np.array(rows), rtol=0, atol=1e-6)
    assert c_loop[:, 2].max() <= y_max - h + 0.05
    assert c_loop[:, 2].max() > y_max - h - 0.5  # and the bound is met: the reference goes past it
    with pytest.raises(ExportError, match="the MPC has none"):
        write_controller(TrackingMPC(exported, **FIXED, solver_options={"compile": False}), tmp_path / "x",
                         half_width=1.0)


def test_the_c_controller_carries_the_online_band(model, tmp_path):
    """write_controller(..., online=): the library also holds online_band and online_update, which give
    the band the Python AdaptiveIntervals gives (the h a robot's loop feeds the control call)."""
    import shutil
    import subprocess

    import casadi as ca

    from hybrid.control import write_controller
    from hybrid.intervals import AdaptiveIntervals

    if shutil.which("gcc") is None or shutil.which("make") is None:
        pytest.skip("gcc and make are needed to build the C controller")
    exported, intervals = model
    online = AdaptiveIntervals(every=25).fit(intervals)
    mpc = TrackingMPC(exported, **FIXED, y_bounds=(None, 55.0), solver_options={"compile": False})
    folder = write_controller(mpc, tmp_path / "ctrl", duration_s=1.0, online=online)
    subprocess.run(["make", "-s", "-C", str(folder), "libcontroller.so"], check=True, capture_output=True)
    band, update = (ca.external(n, str(folder / "libcontroller.so")) for n in ("online_band", "online_update"))
    state = online.update(online.advance(online.update(online.initial(), 0.3), 25), -0.4)
    for ahead in (1, 8, 15):
        half = float(band(state.level, state.offset, state.residual, state.scale, state.since + ahead,
                          state.measured)[1])
        assert half == pytest.approx(float(online.half_width(state, ahead=ahead)), rel=1e-9)
    expected = online.update(online.advance(state, 25), 1.2)
    got = update(*online.advance(state, 25), 1.2, 1.0)
    assert [float(v) for v in got] == pytest.approx([expected.level, expected.offset, expected.scale], abs=1e-12)
    with pytest.raises(ExportError, match="the MPC has none"):
        write_controller(TrackingMPC(exported, **FIXED, solver_options={"compile": False}), tmp_path / "x",
                         online=online)


def test_the_c_closed_loop_runs_the_online_band(model, tmp_path):
    """write_controller(..., online=, measure_every=10, disturbance=0.7): main.c keeps the band's state,
    measures the model's output plus the disturbance every 10th sample and feeds the control call the
    band's half-widths; its printed k, u, y, h[0] equal the same loop in Python with the CasADi
    online_band / online_update and TrackingMPC.solve(half_widths=) (to 1e-9; measured: equal), and
    the half-widths equal AdaptiveIntervals.half_width / update's, run_closed_loop's (measured: equal).
    The band is the offline one until the first measurement, then moves; y + h stays at the bound."""
    import shutil
    import subprocess

    from hybrid.control import reference_signal, rest_output, write_controller
    from hybrid.intervals import AdaptiveIntervals

    if shutil.which("gcc") is None or shutil.which("make") is None:
        pytest.skip("gcc and make are needed to build the C controller")
    exported, intervals = model
    online, every, d, y_max = AdaptiveIntervals(every=10).fit(intervals), 10, 0.7, 55.0
    mpc = TrackingMPC(exported, **FIXED, y_bounds=(None, y_max), tighten=True, solver_options={"compile": False})
    folder = write_controller(mpc, tmp_path / "ctrl", duration_s=4.0, online=online, measure_every=every,
                              disturbance=d)
    subprocess.run(["make", "-s", "-C", str(folder), "closed_loop"], check=True, capture_output=True)
    c_loop = np.loadtxt(subprocess.run([str(folder / "closed_loop")], capture_output=True, text=True,
                                       check=True).stdout.splitlines())
    band, update = online.function(), online.update_function()
    u0 = 0.25  # a twelfth inside the bounds, as main.c
    ref = reference_signal("sine", rest_output(exported, u0), rest_output(exported, 2.75), duration_s=4.6, dt=DT)
    x, u_prev, rows = exported.x0(u0), u0, []
    state = python = online.initial()
    for k in range(c_loop.shape[0]):
        h = [online.offline_ if not state.measured else float(band(*state[:4], state.since + i, state.measured)[1])
             for i in range(1, 16)]
        np.testing.assert_allclose(h, [online.half_width(python, ahead=i) for i in range(1, 16)], rtol=0, atol=1e-9)
        u = mpc.solve(x, ref[k:k + 15], u_prev=u_prev, half_widths=h)
        x, y = exported.step(x, u)
        x, u_prev, y = np.asarray(x, dtype=float).ravel(), u, float(y)
        rows.append((k, u, y, h[0]))
        state, python = online.advance(state), online.advance(python)
        if k % every == 0:  # measured: the model's output plus the disturbance, against the model's y
            r = (y + d) - y
            level, offset, scale = (float(v) for v in update(*state, r, 1.0))
            state, python = state._replace(level=level, offset=offset, residual=r, scale=scale, since=0,
                                           measured=state.measured + 1), online.update(python, r)
    rows = np.array(rows)
    assert rows.shape == (100, 4)
    np.testing.assert_allclose(c_loop, rows, rtol=0, atol=1e-9)
    half = c_loop[:, 3]
    assert half[0] == pytest.approx(online.offline_, abs=1e-12)  # the offline band before the first measurement
    assert np.ptp(half[1:]) > 0.1 and np.unique(np.round(half, 9)).size > 50  # then it moves, sample by sample
    assert state.level < online.level_  # the forecast centres on the disturbance: hits narrow the band
    over = (c_loop[:, 2] + half).max() - y_max  # as the Python fixed-sqp (the same loop): the band at the bound
    assert over == pytest.approx((rows[:, 2] + rows[:, 3]).max() - y_max, abs=1e-9) and -0.1 < over < 0.05
    for bad, match in ((dict(online=online, measure_every=0), "measure_every must be a whole number"),
                       (dict(online=online, half_width=0.5), "leave half_width at 0"),
                       (dict(online=online, disturbance=np.inf), "disturbance must be a finite number"),
                       (dict(measure_every=5), "give online=")):
        with pytest.raises(ExportError, match=match):
            write_controller(mpc, tmp_path / "x", **bad)
