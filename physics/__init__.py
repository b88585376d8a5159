"""Physics blocks written once in CasADi and composed in signal order.

>>> from physics import Series
>>> Series.from_spec("lag+boucwen+linear").param_names[:2]
['lag.time_constant_s', 'boucwen.A']
"""

from ._backlash import Backlash
from ._block import AbstractBlock, Parameter
from ._boucwen import BoucWen
from ._delay import Delay
from ._drift import Drift
from ._errors import PhysicsError
from ._lag import Lag
from ._linear import LinearMap
from ._poly import Poly
from ._preisach import Preisach
from ._registry import BLOCKS, make_block
from ._series import Series
from ._torch import torch_expression, torch_function


def model_from_spec(spec: str, dt: float = 0.04) -> Series:
    """A model from a spec string such as ``"lag+boucwen+linear"``."""
    return Series.from_spec(spec, dt=dt)


__all__ = [
    "AbstractBlock", "Parameter", "PhysicsError", "BLOCKS", "make_block", "model_from_spec",
    "torch_function", "torch_expression", "Series", "Lag", "Delay", "Backlash", "BoucWen", "Preisach", "Poly", "LinearMap", "Drift",
]
