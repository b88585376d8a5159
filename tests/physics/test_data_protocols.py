"""Named real-data protocols (skipped with a message when the shared data folder is absent)."""

import numpy as np
import pytest

from hybrid.experiments._datasets import compare_data, load_data
from physics.data import DataError, data_names, load_preset


def _files(ds):
    return [t.meta["file"] for t in ds]


def test_every_protocol_is_a_data_name():
    assert {"catheter_2023", "catheter_2023:reverse", "catheter_2023:interp", "niti_frequency_trials"} <= set(data_names())
    with pytest.raises(DataError, match="catheter_2023:interp"):
        load_preset("catheter_2023:sideways")


def test_catheter_reverse_swaps_the_sets(root):
    train, test = load_preset("catheter_2023:reverse", root=root)
    assert _files(train) == [f"data_2_{f}.txt" for f in range(1, 6)]
    assert _files(test) == [f"data_1_{f}.txt" for f in range(1, 6)]
    forward = load_preset("catheter_2023", root=root)
    np.testing.assert_array_equal(train[0].y, forward.test[0].y)


def test_catheter_interp_holds_out_frequencies_of_both_sets(root):
    train, test = load_preset("catheter_2023:interp", root=root)
    assert _files(train) == [f"data_{s}_{f}.txt" for s in (1, 2) for f in (1, 3, 5)]
    assert _files(test) == [f"data_{s}_{f}.txt" for s in (1, 2) for f in (2, 4)]
    assert sorted({t.meta["frequency_hz"] for t in test}) == [0.2, 0.4]


def test_niti_random_excitation_is_an_out_of_distribution_category(root):
    data = compare_data("niti_frequency_trials")
    assert set(data.tests) == {"id", "ood_random"}
    assert _files(data.tests["ood_random"]) == ["Random_data.mat"]
    assert _files(data.tests["id"]) == ["f015_data.mat", "f015_data_2.mat"]
    assert data.train[0].input_name == "Tension" and data.train[0].output_unit == "deg"
    # the tip angle from the markers: a bending of tens of degrees, monotone in tension on average
    t = data.train[2]
    assert 20.0 < np.ptp(t.y) < 120.0 and np.corrcoef(t.u, t.y)[0, 1] > 0.8


def test_compare_data_names_each_protocol(root):
    for name in ("catheter_2023", "catheter_2023:reverse", "catheter_2023:interp"):
        data = compare_data(name)
        assert data.name == name and set(data.tests) == {"id"}
        assert len(data.train) + len(data.tests["id"]) == 10
    assert len(load_data("catheter_2023:interp").train) == 6


def test_unknown_data_lists_the_names(tmp_path):
    with pytest.raises(DataError, match="niti_frequency_trials"):
        load_data(str(tmp_path / "nowhere"))
