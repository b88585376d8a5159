"""Network specs for learned and residual models: FNN, FNN-HIB and LSTM.

A spec holds settings only and never imports torch until its module is built.
Each network is one file (spec, torch module, CasADi step) plus its line in
:data:`NETWORKS`; everything that lists networks reads that registry.

>>> from hybrid.networks import make_network
>>> make_network("fnn-hib", buffer=20)
FNNHIBNet(buffer=20, hidden=(64, 64), pad='edge')
"""

from __future__ import annotations

from typing import Any

from physics import LiveTuple
from physics.data import DataError
from ._base import AbstractNetwork, CasadiStep
from ._fnn import FNNHIBNet, FNNNet
from ._lstm import LSTMNet

#: Registry name -> spec class; read by training, hybrids, export, experiments and the CLI.
NETWORKS: dict[str, type[AbstractNetwork]] = {"fnn": FNNNet, "fnn-hib": FNNHIBNet, "lstm": LSTMNet}


def register_network(cls: type[AbstractNetwork]) -> type[AbstractNetwork]:
    """Add a spec class to :data:`NETWORKS` under its ``name`` (usable as a class decorator)."""
    if not (isinstance(cls, type) and issubclass(cls, AbstractNetwork)):
        raise DataError(f"register_network takes an AbstractNetwork subclass. Got {cls!r} instead.")
    name = getattr(cls, "name", None)
    if not isinstance(name, str) or not name:
        raise DataError(f"{cls.__name__} needs a class attribute 'name' (its registry name).")
    if NETWORKS.get(name, cls) is not cls:
        raise DataError(f"The network name {name!r} is taken by {NETWORKS[name].__name__}; choose another name.")
    NETWORKS[name] = cls
    return cls


def residual_choices() -> tuple[str, ...]:
    """What a model folder's residual may be: ``"auto"``, ``"none"`` and every registered network."""
    return ("auto", "none", *NETWORKS)


def auto_residuals() -> tuple[str, ...]:
    """The registered networks that ``residual="auto"`` compares (each declares ``auto_residual``)."""
    return tuple(name for name, cls in NETWORKS.items() if cls.auto_residual)


#: A residual candidate's suffix for the network alone, the physics ignored (``"lstm alone"``): a hybrid's
#: network sees what the network alone sees plus the physics, but where the physics misleads it held out,
#: ``--residual auto`` keeps the network alone as the model.
ALONE = " alone"

#: :func:`residual_choices`, live: ``("auto", "none", "fnn", "fnn-hib", "lstm", ...)``.
RESIDUALS = LiveTuple(residual_choices)
#: :func:`auto_residuals`, live: ``("fnn-hib", "lstm")`` for the built-in networks.
AUTO_RESIDUALS = LiveTuple(auto_residuals)


def make_network(name: str, **settings: Any) -> AbstractNetwork:
    """Build a spec by registry name (``"fnn"``, ``"fnn-hib"``, ``"lstm"``, ...)."""
    if name not in NETWORKS:
        raise DataError(f"unknown network {name!r}. Must be one of {list(NETWORKS)}.")
    return NETWORKS[name](**settings)


def network_label(name: str) -> str:
    """How tables and figures name a network: its spec's ``label`` ("FNN-HIB"), else ``name`` itself."""
    cls = NETWORKS.get(name)
    return (cls.label if cls is not None else "") or name


def network_from_dict(state: dict[str, Any]) -> AbstractNetwork:
    """Rebuild a spec from :meth:`AbstractNetwork.to_dict` output."""
    settings = dict(state)
    name = settings.pop("name", None)
    if "hidden" in settings and isinstance(settings["hidden"], list):
        settings["hidden"] = tuple(settings["hidden"])
    return make_network(name, **settings)


def network_of(module) -> type[AbstractNetwork] | None:
    """The registered spec class whose torch module ``module`` is (the first one; None if none).

    Imports torch (it asks each spec for its module class).
    """
    for cls in NETWORKS.values():
        if isinstance(module, cls.module_class()):
            return cls
    return None


__all__ = ["AbstractNetwork", "CasadiStep", "FNNNet", "FNNHIBNet", "LSTMNet", "NETWORKS", "make_network",
           "network_from_dict", "network_label", "network_of", "register_network", "RESIDUALS", "AUTO_RESIDUALS", "ALONE",
           "residual_choices", "auto_residuals"]
