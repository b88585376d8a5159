"""Data are read at the rate they were recorded at unless a rate is given (kHz stays kHz)."""

import json

import numpy as np
import pytest

from hybrid.cli import main
from hybrid.experiments._datasets import load_data
from physics.data import Trajectory, load_csvs, raw_rate


def _jittered_run(path, rate_hz, seconds, seed):
    """A run sampled at about ``rate_hz`` with +-30 % jitter on every step: y = 2 u + 1."""
    rng = np.random.default_rng(seed)
    steps = rng.uniform(0.7, 1.3, int(seconds * rate_hz)) / rate_hz
    t = np.concatenate([[0.0], np.cumsum(steps)])
    u = 150.0 * np.sin(2 * np.pi * 5.0 * t)
    Trajectory(t, u, 2.0 * u + 1.0).to_csv(path)
    return path


def test_the_raw_rate_is_the_pooled_median_step():
    rng = np.random.default_rng(0)
    runs = [np.cumsum(rng.uniform(0.7e-3, 1.3e-3, n)) for n in (300, 3000)]
    assert raw_rate(runs) == pytest.approx(1000.0, rel=0.01)
    assert raw_rate([np.arange(0, 2, 0.04)]) == 25.0
    with pytest.raises(Exception, match="never increase"):
        raw_rate([np.zeros(5)])


def test_every_run_of_a_data_set_gets_one_uniform_rate(tmp_path):
    paths = [_jittered_run(tmp_path / f"r{i}.csv", 1000.0, s, i) for i, s in enumerate((0.3, 2.0))]
    runs = load_csvs(paths)
    rates = {r.meta["rate_hz"] for r in runs}
    assert len(rates) == 1 and rates.pop() == pytest.approx(1000.0, rel=0.01)
    for r in runs:
        np.testing.assert_allclose(np.diff(r.time), 1.0 / r.meta["rate_hz"], rtol=1e-9)
        np.testing.assert_allclose(r.y, 2.0 * r.u + 1.0, atol=0.02 * 150)  # interpolation, not aliasing
    assert load_csvs(paths, rate_hz=25.0)[0].meta["rate_hz"] == 25.0


def test_identify_fits_kHz_data_at_its_own_rate_and_tests_at_the_same(tmp_path):
    train = _jittered_run(tmp_path / "train.csv", 1000.0, 1.0, 1)
    test = _jittered_run(tmp_path / "test.csv", 990.0, 0.5, 2)
    out = tmp_path / "fit.json"
    assert main(["identify", str(train), "--model", "linear", "--test", str(test), "--out", str(out)]) == 0
    fit = json.loads(out.read_text())
    assert fit["dt"] == pytest.approx(1e-3, rel=0.01)
    assert fit["parameters"]["linear.gain"] == pytest.approx(2.0, rel=1e-3)
    assert fit["test_rmse"] < 0.05 * 150


def test_a_folder_without_a_manifest_is_read_at_its_files_rate(tmp_path):
    for part, seed in (("train", 0), ("test", 1)):
        (tmp_path / part).mkdir()
        _jittered_run(tmp_path / part / "run.csv", 1000.0, 0.5, seed)
    split = load_data(tmp_path)
    rates = {t.meta["rate_hz"] for t in (*split.train, *split.test)}
    assert len(rates) == 1 and rates.pop() == pytest.approx(1000.0, rel=0.03)  # median of 1000 jittered steps
    (tmp_path / "manifest.json").write_text(json.dumps({"rate_hz": 250.0}))
    assert load_data(tmp_path).train[0].meta["rate_hz"] == 250.0
