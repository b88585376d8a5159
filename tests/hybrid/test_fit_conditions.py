"""``hyst fit`` calibrates its intervals leaving a whole condition out (issue 45): from the runs' ``meta`` or a
file-name pattern (``--group``), and the card says how many conditions and runs the calibration saw."""

from dataclasses import replace

import numpy as np
import pytest

from hybrid.experiments._fit import fit_model_dir
from physics import Series
from physics.data import DataError, Trajectory

DT = 0.1


def _run(day: int, k: int, offset: float) -> Trajectory:
    """Loops through a line, offset by the day they were recorded on (the shift leaving a day out shows)."""
    truth = Series.from_spec("linear", dt=DT).set_params(**{"linear.gain": 10.0})
    t = np.arange(300) * DT
    u = 2.0 - 1.5 * np.cos(2 * np.pi * (0.1 + 0.02 * k) * t)
    rng = np.random.default_rng(10 * day + k)
    return Trajectory(t, u, truth.simulate(u) + offset + rng.normal(0, 0.1, t.size), source=f"day{day}_run{k}.csv",
                      meta={"day": f"d{day}"})


@pytest.fixture(scope="module")
def runs():
    return [_run(d, k, off) for d, off in ((1, 0.0), (2, 1.0)) for k in range(3)]


def test_a_condition_in_the_meta_is_left_out_whole_and_the_card_says_so(runs, tmp_path):
    result = fit_model_dir(runs, tmp_path / "m", physics="linear", residual="none", progress=False, warmup=0)
    cal = result.calibration
    assert cal["conditions"] == "meta 'day'" and cal["report"]["conditions"] == 2
    assert result.intervals.conditions_ == ["d1"] * 3 + ["d2"] * 3
    # each day predicted by the line fitted on the other day: the days differ by 1, so do the errors
    offsets = [float(np.mean(r)) for r in result.intervals.errors_]
    assert np.allclose(offsets, [-1.0] * 3 + [1.0] * 3, atol=0.05), offsets
    report = (tmp_path / "m" / "report.md").read_text()
    assert "2 conditions left out whole (6 runs)" in report and "**Too few for the stated level**" in report
    assert "it needs at least 9 conditions" in report and "widened for a new run's offset" in report


def test_a_file_name_pattern_names_the_condition_and_a_bad_one_fails_before_any_work(runs, tmp_path):
    bare = [replace(r, meta={}) for r in runs]
    result = fit_model_dir(bare, tmp_path / "m", physics="linear", residual="none", progress=False, warmup=0,
                           group=r"day(\d)")
    assert result.intervals.conditions_ == ["1"] * 3 + ["2"] * 3
    assert result.calibration["conditions"] == "file names by 'day(\\\\d)'"
    with pytest.raises(DataError, match="matches no part of the file name"):
        fit_model_dir(bare, tmp_path / "n", physics="linear", residual="none", progress=False, group=r"week(\d)")
    assert not (tmp_path / "n").exists()
    plain = fit_model_dir(bare, tmp_path / "p", physics="linear", residual="none", progress=False, warmup=0)
    assert plain.calibration["conditions"] == "none (each run its own)" and plain.intervals.conditions_ == [None] * 6


def test_hyst_fit_group_reaches_the_fit_and_a_bad_pattern_is_refused_before_any_work(fitted_linear, tmp_path,
                                                                                      capsys):
    from hybrid.cli import main

    code = main(["fit", str(fitted_linear / "run.csv"), "--physics", "linear", "--residual", "none", "--no-progress",
                 "--group", r"week(\d)", "--out", str(tmp_path / "m")])
    assert code != 0 and "matches no part of the file name 'run.csv'" in capsys.readouterr().err
    assert not (tmp_path / "m").exists()
