"""History windows, LSTM subsequences, min-max scaling and metrics."""

import json

import numpy as np
import pytest

from physics.data import DataError, MinMaxScaler, NotFittedError, history_windows, lstm_subsequences, nrmse, rmse

X = [1.0, 2.0, 3.0, 4.0]


def test_history_windows_hand_built():
    np.testing.assert_array_equal(history_windows(X, 3), [[1, 2, 3], [2, 3, 4]])
    np.testing.assert_array_equal(
        history_windows(X, 3, pad=-1.0), [[-1, -1, 1], [-1, 1, 2], [1, 2, 3], [2, 3, 4]]
    )
    np.testing.assert_array_equal(history_windows(X, 3, pad="edge"), [[1, 1, 1], [1, 1, 2], [1, 2, 3], [2, 3, 4]])
    np.testing.assert_array_equal(history_windows(X, 1), [[1], [2], [3], [4]])


def test_history_windows_row_semantics_and_copy():
    x = np.arange(10.0)
    w = history_windows(x, 4)
    assert w.shape == (7, 4)
    for i, row in enumerate(w):  # row i ends at sample n = i + length - 1, oldest first
        n = i + 3
        np.testing.assert_array_equal(row, x[n - 3 : n + 1])
    w[0, 0] = 99.0
    assert x[0] == 0.0 and w[1, 0] == 1.0  # a real copy, rows independent
    assert w.flags.writeable and w.flags.c_contiguous


def test_history_windows_2d():
    x = np.column_stack([np.arange(5.0), -np.arange(5.0)])
    w = history_windows(x, 2, pad=0.0)
    assert w.shape == (5, 2, 2)
    np.testing.assert_array_equal(w[3], [[2, -2], [3, -3]])
    np.testing.assert_array_equal(w[0], [[0, 0], [0, 0]])


def test_history_windows_errors():
    with pytest.raises(DataError, match="has 4 samples but the history buffer needs 5.*shorter buffer"):
        history_windows(X, 5)
    with pytest.raises(DataError, match="length must be an integer >= 1"):
        history_windows(X, 0)
    with pytest.raises(DataError, match="pad must be None, a number or 'edge'"):
        history_windows(X, 2, pad="zero")
    with pytest.raises(DataError, match="pad must be None, a finite number"):
        history_windows(X, 2, pad=np.nan)


def test_lstm_subsequences_flag_scheme():
    s = lstm_subsequences(X, length=3)
    assert s.shape == (4, 3, 1)
    np.testing.assert_array_equal(s[:, :, 0], history_windows(X, 3, pad=-1.0))
    x = np.linspace(0.0, 1.0, 120)
    s50 = lstm_subsequences(x)
    assert s50.shape == (120, 50, 1)
    assert np.all(s50[0, :49, 0] == -1.0) and s50[0, -1, 0] == x[0]
    np.testing.assert_array_equal(s50[-1, :, 0], x[-50:])
    assert lstm_subsequences(np.ones((7, 2)), length=3, flag=0.0).shape == (7, 3, 2)


def test_scaler_round_trip_and_dict():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(100, 3)) * [1.0, 1e-3, 1e4] + [0.0, 5.0, -7.0]
    s = MinMaxScaler().fit(x)
    assert s.fit(x) is s
    z = s.transform(x)
    np.testing.assert_allclose(z.min(axis=0), 0.0)
    np.testing.assert_allclose(z.max(axis=0), 1.0)
    np.testing.assert_allclose(s.inverse_transform(z), x, rtol=1e-12, atol=1e-9)
    restored = MinMaxScaler.from_dict(json.loads(json.dumps(s.to_dict())))
    np.testing.assert_array_equal(restored.min_, s.min_)
    np.testing.assert_array_equal(restored.max_, s.max_)
    np.testing.assert_array_equal(restored.transform(x), z)


def test_scaler_1d_series():
    s = MinMaxScaler().fit(np.array([2.0, 4.0, 6.0]))
    np.testing.assert_allclose(s.transform(np.array([2.0, 5.0])), [0.0, 0.75])
    assert s.inverse_transform(1.0) == 6.0


def test_scaler_errors():
    with pytest.raises(NotFittedError, match="not fitted yet. Call fit"):
        MinMaxScaler().transform([1.0])
    with pytest.raises(DataError, match=r"column 1 of x is constant \(every value is 3.0\)"):
        MinMaxScaler().fit([[0.0, 3.0], [1.0, 3.0]])
    s = MinMaxScaler().fit(np.ones((2, 2)) * [[0], [1]])
    with pytest.raises(DataError, match="x has 3 column\\(s\\) but the scaler was fitted on 2"):
        s.transform(np.zeros((4, 3)))
    with pytest.raises(DataError, match="'min' and 'max'"):
        MinMaxScaler.from_dict({"min": [0.0]})
    with pytest.raises(DataError, match="constant must be 'raise' or 'keep'"):
        MinMaxScaler(constant="drop")


def test_scaler_keeps_a_constant_column_at_zero_when_asked():
    s = MinMaxScaler(constant="keep").fit([[0.0, -3e-6], [2.0, -3e-6], [1.0, -3e-6]])
    np.testing.assert_allclose(s.transform([[1.0, -3e-6], [2.0, 1 - 3e-6]]), [[0.5, 0.0], [1.0, 1.0]])
    np.testing.assert_allclose(s.inverse_transform(s.transform([[0.5, 7.0]])), [[0.5, 7.0]])
    big = MinMaxScaler(constant="keep").fit([[1e20], [1e20]])  # a unit span would vanish in rounding
    assert big.max_[0] > big.min_[0] and MinMaxScaler.from_dict(big.to_dict()).max_[0] == big.max_[0]


def test_metrics():
    assert rmse([0.0, 0.0], [3.0, 4.0]) == pytest.approx(np.sqrt(12.5))
    assert nrmse([0.0, 10.0], [1.0, 11.0]) == pytest.approx(0.1)
    with pytest.raises(DataError, match="shape"):
        rmse([1.0, 2.0], [1.0])
    with pytest.raises(DataError, match="y is constant"):
        nrmse([1.0, 1.0], [1.0, 2.0])
