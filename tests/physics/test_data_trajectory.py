"""Trajectory and Dataset: validation messages, derived values, swap, split."""

import numpy as np
import pytest

from physics.data import DataError, Dataset, DataSplit, Trajectory


def make(n=5, **kw):
    t = np.arange(n) * 0.04
    return Trajectory(t, np.sin(t), np.cos(t), **kw)


def test_basic_properties_and_read_only():
    traj = make(6, input_name="disp", input_unit="mm")
    assert traj.n == 6
    assert traj.dt == pytest.approx(0.04)
    assert traj.duration == pytest.approx(0.2)
    assert traj.time.dtype == np.float64
    with pytest.raises(ValueError):
        traj.u[0] = 1.0  # arrays are read-only
    with pytest.raises(AttributeError):
        traj.u = np.zeros(6)  # frozen


def test_inputs_are_copied():
    t, u = np.arange(3.0), np.arange(3.0)
    traj = Trajectory(t, u, u)
    u[0] = 99.0
    assert traj.u[0] == 0.0


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
@pytest.mark.parametrize("field", ["u", "y", "time"])
def test_nonfinite_names_array_and_index(bad, field):
    arrays = {"time": np.arange(5.0), "u": np.zeros(5), "y": np.zeros(5)}
    arrays[field] = arrays[field].copy()
    arrays[field][3] = bad
    with pytest.raises(DataError, match=rf"{field} has a non-finite value .* at index 3"):
        Trajectory(**arrays)


def test_nonfinite_extra_named():
    with pytest.raises(DataError, match=r"extra\['z'\] has a non-finite value .* at index 1"):
        Trajectory(np.arange(3.0), np.zeros(3), np.zeros(3), extra={"z": [0.0, np.nan, 0.0]})


@pytest.mark.parametrize("time", [[0.0, 1.0, 1.0, 2.0], [0.0, 1.0, 0.5, 2.0]])
def test_time_not_strictly_increasing_names_index(time):
    with pytest.raises(DataError, match=r"strictly increasing, but time\[2\].*from_raw"):
        Trajectory(time, np.zeros(4), np.zeros(4))


def test_mismatched_lengths_listed():
    with pytest.raises(DataError, match="time has 4, u has 4, y has 3 samples"):
        Trajectory(np.arange(4.0), np.zeros(4), np.zeros(3))
    with pytest.raises(DataError, match=r"extra\['s'\] has 2"):
        Trajectory(np.arange(4.0), np.zeros(4), np.zeros(4), extra={"s": np.zeros(2)})


def test_not_1d():
    with pytest.raises(DataError, match=r"u must be 1-D; got an array of shape \(4, 1\)"):
        Trajectory(np.arange(4.0), np.zeros((4, 1)), np.zeros(4))


def test_reserved_extra_name():
    with pytest.raises(DataError, match="extra column name 'u' is not allowed"):
        Trajectory(np.arange(2.0), np.zeros(2), np.zeros(2), extra={"u": np.zeros(2)})


def test_swap_exchanges_signals_names_units():
    traj = make(4, input_name="disp", output_name="angle", input_unit="mm", output_unit="deg")
    inv = traj.swap()
    np.testing.assert_array_equal(inv.u, traj.y)
    np.testing.assert_array_equal(inv.y, traj.u)
    assert (inv.input_name, inv.output_name, inv.input_unit, inv.output_unit) == ("angle", "disp", "deg", "mm")
    np.testing.assert_array_equal(inv.swap().u, traj.u)


def test_from_raw_handles_duplicates_and_sets_rate():
    t = np.array([0.0, 0.1, 0.1, 0.25, 0.4, 0.4, 0.5])
    traj = Trajectory.from_raw(t, 2 * t, 3 * t, rate_hz=10.0, extra={"s": t}, meta={"set": 1})
    np.testing.assert_allclose(np.diff(traj.time), 0.1)
    np.testing.assert_allclose(traj.u, 2 * traj.time, atol=1e-12)
    np.testing.assert_allclose(traj.extra["s"], traj.time, atol=1e-12)
    assert traj.meta == {"set": 1, "rate_hz": 10.0}


def test_from_raw_rejects_decreasing_time_with_index():
    with pytest.raises(DataError, match=r"time decreases at index 2"):
        Trajectory.from_raw([0.0, 0.2, 0.1, 0.3], np.zeros(4), np.zeros(4), rate_hz=10.0)


def test_resample_method_keeps_names_and_extra():
    t = np.linspace(0.0, 2.0, 2001)
    traj = Trajectory(t, t, 2 * t, input_name="a", source="src", extra={"e": -t}, meta={"k": 1})
    out = traj.resample(25.0)
    assert out.meta == {"k": 1, "rate_hz": 25.0}
    assert out.input_name == "a" and out.source == "src"
    np.testing.assert_allclose(np.diff(out.time), 0.04)
    np.testing.assert_allclose(out.extra["e"], -out.time, atol=1e-6)


def test_dataset_sequence_split_filter():
    trajs = [make(3, source=name) for name in "abcd"]
    ds = Dataset(trajs)
    assert len(ds) == 4 and ds[1] is trajs[1] and list(ds) == trajs
    assert ds.names == ("a", "b", "c", "d")
    assert isinstance(ds[1:3], Dataset) and ds[1:3].names == ("b", "c")
    split = ds.split(test=[1, -1])
    assert isinstance(split, DataSplit)
    assert split.train.names == ("a", "c") and split.test.names == ("b", "d")
    train, test = ds.split(test=lambda tr: tr.source in "ab")
    assert test.names == ("a", "b") and train.names == ("c", "d")
    assert ds.filter(lambda tr: tr.source == "c").names == ("c",)
    with pytest.raises(DataError, match="index 7 is out of range for a Dataset of 4"):
        ds.split(test=[7])
    with pytest.raises(DataError, match="not a Trajectory"):
        Dataset([trajs[0], "x"])
