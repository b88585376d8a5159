"""Presets of the experiments: training settings shared by every network, with per-network changes.

A preset names a budget ("quick", "paper"; "tiny" for the tests). Its training settings
hold for any registered network, so a network added to :data:`hybrid.networks.NETWORKS`
runs in every experiment without a line here; a network that needs other settings (the
paper's LSTM trains on fewer windows in the quick preset) gets its own changes.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from physics.data import DataError

__all__ = ["PAPER_NETWORKS", "NetworkSettings", "check_preset"]

#: The seed paper's three networks, in its order: Table I's rows and what the experiments train by default.
PAPER_NETWORKS = ("fnn", "fnn-hib", "lstm")
#: Presets kept for the tests; not offered in messages.
TEST_ONLY = ("tiny",)


@dataclass(frozen=True)
class NetworkSettings:
    """Training settings of a preset: ``common`` to every network, updated by ``per_network[name]``."""

    common: dict[str, Any]
    per_network: dict[str, dict[str, Any]] = field(default_factory=dict)

    def for_network(self, name: str) -> dict[str, Any]:
        """The settings network ``name`` trains with."""
        return {**self.common, **self.per_network.get(name, {})}


def check_preset(preset: str, presets: Mapping[str, Any]) -> None:
    """Reject a preset that is not in ``presets``, listing the ones a user may choose."""
    if preset not in presets:
        raise DataError(f"unknown preset {preset!r}. Must be one of {[p for p in presets if p not in TEST_ONLY]}.")
