"""The virtual catheter: each effect changes the output the way its physics says."""

import math

import numpy as np
import pytest

from physics.virtual import (
    EFFECTS, LAG_TIME_CONSTANT_S, Command, DecayingSinusoid, VirtualCatheter, lag_for_peak,
    parse_effects,
)


def quiet(effects, **kw):
    kw.setdefault("input", "command")
    return VirtualCatheter(effects, noise_std_deg=0.0, **kw)


def phase_deg(u, y, f, dt):
    t = np.arange(u.size) * dt
    ref = np.exp(-2j * np.pi * f * t)
    return -math.degrees(np.angle(np.sum((y - y.mean()) * ref) / np.sum((u - u.mean()) * ref)))


def loop_width(x, y, level=3.0):
    """Falling minus rising branch of y at x = level, first cycle (positive: the output lags)."""
    d = x - level
    up = np.flatnonzero((d[:-1] < 0) & (d[1:] >= 0))[0]
    down = np.flatnonzero((d[:-1] > 0) & (d[1:] <= 0))[0]

    def at(i):
        w = -d[i] / (d[i + 1] - d[i])
        return y[i] + w * (y[i + 1] - y[i])

    return at(down) - at(up)


def test_lag_shifts_phase_more_at_higher_frequency():
    cath = quiet({"lag"})
    phases = {}
    for f in (0.1, 0.5):
        tr = cath.run(DecayingSinusoid(frequency_hz=f, baseline="mid"))
        phases[f] = phase_deg(tr.u, tr.extra["q_actual"], f, tr.dt)
        # a first-order lag delays a sine by atan(2 pi f T)
        assert phases[f] == pytest.approx(math.degrees(math.atan(2 * math.pi * f * LAG_TIME_CONSTANT_S)), abs=1.0)
    assert phases[0.5] > 3 * phases[0.1]


def test_lag_calibration_actuator_peaks_near_5_8_mm():
    tr = VirtualCatheter().run(DecayingSinusoid(frequency_hz=0.5, baseline="end"))
    first_cycle = tr.time <= 2.0
    assert tr.extra["command"][first_cycle].max() == pytest.approx(6.0)
    assert tr.extra["q_actual"][first_cycle].max() == pytest.approx(5.8, abs=0.1)
    assert lag_for_peak(5.8, 0.5) == pytest.approx(LAG_TIME_CONSTANT_S, abs=1e-3)


def test_delay_shifts_by_whole_samples():
    tr = quiet({"delay"}).run(DecayingSinusoid(frequency_hz=0.2))
    np.testing.assert_allclose(tr.extra["q_actual"][1:], tr.u[:-1], atol=1e-12)  # 0.04 s = 1 sample
    assert quiet({"delay"}).truth_model(250.0).blocks[0].samples == 10


def test_backlash_holds_the_output_right_after_a_reversal():
    # triangle 0 -> 4 -> 0 mm at 2 mm/s: 0.08 mm per sample, play 0.2 mm
    cmd = Command([0.0, 2.0, 4.0], [0.0, 4.0, 0.0])
    tr = quiet({"backlash"}).run(cmd)
    k = int(np.argmax(tr.u))  # the reversal
    assert tr.u[k] - tr.u[k + 2] == pytest.approx(0.16)
    assert abs(tr.extra["y_true"][k + 2] - tr.extra["y_true"][k]) < 1e-9   # flat zone
    assert tr.extra["y_true"][k] - tr.extra["y_true"][k + 4] > 0.5         # then it follows
    without = quiet(set()).run(cmd)
    assert without.extra["y_true"][k] - without.extra["y_true"][k + 2] > 1.5


def test_hysteresis_loop_is_rate_independent_and_lags():
    widths = {f: loop_width(*(lambda tr: (tr.u, tr.extra["y_true"]))(
        quiet({"hysteresis"}).run(DecayingSinusoid(frequency_hz=f, baseline="zero")))) for f in (0.1, 0.5)}
    assert widths[0.1] > 3.0  # falling branch above rising: the tip lags the tendon
    assert widths[0.5] == pytest.approx(widths[0.1], rel=0.05)
    for effects in (set(), {"nonlinearity"}):
        tr = quiet(effects).run(DecayingSinusoid(frequency_hz=0.1, baseline="zero"))
        assert abs(loop_width(tr.u, tr.extra["y_true"])) < 0.05


def test_default_catheter_looks_like_the_real_one():
    tr = VirtualCatheter().run(DecayingSinusoid(frequency_hz=0.1, baseline="end"))
    assert 5.0 <= loop_width(tr.extra["q_actual"], tr.extra["y_true"]) <= 7.0  # loop at mid travel
    assert tr.extra["y_true"].min() == pytest.approx(30.0, abs=2.0)
    assert tr.extra["y_true"].max() == pytest.approx(95.0, abs=2.0)
    assert np.abs(tr.extra["z"]).max() <= 0.18 + 1e-6  # Bouc-Wen saturation A / (beta + gamma)


def test_nonlinearity_and_drift_follow_their_formulas():
    cath = quiet({"nonlinearity", "drift"})
    tr = cath.run(DecayingSinusoid(frequency_hz=0.2, baseline="mid"))
    v = tr.u + cath.truth.poly_c3 * (tr.u - 3.0) ** 3
    expected = cath.truth.gain_deg_per_mm * v + cath.truth.offset_deg + tr.time / 60.0  # 1 deg per minute
    np.testing.assert_allclose(tr.extra["y_true"], expected, atol=1e-9)


def test_noise_matches_its_std_and_the_noise_floor():
    cath = VirtualCatheter(noise_std_deg=0.15, seed=3)
    tr = cath.run(DecayingSinusoid(frequency_hz=0.1, baseline="mid"))
    e = tr.y - tr.extra["y_true"]
    assert np.std(e) == pytest.approx(0.15, rel=0.08)
    assert abs(np.mean(e)) < 0.02
    assert cath.noise_floor == 0.15
    np.testing.assert_array_equal(quiet({"lag"}).run(DecayingSinusoid(0.5)).y,
                                  quiet({"lag"}).run(DecayingSinusoid(0.5)).extra["y_true"])


def test_same_seed_repeats_and_runs_get_independent_noise():
    s = DecayingSinusoid(frequency_hz=0.5, baseline="mid")
    a, b = VirtualCatheter(seed=7).run(s), VirtualCatheter(seed=7).run(s)
    np.testing.assert_array_equal(a.y, b.y)
    c = VirtualCatheter(seed=8).run(s)
    assert not np.allclose(a.y, c.y)
    np.testing.assert_array_equal(a.extra["y_true"], c.extra["y_true"])
    cath = VirtualCatheter(seed=7)
    e1 = cath.run(s, name="trial1").y - a.extra["y_true"]
    e2 = cath.run(s, name="trial2").y - a.extra["y_true"]
    assert abs(np.corrcoef(e1, e2)[0, 1]) < 0.2


def test_oversampling_converges():
    s = DecayingSinusoid(frequency_hz=0.5, baseline="zero")
    effects = set(EFFECTS)
    a = quiet(effects, oversample=10).run(s).extra["y_true"]
    b = quiet(effects, oversample=20).run(s).extra["y_true"]
    assert np.abs(a - b).max() < 0.1 * 0.15


def test_truth_model_reproduces_the_data():
    cath = VirtualCatheter(effects=set(EFFECTS), input="command")
    tr = cath.run(DecayingSinusoid(frequency_hz=0.3, baseline="end"))
    time, fine = cath.simulate_fine(DecayingSinusoid(frequency_hz=0.3, baseline="end"))
    y_fine = cath.truth_model(250.0).simulate(fine["command"])
    np.testing.assert_allclose(y_fine[::10], tr.extra["y_true"], atol=1e-9)
    y25 = cath.truth_model().simulate(tr.u)  # the model identification fits, at the data's rate
    assert np.sqrt(np.mean((y25 - tr.extra["y_true"]) ** 2)) < 0.2 * cath.noise_floor
    assert cath.truth_model().spec == "lag+delay+backlash+boucwen+poly+linear+drift"


def test_trajectory_carries_units_states_and_meta():
    tr = VirtualCatheter(seed=5).run(DecayingSinusoid(frequency_hz=0.5, baseline="end"))
    assert (tr.input_unit, tr.output_unit) == ("mm", "deg")
    assert list(tr.extra) == ["command", "q_actual", "q_backlash", "z", "y_true"]
    m = tr.meta
    assert m["source"] == "virtual" and m["seed"] == 5 and m["frequency_hz"] == 0.5
    assert m["baseline"] == "end" and m["oversample"] == 10 and m["rate_hz"] == 25.0
    assert m["effects"] == ["actuator_lag", "backlash", "hysteresis"] and m["noise_std_deg"] == 0.15
    assert m["lag_time_constant_s"] == LAG_TIME_CONSTANT_S and m["input"] == "measured"
    assert m["truth_params"]["boucwen.A"] == 0.45  # the u -> y chain: lag acts before u
    assert "z" not in quiet({"lag"}).run(DecayingSinusoid(0.5)).extra


def test_unknown_effect_lists_the_vocabulary():
    with pytest.raises(ValueError, match="actuator_lag, time_delay, backlash, hysteresis, static_nonlinearity, drift"):
        VirtualCatheter({"lag", "friction"}).run(DecayingSinusoid(0.5))
    assert parse_effects("lag, hysteresis") == {"actuator_lag", "hysteresis"}


def test_measured_input_is_the_actuator_position_and_its_loop_is_rate_independent():
    cath = VirtualCatheter(noise_std_deg=0.0)  # default: u is the measured tendon displacement
    widths = {}
    for f in (0.1, 0.5):
        tr = cath.run(DecayingSinusoid(frequency_hz=f, baseline="mid"))
        np.testing.assert_array_equal(tr.u, tr.extra["q_actual"])
        assert tr.extra["command"].max() > tr.u.max()  # the lag keeps the tendon short of the command
        widths[f] = loop_width(tr.u, tr.y)
        np.testing.assert_allclose(cath.truth_model().simulate(tr.u), tr.y, atol=0.05)
    assert cath.truth_model().spec == "backlash+boucwen+linear"
    assert widths[0.5] == pytest.approx(widths[0.1], rel=0.05)
    with pytest.raises(ValueError, match="'input' of VirtualCatheter must be one of"):
        VirtualCatheter(input="motor").run(DecayingSinusoid(0.5, "mid"))
