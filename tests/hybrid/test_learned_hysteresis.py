"""The seed paper's central finding on the virtual catheter: with hysteresis the memoryless FNN's
error is at least twice that of the FNN-HIB and the LSTM; without hysteresis it is not."""

import numpy as np
import pytest

from hybrid import FNNHIBNet, FNNNet, LearnedModel, LSTMNet, TrainingSettings
from physics.data import rmse
from physics.virtual import CatheterTruth, VirtualCatheter, paper_protocol

FREQS, TESTS = (0.2, 0.4), (0.15, 0.45)


def _data(effects, **params):
    return paper_protocol(VirtualCatheter(effects, seed=0, truth=CatheterTruth(**params)), frequencies=FREQS,
                          tests=TESTS)


def _pooled_rmse(model, tests):
    return rmse(np.concatenate([t.y for t in tests]), np.concatenate([model.predict(t) for t in tests]))


def _errors(split, lstm_epochs, lstm_stride):
    common = TrainingSettings(progress=False, threads=1, seed=0)
    fits = {
        "fnn": LearnedModel(FNNNet(), training=common.replace(epochs=10, stride=2)),
        "fnn-hib": LearnedModel(FNNHIBNet(buffer=50), training=common.replace(epochs=15, stride=1)),
        "lstm": LearnedModel(LSTMNet(hidden=64, layers=2, seq_len=50),
                             training=common.replace(epochs=lstm_epochs, stride=lstm_stride)),
    }
    return {name: _pooled_rmse(m.fit(split.train), split.test) for name, m in fits.items()}


@pytest.mark.slow
def test_with_hysteresis_fnn_error_is_at_least_twice_the_memory_models():
    # lag + Bouc-Wen with |z| up to 0.8 mm (beta 0.75, gamma 0.5): a clear loop, and a budget the
    # LSTM (slowest to train) can meet in about a minute on 2 cores: FNN 2.84, FNN-HIB 0.76, LSTM 1.33 deg.
    err = _errors(_data("lag,hysteresis", boucwen_beta=0.75, boucwen_gamma=0.5), lstm_epochs=20, lstm_stride=1)
    assert err["fnn"] >= 2 * err["fnn-hib"], err
    assert err["fnn"] >= 2 * err["lstm"], err


def test_without_hysteresis_fnn_is_not_twice_as_bad():
    # a static nonlinearity only: the FNN fits it down to the noise; the memory models gain nothing.
    err = _errors(_data("nonlinearity"), lstm_epochs=3, lstm_stride=4)
    assert err["fnn"] < 2 * err["fnn-hib"] and err["fnn"] < 2 * err["lstm"], err
    assert err["fnn"] < 0.3  # noise floor 0.15 deg
