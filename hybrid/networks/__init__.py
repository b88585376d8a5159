"""Network specs for learned and residual models: FNN, FNN-HIB and LSTM.

A spec holds settings only and never imports torch until ``build`` is called.

>>> from hybrid.networks import make_network
>>> make_network("fnn-hib", buffer=20)
FNNHIBNet(buffer=20, hidden=(64, 64), pad='edge')
"""

from __future__ import annotations

from typing import Any

from physics.data import DataError
from ._base import AbstractNetwork
from ._fnn import FNNHIBNet, FNNNet
from ._lstm import LSTMNet

NETWORKS: dict[str, type[AbstractNetwork]] = {"fnn": FNNNet, "fnn-hib": FNNHIBNet, "lstm": LSTMNet}


def make_network(name: str, **settings: Any) -> AbstractNetwork:
    """Build a spec by registry name (``"fnn"``, ``"fnn-hib"``, ``"lstm"``)."""
    if name not in NETWORKS:
        raise DataError(f"unknown network {name!r}. Must be one of {list(NETWORKS)}.")
    return NETWORKS[name](**settings)


def network_from_dict(state: dict[str, Any]) -> AbstractNetwork:
    """Rebuild a spec from :meth:`AbstractNetwork.to_dict` output."""
    settings = dict(state)
    name = settings.pop("name", None)
    if "hidden" in settings and isinstance(settings["hidden"], list):
        settings["hidden"] = tuple(settings["hidden"])
    return make_network(name, **settings)


__all__ = ["AbstractNetwork", "FNNNet", "FNNHIBNet", "LSTMNet", "NETWORKS", "make_network", "network_from_dict"]
