"""Physics blocks written once in CasADi and composed in signal order.

Examples
--------
>>> from physics import Series
>>> Series.from_spec("lag+boucwen+linear").param_names[:2]
['lag.time_constant_s', 'boucwen.A']
"""

from ._arc import Arc, arc_points
from ._backlash import Backlash, backlash_shapes
from ._block import AbstractBlock, DataSummary, Parameter, clip_to_bounds
from ._boucwen import BoucWen, boucwen_shapes
from ._creep import Creep
from ._delay import Delay, delay_shapes
from ._drift import Drift
from ._gpi import GPI
from ._hysteretic_oscillator import HystereticOscillator
from ._errors import PhysicsError
from ._integrate import CLASSIC, THREE_EIGHTHS, Tableau, rk_step
from ._lag import Lag, lag_shapes
from ._linear import LinearMap
from ._output_maps import OutputMaps
from ._poly import Poly
from ._preisach import Preisach
from ._resonance import Resonance
from ._registry import (BLOCKS, EFFECTS, LiveTuple, effect_blocks, effects, in_signal_order, make_block, register_block,
                        resolve_effect, unregister_block)
from ._series import Series
from ._traits import BlockTraits
from ._signature import Estimate, Signature, direction, since_reversal
from ._torch import torch_expression, torch_function


def model_from_spec(spec: str, dt: float = 0.04) -> Series:
    """A model from a spec string such as ``"lag+boucwen+linear"``."""
    return Series.from_spec(spec, dt=dt)


__all__ = [
    "AbstractBlock", "BlockTraits", "Parameter", "DataSummary", "Signature", "Estimate", "PhysicsError", "BLOCKS", "EFFECTS",
    "make_block", "register_block", "unregister_block", "effects", "effect_blocks", "resolve_effect", "in_signal_order", "LiveTuple",
    "clip_to_bounds", "model_from_spec", "rk_step", "Tableau", "CLASSIC", "THREE_EIGHTHS",
    "torch_function", "torch_expression", "Series", "Lag", "Delay", "Backlash", "BoucWen", "Preisach", "Poly", "LinearMap", "Drift", "Creep", "GPI", "Resonance",
    "HystereticOscillator", "OutputMaps", "Arc", "arc_points",
    # discovery's library: each block's response shapes over a grid, and the input's direction
    "lag_shapes", "delay_shapes", "backlash_shapes", "boucwen_shapes", "direction", "since_reversal",
]
