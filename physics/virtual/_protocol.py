"""The seed paper's data-collection protocol, run on a virtual catheter."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

from ._catheter import VirtualCatheter
from ._signals import BASELINES, DecayingSinusoid

if TYPE_CHECKING:
    from physics.data import DataSplit

#: Training and test frequencies (Hz) of the seed paper.
TRAIN_FREQUENCIES = (0.1, 0.2, 0.3, 0.4, 0.5)
TEST_FREQUENCIES = (0.15, 0.45)


def paper_protocol(catheter: VirtualCatheter | None = None,
                   frequencies: Sequence[float] = TRAIN_FREQUENCIES,
                   tests: Sequence[float] = TEST_FREQUENCIES,
                   baselines: Sequence[str] = tuple(BASELINES),
                   q_max_mm: float = 3.0) -> DataSplit:
    """The seed paper's protocol: decaying sinusoids (7 cycles) at each frequency and baseline.

    Training runs are named ``'train_f0.10_mid'``, test runs ``'test_f0.15_end'``;
    each carries ``meta['frequency_hz']`` and ``meta['baseline']``. With the
    defaults: 15 training and 6 test trajectories.

    Parameters
    ----------
    catheter : VirtualCatheter, optional
        Default ``VirtualCatheter()`` (lag, hysteresis and backlash; seed 0).
    frequencies, tests : sequence of float
        Training and test frequencies (Hz).
    baselines : sequence of {'zero', 'mid', 'end'}
    q_max_mm : float, default 3.0
        Amplitude of the sinusoids (the paper's 3 mm).

    Returns
    -------
    DataSplit
        ``(train, test)`` datasets.

    Examples
    --------
    >>> split = paper_protocol(frequencies=(0.5,), tests=(0.45,), baselines=("mid",))
    >>> split.train.names, split.test.names
    (('train_f0.50_mid',), ('test_f0.45_mid',))
    """
    from physics.data import Dataset, DataSplit

    catheter = VirtualCatheter() if catheter is None else catheter
    for b in baselines:
        if b not in BASELINES:
            raise ValueError(f"Unknown baseline '{b}'. Must be one of: {', '.join(BASELINES)}.")

    def runs(prefix: str, freqs: Sequence[float]) -> Dataset:
        return Dataset(
            catheter.run(DecayingSinusoid(frequency_hz=float(f), baseline=b, q_max_mm=q_max_mm),
                         name=f"{prefix}_f{float(f):.2f}_{b}")
            for f in freqs for b in baselines
        )

    return DataSplit(runs("train", frequencies), runs("test", tests))
