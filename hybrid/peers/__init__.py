"""Peers: the models a robotics researcher would otherwise pick, scored beside ours on the same runs.

``LinearARX`` (numpy), ``PolynomialNARX`` (SysIdentPy) and ``SubnetPeer`` (deepSI) share one contract:
``fit(runs)`` and ``predict(data, warmup=...)``, a free run from the state the measured window sets,
so ``score_model`` and ``hyst compare`` score them like our own models. The last two need the optional
extra: ``pip install 'hysteresis-hybrid[peers]'``.
"""

from __future__ import annotations

import importlib.util

from ._arx import LinearARX
from ._base import EXTRA, AbstractPeer
from ._narx import PolynomialNARX
from ._subnet import SubnetPeer

__all__ = ["AbstractPeer", "LinearARX", "PolynomialNARX", "SubnetPeer", "PEERS", "available_peers"]

#: name -> peer class.
PEERS = {"arx": LinearARX, "narx": PolynomialNARX, "subnet": SubnetPeer}
_NEEDS = {"narx": "sysidentpy", "subnet": "deepSI"}


def available_peers() -> dict[str, str | None]:
    """Per peer, None when it can run here, else a one-line note why not."""
    return {name: (None if name not in _NEEDS or importlib.util.find_spec(_NEEDS[name]) is not None
                   else f"{_NEEDS[name]} is not installed: {EXTRA}") for name in PEERS}
