"""Block names for model specs such as ``"lag+boucwen+linear"``."""

from __future__ import annotations

from ._backlash import Backlash
from ._boucwen import BoucWen
from ._delay import Delay
from ._drift import Drift
from ._errors import PhysicsError
from ._lag import Lag
from ._linear import LinearMap
from ._poly import Poly
from ._preisach import Preisach

BLOCKS = {
    cls.name: cls
    for cls in (Lag, Delay, Backlash, BoucWen, Preisach, Poly, LinearMap, Drift)
}


def make_block(name: str, **settings):
    """A block from its spec name, e.g. ``make_block("lag")``."""
    key = name.strip().lower()
    if key not in BLOCKS:
        raise PhysicsError(
            f"Unknown block '{name}'. Must be one of: {', '.join(sorted(BLOCKS))}."
        )
    return BLOCKS[key](**settings)
