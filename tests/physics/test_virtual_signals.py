"""Command signals against the seed paper's formula and their documented settings."""

import math

import numpy as np
import pytest

from physics.virtual import BASELINES, Command, DecayingSinusoid, Multisine, RandomSteps, sample_times


def test_decaying_sinusoid_matches_hand_computed_points():
    end = DecayingSinusoid(frequency_hz=0.5, baseline="end")
    # tau = f ln(7/6); after one period exp(-tau/f) = 6/7
    assert end.tau == pytest.approx(0.5 * math.log(7 / 6))
    assert float(end(0.0)) == pytest.approx(0.0, abs=1e-12)          # 3 (−1 − 1) + 6
    assert float(end(1.0)) == pytest.approx(6.0, abs=1e-12)          # sin = 1, c = −1
    assert float(end(2.0)) == pytest.approx(6 - 6 * 6 / 7, abs=1e-12)
    zero = DecayingSinusoid(frequency_hz=0.1, baseline="zero")
    assert float(zero(5.0)) == pytest.approx(6 * math.sqrt(6 / 7), abs=1e-12)
    mid = DecayingSinusoid(frequency_hz=0.2, baseline="mid")
    assert float(mid(1.25)) == pytest.approx(3.0, abs=1e-12)         # quarter period: sin = 0
    assert float(mid(0.0)) == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("baseline", list(BASELINES))
def test_paper_baselines_start_at_rest_and_stay_in_travel(baseline):
    s = DecayingSinusoid(frequency_hz=0.3, baseline=baseline)
    time, q = s.sample(25.0)
    assert s.duration == pytest.approx(7 / 0.3)
    assert q[0] == pytest.approx(0.0, abs=1e-12)
    assert q.min() >= -1e-12 and q.max() <= 6 + 1e-12


def test_amplitude_scales_for_out_of_range_tests():
    s = DecayingSinusoid(frequency_hz=0.1, baseline="zero", q_max_mm=4.5)
    assert float(s(5.0)) == pytest.approx(9 * math.sqrt(6 / 7))
    assert "q4.5" in s.name and s.describe()["q_max_mm"] == 4.5


def test_sample_grid_includes_the_end():
    time, q = DecayingSinusoid(frequency_hz=0.5).sample(25.0)
    assert time.size == 351 and time[-1] == pytest.approx(14.0)
    np.testing.assert_allclose(np.diff(time), 0.04)
    assert sample_times(1.0, 10.0).size == 11


def test_bad_settings_say_what_is_allowed():
    with pytest.raises(ValueError, match="zero, mid, end"):
        DecayingSinusoid(baseline="top")
    with pytest.raises(ValueError, match="frequency_hz"):
        DecayingSinusoid(frequency_hz=0.0)


def test_multisine_is_seeded_in_band_and_within_travel():
    a, b, c = Multisine(duration_s=40, seed=1), Multisine(duration_s=40, seed=1), Multisine(duration_s=40, seed=2)
    _, qa = a.sample(25.0)
    np.testing.assert_array_equal(qa, b.sample(25.0)[1])
    assert not np.allclose(qa, c.sample(25.0)[1])
    assert qa.min() >= 0.0 and qa.max() <= 6.0 and qa.max() - qa.min() > 5.8
    tones = np.array(a.describe()["tones_hz"])
    assert tones.min() >= 0.05 - 1 / 40 and tones.max() <= 0.5 + 1 / 40
    narrow = Multisine(duration_s=40, range_mm=(2.0, 4.0), seed=1).sample(25.0)[1]
    assert narrow.min() >= 2.0 and narrow.max() <= 4.0


def test_random_steps_hold_and_levels():
    s = RandomSteps(duration_s=60, hold_s=(1.0, 2.0), levels_mm=(1.0, 5.0), seed=4)
    time, q = s.sample(100.0)
    switches = time[1:][np.diff(q) != 0]
    holds = np.diff(switches)
    assert holds.min() >= 1.0 - 0.011 and holds.max() <= 2.0 + 0.011
    assert q.min() >= 1.0 and q.max() <= 5.0
    np.testing.assert_array_equal(q, RandomSteps(duration_s=60, hold_s=(1.0, 2.0), levels_mm=(1.0, 5.0), seed=4).sample(100.0)[1])


def test_user_command_is_interpolated_linearly_from_its_start():
    c = Command([10.0, 11.0, 13.0], [1.0, 3.0, 2.0])
    assert c.duration == 3.0
    np.testing.assert_allclose(c([0.0, 0.5, 2.0, 3.0]), [1.0, 2.0, 2.5, 2.0])
    with pytest.raises(ValueError, match="strictly increasing"):
        Command([0.0, 0.0, 1.0], [0.0, 1.0, 2.0])
