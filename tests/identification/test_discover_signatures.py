"""Effect signatures: the library's path features, exact shapes and the diagnosis on known residuals."""

import numpy as np
import pytest

from identification.discovery._noise import noise_floor, whiteness
from identification.discovery._shapes import (backlash_shapes, boucwen_shapes, delay_shapes, direction, lag_shapes,
                                    since_reversal)
from identification.discovery._signatures import EFFECTS, ResidualTrace, diagnose
from physics import Backlash, BoucWen, Creep, Delay, Lag, Series

DT = 0.04


def _path(freqs=(0.1, 0.3, 0.6), cycles=4):
    """Decaying sinusoids (the seed paper's command) at several frequencies."""
    out = []
    for f in freqs:
        t = np.arange(0, cycles / f, DT)
        out.append((t, 3 * np.exp(-f * np.log(7 / 6) * t) * (np.sin(2 * np.pi * f * t - np.pi / 2) + 1)))
    return out


def test_noise_floor_recovers_white_noise_on_a_smooth_signal():
    rng = np.random.default_rng(0)
    t, v = _path()[2]
    y = 30 + 10 * v + rng.normal(0, 0.2, v.size)
    assert noise_floor(y) == pytest.approx(0.2, rel=0.1)
    assert noise_floor([y, y[::-1]]) == pytest.approx(0.2, rel=0.1)


def test_whiteness_is_small_for_white_noise_and_large_for_a_trend():
    rng = np.random.default_rng(1)
    assert whiteness(rng.normal(size=2000)) < 0.1
    assert whiteness(np.sin(np.arange(2000) / 50.0)) > 0.9


def test_direction_holds_through_rests_and_distance_restarts_at_reversals():
    v = np.array([0.0, 1.0, 2.0, 2.0, 1.5, 1.0, 1.0, 2.0])
    np.testing.assert_array_equal(direction(v), [1, 1, 1, 1, -1, -1, -1, 1])
    np.testing.assert_allclose(since_reversal(v), [0, 1, 2, 2, 0.5, 1.0, 1.0, 1.0])


@pytest.mark.parametrize("make, shape", [
    (lambda: Lag(time_constant_s=0.15), lambda v: lag_shapes(v, DT, np.array([0.15]))),
    (lambda: Delay(samples=2), lambda v: delay_shapes(v, DT, np.array([2 * DT]))),
    (lambda: Backlash(width=0.3, smoothing=0.0), lambda v: backlash_shapes(v, np.array([0.3]))),
])
def test_exact_shapes_match_the_physics_blocks(make, shape):
    _, v = _path()[1]
    block_out = Series(make(), dt=DT).simulate(v)
    np.testing.assert_allclose(shape(v)[:, 0], block_out - v, atol=1e-9)


def test_boucwen_shape_matches_the_block_to_integration_accuracy():
    _, v = _path()[0]
    block_out = Series(BoucWen(A=1.0, beta=2.0, gamma=1.0, n=1.0, substeps=8), dt=DT).simulate(v)
    shape = boucwen_shapes(v, np.array([2.0]), np.array([1.0]))[:, 0]
    assert np.max(np.abs(shape - (block_out - v))) < 2e-3 * np.ptp(block_out - v)


def _traces(extra, noise=0.1, gain=10.0, seed=0):
    rng = np.random.default_rng(seed)
    out = []
    for t, v in _path():
        out.append(ResidualTrace(t, extra(t, v) + rng.normal(0, noise, v.size), v, gain=gain))
    return out


@pytest.mark.parametrize("effect, extra, check", [
    ("actuator_lag", lambda t, v: 10 * (Series(Lag(time_constant_s=0.15), dt=DT).simulate(v) - v),
     lambda c: c.parameters["time_constant_s"] == pytest.approx(0.15, rel=0.15)),
    ("time_delay", lambda t, v: 10 * (Series(Delay(samples=2), dt=DT).simulate(v) - v),
     lambda c: c.settings["samples"] == 2),
    ("backlash", lambda t, v: 10 * (Series(Backlash(width=0.3, smoothing=0), dt=DT).simulate(v) - v),
     lambda c: c.parameters["width"] == pytest.approx(0.3, rel=0.15)),
    ("hysteresis", lambda t, v: 10 * (Series(BoucWen(A=0.5, beta=1.5, gamma=1.0), dt=DT).simulate(v) - v),
     lambda c: c.parameters["A"] == pytest.approx(0.5, rel=0.3)),
    ("static_nonlinearity", lambda t, v: 10 * (-0.02 * (v - 3) ** 3),
     lambda c: c.parameters["c3"] == pytest.approx(-0.02, rel=0.1)),
    ("drift", lambda t, v: 0.03 * t, lambda c: c.parameters["rate"] == pytest.approx(0.03, rel=0.1)),
    ("creep", lambda t, v: 10 * (Series(Creep(gains=[0.2], time_constants_s=[5.0], start="steady"),
                                        dt=DT).simulate(v) - v),
     lambda c: c.parameters["gain"] == pytest.approx(0.2, rel=0.3)
     and 2.0 < c.settings["time_constant_s"] < 12.0),
])
def test_diagnose_names_the_hidden_effect_first_with_a_first_estimate(effect, extra, check):
    cands = diagnose(_traces(extra), noise_std=0.1)
    assert cands and cands[0].effect == effect
    assert check(cands[0])
    assert 0 < cands[0].score <= 1 and set(cands[0].to_dict()) >= {"effect", "score", "parameters"}


def test_creep_shape_is_the_block_with_one_mode_per_unit_gain():
    _, v = _path()[1]
    block_out = Series(Creep(gains=[0.5], time_constants_s=[4.0], start="steady"), dt=DT).simulate(v)
    shape = Creep.signature.shapes(v, DT, [{"time_constant_s": 4.0}])[:, 0]
    np.testing.assert_allclose(0.5 * shape, block_out - v, atol=1e-9 * np.ptp(v))


def test_an_output_running_ahead_of_its_input_is_not_named_creep():
    # a negative creep gain (output drawn away from where the input has been) is no creep
    anti = diagnose(_traces(lambda t, v: -10 * (Series(Creep(gains=[0.2], time_constants_s=[5.0], start="steady"),
                                                       dt=DT).simulate(v) - v)), noise_std=0.1)
    assert all(c.effect != "creep" for c in anti)


def test_diagnose_names_nothing_in_white_noise():
    assert diagnose(_traces(lambda t, v: 0 * v), noise_std=0.1) == []


def test_diagnose_estimates_the_noise_itself_and_respects_exclude():
    cands = diagnose(_traces(lambda t, v: 0.03 * t), exclude={"drift"})
    assert all(c.effect != "drift" for c in cands)


def test_diagnose_rejects_unknown_effects_and_bad_traces():
    tr = _traces(lambda t, v: 0 * v)
    with pytest.raises(ValueError, match="Must be among"):
        diagnose(tr, exclude={"friction"})
    with pytest.raises(ValueError, match="ResidualTrace"):
        diagnose([np.zeros(10)])
    with pytest.raises(ValueError, match="residual must be a finite 1-D array"):
        ResidualTrace(np.arange(10.0), np.full(10, np.nan), np.zeros(10))
    assert set(EFFECTS) == {"actuator_lag", "time_delay", "backlash", "hysteresis",
                            "static_nonlinearity", "creep", "drift", "resonance"}


def test_each_candidate_reports_what_its_shape_explains_alone():
    cands = diagnose(_traces(lambda t, v: 10 * (Series(Lag(time_constant_s=0.15), dt=DT).simulate(v) - v)),
                     noise_std=0.1)
    assert cands and all(c.alone >= c.score - 1e-9 and c.to_dict()["alone"] == c.alone for c in cands)


def test_look_alike_candidates_of_two_families_are_fitted_together():
    from identification.discovery._discover import _alike
    from identification.discovery._signatures import Candidate

    creep = Candidate("creep", 0.03, 1.0, "creep", alone=0.95)
    hyst = Candidate("hysteresis", 0.015, 1.0, "boucwen", alone=0.94)
    lag = Candidate("actuator_lag", 0.135, 1.0, "lag", alone=0.90)  # explains much beyond the others
    assert _alike(creep, hyst, 0.85) and _alike(hyst, creep, 0.85)
    assert not _alike(lag, hyst, 0.85)
    assert not _alike(creep, Candidate("drift", 0.01, 1.0, "drift", alone=0.3), 0.85)


def _same_path_at_speeds(extra, freqs=(0.1, 0.5), seed=0):
    """One decaying path (4 cycles) traced at several speeds, 25 Hz, residual ``extra(v)`` + noise."""
    rng = np.random.default_rng(seed)
    out = []
    for f in freqs:
        t = np.arange(0, 4 / f, DT)
        v = 1 + np.exp(-f * np.log(7 / 6) * t) * (np.sin(2 * np.pi * f * t - np.pi / 2) + 0.5)
        out.append(ResidualTrace(t, extra(v) + rng.normal(0, 0.01, v.size), v, gain=10.0))
    return out


def test_a_loop_traced_at_several_speeds_fails_creep_checks_but_a_relaxation_passes():
    from identification.discovery._timescale import not_in_time

    def fails(traces):
        return not_in_time(Creep.signature, traces, 10.0, 0.01, 0.02)

    # weighted wide play operators (Prandtl-Ishlinskii): rate independent, so the time constant
    # that best mimics them on each run follows that run's duration
    plays = _same_path_at_speeds(lambda v: 10 * np.mean(backlash_shapes(v, np.array([0.4, 0.8, 1.6, 2.4])), axis=1))
    assert fails(plays)
    slow = Creep(gains=[0.1, 0.1], time_constants_s=[2.0, 6.0], start="steady")
    relaxed = _same_path_at_speeds(lambda v: 10 * (Series(slow, dt=DT).simulate(v) - v))
    assert not fails(relaxed)
    assert diagnose(relaxed, noise_std=0.01)[0].effect == "creep"
    # a slow mode that only sets each run's offset (its first input) shows nothing within the runs
    offsets = [ResidualTrace(t.time, 3.0 * t.drive[0] + 0 * t.residual, t.drive, gain=10.0) for t in relaxed]
    assert fails(offsets)


def test_a_relaxation_faster_than_creep_is_left_to_the_lag():
    # a first-order lag of 0.3 s with a gain of one half: its best creep time is the grid's fast end
    fast = diagnose(_traces(lambda t, v: 10 * 0.5 * (Series(Lag(time_constant_s=0.3), dt=DT).simulate(v) - v)),
                    noise_std=0.1)
    assert fast and all(c.effect != "creep" for c in fast)
