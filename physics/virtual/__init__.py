"""A virtual catheter: known physics and noise, for data whose truth is known.

>>> from hybrid.virtual import VirtualCatheter, DecayingSinusoid, paper_protocol
>>> traj = VirtualCatheter(seed=1).run(DecayingSinusoid(0.5, "mid"))
>>> traj.meta["baseline"], traj.output_unit
('mid', 'deg')
"""

from ._catheter import (
    DEFAULT_EFFECTS,
    DEFAULT_TRUTH,
    CatheterTruth,
    EFFECTS,
    INPUTS,
    LAG_TIME_CONSTANT_S,
    TipArc,
    VirtualCatheter,
    lag_for_peak,
    parse_effects,
)
from ._protocol import TEST_FREQUENCIES, TRAIN_FREQUENCIES, paper_protocol
from ._signals import BASELINES, Command, DecayingSinusoid, Multisine, RandomSteps, Signal, sample_times

__all__ = [
    "VirtualCatheter",
    "CatheterTruth",
    "TipArc",
    "DEFAULT_TRUTH",
    "EFFECTS",
    "INPUTS",
    "DEFAULT_EFFECTS",
    "LAG_TIME_CONSTANT_S",
    "lag_for_peak",
    "parse_effects",
    "paper_protocol",
    "TRAIN_FREQUENCIES",
    "TEST_FREQUENCIES",
    "Signal",
    "DecayingSinusoid",
    "Multisine",
    "RandomSteps",
    "Command",
    "BASELINES",
    "sample_times",
]
