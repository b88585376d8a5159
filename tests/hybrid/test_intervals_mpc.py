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


def _loop(mpc, exported, steps=30):
    x, u, ys, hws = exported.x0(0.0), 0.0, [], []
    for _ in range(steps):
        u_new = mpc.solve(x, [80.0] * mpc.horizon, u_prev=u)  # a reference far above the limit
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
        TrackingMPC(exported, u_bounds=(0.0, 3.0), y_bounds=(0.0, 1.0), solver="fixed-sqp")
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
