"""Presets on the shared measured data (skipped when the data folder is absent)."""

import numpy as np
import pytest

from physics.data import DataError, DataNotFoundError, DataSplit, data_root, load_preset


@pytest.fixture(scope="module")
def catheter(root):
    return load_preset("catheter_2023", rate_hz=25.0, root=root)


def test_catheter_all_files_at_25hz(catheter):
    assert isinstance(catheter, DataSplit)
    train, test = catheter
    assert len(train) == 5 and len(test) == 5
    assert [t.meta["set"] for t in train] == [1] * 5 and [t.meta["set"] for t in test] == [2] * 5
    assert [t.meta["frequency_hz"] for t in train] == [0.1, 0.2, 0.3, 0.4, 0.5]
    for traj in [*train, *test]:
        np.testing.assert_allclose(np.diff(traj.time), 0.04, atol=1e-9)
        assert traj.meta["rate_hz"] == 25.0
        assert traj.input_name == "Tendon Disp." and traj.input_unit == "mm"
        assert traj.output_name == "Angle x" and traj.output_unit == "deg"
        assert 29.0 < traj.y.min() and traj.y.max() < 96.0 and np.ptp(traj.y) > 40.0
        assert -0.1 < traj.u.min() and traj.u.max() < 6.0 and np.ptp(traj.u) > 5.0
        assert traj.source == traj.meta["file"]
    assert train[0].duration == pytest.approx(70.0, abs=0.1)


def test_catheter_motor_current_input(root):
    train, _ = load_preset("catheter_2023", input="Motor Curr.", root=root)
    traj = train[0]
    assert traj.input_name == "Motor Curr."
    assert traj.output_name == "Angle x" and "Tendon Disp." in traj.extra
    assert np.ptp(traj.u) > 200.0  # raw motor-current units, about 0 to 270
    # current follows tension (friction, spikes), so it tracks displacement only loosely
    assert np.corrcoef(traj.u, traj.extra["Tendon Disp."])[0, 1] > 0.5


def test_niti_angle_grows_with_tension(root):
    train, test = load_preset("niti_frequency_trials", root=root)
    assert train.names == ("f001_data_2.mat", "f002_data_2.mat", "f010_data.mat", "f020_data.mat", "f030_data.mat")
    assert test.names == ("f015_data.mat", "f015_data_2.mat", "Random_data.mat")
    for traj in [*train, *test]:
        np.testing.assert_allclose(np.diff(traj.time), 0.04, atol=1e-9)
        assert traj.time[0] == 0.0
        assert traj.input_name == "Tension" and traj.output_unit == "deg"
        assert np.corrcoef(traj.u, traj.y)[0, 1] > 0.8
        assert -5.0 < traj.y.min() and 60.0 < traj.y.max() < 100.0
    assert train[0].meta["frequency_hz"] == 0.01 and test[-1].meta["frequency_hz"] is None


def test_niti_stroke_raw(root):
    train, _ = load_preset("niti_frequency_trials", rate_hz=None, input="Stroke", root=root)
    assert train[2].meta["file"] == "f010_data.mat" and train[2].n == 726
    assert np.corrcoef(train[2].u, train[2].y)[0, 1] > 0.9


def test_unknown_preset_and_input(root):
    with pytest.raises(DataError, match=r"unknown preset 'nope'. Must be one of \['catheter_2023', 'niti_frequency_trials', 'boucwen_benchmark', 'catheter_2023:reverse'"):
        load_preset("nope")
    with pytest.raises(DataError, match=r"no input 'Force'. Must be one of \['Tension', 'Stroke', 'Stroke_Ref'\]"):
        load_preset("niti_frequency_trials", input="Force", root=root)


def test_data_root_env(monkeypatch, tmp_path):
    monkeypatch.setenv("HYST_DATA_DIR", str(tmp_path))
    assert data_root() == tmp_path
    # an empty $HYST_DATA_DIR is where the data set is downloaded to; with no network, the error says
    # where to put the files by hand (the source points at a closed local port: no real download here)
    from dataclasses import replace

    from physics.data import _fetch

    closed = replace(_fetch.SOURCES["catheter_2023"], base_url="http://127.0.0.1:9/none")
    monkeypatch.setitem(_fetch.SOURCES, "catheter_2023", closed)
    with pytest.raises(DataNotFoundError, match=r"Put its files \(data_1_1.txt, .*\) in .*catheter_2023 by hand"):
        load_preset("catheter_2023")
    monkeypatch.setenv("HYST_DATA_DIR", str(tmp_path / "absent"))
    with pytest.raises(DataNotFoundError, match="HYST_DATA_DIR is set to"):
        data_root()
    with pytest.raises(FileNotFoundError):
        data_root()
