"""Intervals for the shift a new run brings (issue 45): the random effect per run, the report of what the
calibration saw, the conditions left out whole."""

import math

import numpy as np
import pytest
from scipy import stats

from hybrid.intervals import condition_folds, run_conditions
from hybrid.intervals import CalibrationReport, ConformalIntervals, HeldOut, coverage
from hybrid.intervals._shift import offset_quantile
from physics.data import DataError, Trajectory

DT = 0.04


def _run(rng, offset: float, n: int = 300, noise: float = 0.3, source: str = "", meta=None):
    """A run whose error is its own offset plus autocorrelated noise; the prediction is the truth."""
    t = np.arange(n) * DT
    u = 1.5 * (1 - np.cos(2 * np.pi * 0.3 * t))
    y_hat = 10 * u
    e = np.convolve(rng.normal(0, noise, n + 10), np.ones(10) / np.sqrt(10), mode="valid")[:n]
    return Trajectory(t, u, y_hat + offset + e, source=source, meta=dict(meta or {})), y_hat


@pytest.fixture(scope="module")
def train():
    rng = np.random.default_rng(0)
    return [_run(rng, 0.0, source=f"train{i}")[0] for i in range(4)]


def test_offset_quantile_matches_the_normal_mixture_with_many_runs():
    """Offsets N(0, 1) and within-run errors N(0, 0.5) over 400 runs: the half-width of 90 % is the
    normal quantile of the offsets' spread (as sampled, times sqrt(1 + 1/G)) and the within-run one
    added in quadrature, to 1 % (t with 399 degrees of freedom is all but normal)."""
    rng = np.random.default_rng(1)
    residuals = [rng.normal(m, 0.5, 200) for m in rng.normal(0, 1, 400)]
    offsets = np.array([r.mean() for r in residuals])
    spread = math.sqrt(offsets.var(ddof=1) * (1 + 1 / 400) + np.mean([r.var() for r in residuals]))
    assert abs(offsets.mean()) < 0.1  # centred: the 90 % half-width is the one-sided 95 % quantile
    assert offset_quantile(residuals, 0.9) == pytest.approx(stats.norm.ppf(0.95) * spread, rel=0.01)


def test_offset_quantile_widens_with_fewer_runs_and_needs_two():
    """The same spread of offsets seen on 3 runs gives a wider half-width than on 30 (Student's t)."""
    rng = np.random.default_rng(2)
    offsets = np.array([-1.0, 0.0, 1.0])
    few = offset_quantile([rng.normal(m, 0.3, 300) for m in offsets], 0.9)
    many = offset_quantile([rng.normal(m, 0.3, 300) for m in np.tile(offsets, 10)], 0.9)
    assert few > 1.5 * many
    with pytest.raises(ValueError, match="at least 2 runs"):
        offset_quantile([np.zeros(5)], 0.9)


def test_the_shift_term_holds_the_level_on_new_runs_where_pooled_samples_do_not(train):
    """Five held-out runs, each offset by N(0, 1) over within-run noise of 0.3: averaged over 80
    calibrations, a new run is covered 0.93 with the random effect and 0.85 without (pooling the
    few offsets seen as all there are)."""
    rng = np.random.default_rng(3)
    with_shift, without = [], []
    for _ in range(80):
        held = [HeldOut(*_run(rng, rng.normal(0, 1), source=f"h{i}"), train) for i in range(5)]
        run, y_hat = _run(rng, rng.normal(0, 1))
        for shift, out in ((True, with_shift), (False, without)):
            band = ConformalIntervals(0.9, shift=shift).fit(train, held).interval(y_hat, run.u, run.dt)
            out.append(coverage(run.y, band.lo, band.hi))
    assert 0.89 <= np.mean(with_shift) <= 0.97, np.mean(with_shift)
    assert np.mean(without) < np.mean(with_shift) - 0.04, (np.mean(without), np.mean(with_shift))


def test_report_says_how_many_runs_and_conditions_and_when_too_few(train):
    rng = np.random.default_rng(4)
    held = [HeldOut(*_run(rng, rng.normal(0, 1), source=f"h{i}"), train) for i in range(5)]
    report = ConformalIntervals(0.9).fit(train, held).report()
    assert isinstance(report, CalibrationReport)
    assert (report.runs, report.conditions, report.needed, report.unit) == (5, 0, 9, "runs")
    assert not report.enough and 0.8 <= report.nested <= 1.0
    text = " ".join(report.notes)
    assert "5 runs of one condition" in text and "too few for a guaranteed 90%" in text
    assert "at least 9 runs recorded under other conditions" in text

    conditions = [HeldOut(h.run, h.prediction, h.trained_on, condition=f"day{i % 2}") for i, h in enumerate(held)]
    report = ConformalIntervals(0.9).fit(train, conditions).report()
    assert (report.conditions, report.unit, report.units) == (2, "conditions", 2)
    assert "2 conditions left out whole (5 runs)" in report.notes[0]


def test_two_whole_runs_are_reported_as_runs_whose_offsets_come_from_their_pieces(train):
    """Two held-out runs are two runs (not "2 pieces"): only the offsets between recordings rest on their
    segments, the weaker assumption the card states; held-out pieces of runs stay pieces."""
    rng = np.random.default_rng(6)
    two = ConformalIntervals(0.9).fit(train, [HeldOut(*_run(rng, 0.0, source=f"h{i}"), train) for i in range(2)])
    report = two.report()
    assert (report.runs, report.pieces, report.unit) == (2, True, "runs") and not report.enough
    assert report.notes[0] == "The calibration saw 2 runs of one condition, each left out in turn."
    assert "2 runs are too few to show how recordings are offset from each other" in report.notes[1]
    pieces = [HeldOut(*_run(rng, 0.0, n=100, source=f"run.csv[{100 * i}:{100 * i + 100}]"), train, piece=True)
              for i in range(6)]
    report = ConformalIntervals(0.9).fit(train, pieces).report()
    assert (report.runs, report.pieces, report.unit) == (6, True, "pieces of runs")
    assert report.notes[0] == "The calibration saw 6 pieces of runs."
    assert "pieces of the same recordings are the calibration groups" in report.notes[1]


def test_report_warns_from_the_training_runs_alone_when_one_run_is_far_off(train):
    """Four runs alike and one offset by 6 noise widths: calibrated without it, the others cannot cover
    it, and the nested check says so before any test run is seen."""
    rng = np.random.default_rng(5)
    held = [HeldOut(*_run(rng, 0.0, source=f"h{i}"), train) for i in range(4)]
    held.append(HeldOut(*_run(rng, 6.0, source="far"), train))
    intervals = ConformalIntervals(0.9).fit(train, held)
    report = intervals.report()
    assert report.nested < 0.85 and report.reaches is False
    assert any("Expect less than 90% on new recordings" in n for n in report.notes)
    # the far run is the one short, named with the chance a new recording falls short as it did: (1 + 1) / (5 + 1)
    shares = intervals.nested_shares()
    assert report.nested_runs == shares and np.mean(shares) == pytest.approx(report.nested)
    assert shares[-1] < 0.85 and min(shares[:-1]) >= 0.85 and report.short == 1
    assert report.chance_short == pytest.approx(2 / 6)
    assert f"1 of the 5 held-out runs covered less than 85% calibrated without them (worst {shares[-1]:.0%})" in \
        report.notes[-1] and "about 33%" in report.notes[-1]
    assert report.to_dict()["short"] == 1 and report.to_dict()["nested_runs"] == shares


def test_one_short_run_is_not_enough_though_the_mean_reaches_the_level():
    """The mean of the nested check can reach 85 % while one run falls far short (set 1 -> 2's default:
    92 % mean, one run 78 %): the report is then not enough, and says how likely a new one falls short."""
    report = CalibrationReport.build(0.9, 5, 0, False, [0.78, 1.0, 1.0, 1.0, 0.92])
    assert report.reaches and not report.enough and report.short == 1
    assert "a new recording can fall short as they did, with a chance of about 33%" in report.notes[-1]
    fine = CalibrationReport.build(0.9, 5, 0, False, [0.91, 1.0, 1.0, 1.0, 0.92])
    assert fine.short == 0 and fine.chance_short == pytest.approx(1 / 6)
    assert "None of the 5 held-out runs covered less than 85%" in fine.notes[-1] and "up to 17%" in fine.notes[-1]
    assert CalibrationReport.build(0.9, 2, 0, True).chance_short is None  # too few runs to check


def test_nested_folds_leave_a_run_or_a_condition_out():
    from hybrid.intervals._shift import nested_folds

    assert nested_folds(2) == []
    assert nested_folds(3) == [([1, 2], [0]), ([0, 2], [1]), ([0, 1], [2])]
    assert nested_folds(4, ["A", "A", "B", None]) == [([2, 3], [0, 1]), ([0, 1, 3], [2]), ([0, 1, 2], [3])]
    assert nested_folds(3, ["A", "A", "B"]) == [([0, 1], [2])]  # leaving A out keeps one run: not scored


def test_two_held_out_runs_take_the_offsets_of_their_segments(train):
    """Two runs' offsets would give t one degree of freedom (a band 100 times the spread): the segments'
    offsets set the random effect instead, and the report names the weaker assumption."""
    rng = np.random.default_rng(6)
    held = [HeldOut(*_run(rng, m, source=f"h{i}"), train) for i, m in enumerate((-1.0, 1.0))]
    intervals = ConformalIntervals(0.9).fit(train, held)
    assert intervals.quantile() < 4.0
    report = intervals.report()
    assert report.pieces and report.nested is None
    assert any("A weaker assumption than held-out runs" in n for n in report.notes)


def test_round_trip_keeps_the_signed_residuals_and_an_old_file_loads_without_the_shift(train):
    rng = np.random.default_rng(7)
    held = [HeldOut(*_run(rng, rng.normal(0, 1), source=f"h{i}"), train, condition=str(i % 2)) for i in range(5)]
    intervals = ConformalIntervals(0.9).fit(train, held)
    again = ConformalIntervals.from_dict(intervals.to_dict())
    assert again.quantile() == pytest.approx(intervals.quantile(), rel=1e-5)
    assert again.conditions_ == ["0", "1", "0", "1", "0"]
    old = intervals.to_dict()
    old["scores"] = [np.abs(r).tolist() for r in old.pop("residuals")]
    for key in ("shift", "conditions", "pieces"):
        old.pop(key)
    legacy = ConformalIntervals.from_dict(old)
    assert legacy.shift is False
    assert legacy.quantile() == pytest.approx(ConformalIntervals(0.9, shift=False).fit(train, held).quantile(),
                                              rel=1e-5)


def test_conditions_from_meta_from_file_names_and_clear_refusals():
    rng = np.random.default_rng(8)
    runs = [_run(rng, 0, source=f"/data/day{d}_run{i}.csv", meta={"baseline": b, "frequency_hz": f})[0]
            for i, (d, b, f) in enumerate([(1, "a", 0.1), (1, "a", 0.2), (2, "b", 0.1), (2, "b", 0.2)])]
    labels, how = run_conditions(runs)
    assert labels == ["a", "a", "b", "b"] and how == "meta 'baseline'"
    assert condition_folds(labels) == [[0, 1], [2, 3]]
    assert run_conditions(runs, r"day(\d+)")[0] == ["1", "1", "2", "2"]
    assert run_conditions(runs, "frequency_hz")[0] == ["0.1", "0.2", "0.1", "0.2"]
    assert run_conditions(runs[:1] + runs[2:3])[0] is None  # every run its own condition: leave one run out
    with pytest.raises(DataError, match="matches no part of the file name"):
        run_conditions(runs, r"week(\d+)")
    with pytest.raises(DataError, match="one condition"):
        run_conditions(runs, r"run")
    with pytest.raises(DataError, match="not a valid regular expression|neither a meta key"):
        run_conditions(runs, "day(")


def test_the_nested_check_leaves_a_whole_condition_out_where_runs_carry_one():
    """Three runs of condition A around 0 and three of B around 5 (noise 1): left out run by run, each
    run has its condition's others beside it and is covered; left out condition by condition, B's runs
    meet A's band (about 1.6 wide: under 1 % of B inside) and A's runs B's (about 6.5: all inside)."""
    from hybrid.intervals._conformal import _half_width
    from hybrid.intervals._shift import nested_coverage

    rng = np.random.default_rng(0)
    runs = [rng.normal(0, 1, 400) for _ in range(3)] + [5 + rng.normal(0, 1, 400) for _ in range(3)]
    rule = lambda rs, lv: _half_width(rs, lv, True)  # noqa: E731
    by_run = nested_coverage(runs, 0.9, rule)
    by_condition = nested_coverage(runs, 0.9, rule, ["A"] * 3 + ["B"] * 3)
    assert by_run > 0.85
    assert by_condition == pytest.approx(0.5, abs=0.03), by_condition
    assert nested_coverage(runs, 0.9, rule, [None] * 6) == by_run  # no conditions: run by run
    assert nested_coverage(runs[:4], 0.9, rule, ["A", "A", "A", "B"]) is not None  # B alone is still scored
