"""The seed paper's protocol on the virtual catheter."""

import numpy as np
import pytest

from physics.virtual import VirtualCatheter, paper_protocol


def test_paper_protocol_has_the_papers_runs():
    split = paper_protocol()
    assert len(split.train) == 15 and len(split.test) == 6
    assert "train_f0.10_mid" in split.train.names and "test_f0.45_end" in split.test.names
    for tr in split.test:
        assert tr.meta["frequency_hz"] in (0.15, 0.45) and tr.meta["baseline"] in ("zero", "mid", "end")
        assert tr.duration == pytest.approx(7 / tr.meta["frequency_hz"], abs=0.04)
    # independent noise between runs of equal length
    a, b = split.train[0], split.train[1]
    assert abs(np.corrcoef(a.y - a.extra["y_true"], b.y - b.extra["y_true"])[0, 1]) < 0.15


def test_paper_protocol_subsets_and_bad_baseline():
    split = paper_protocol(VirtualCatheter(seed=2), frequencies=(0.5,), tests=(), baselines=("end",))
    assert split.train.names == ("train_f0.50_end",) and len(split.test) == 0
    with pytest.raises(ValueError, match="zero, mid, end"):
        paper_protocol(frequencies=(0.5,), baselines=("top",))
