"""Features of an input path and the exact residual shapes of the blocks a model may miss.

Each block declares its own shapes beside its equations (``physics/_lag.py``,
``_delay.py``, ``_backlash.py``, ``_boucwen.py``: its
:class:`physics.Signature`); they are gathered here under their old names and
checked against the blocks' CasADi steps in ``tests/test_discover_signatures.py``.
"""

from __future__ import annotations

from physics._backlash import backlash_shapes
from physics._boucwen import boucwen_shapes
from physics._delay import delay_shapes
from physics._lag import lag_shapes
from physics._signature import direction, since_reversal

__all__ = ["direction", "since_reversal", "lag_shapes", "delay_shapes", "backlash_shapes", "boucwen_shapes"]
