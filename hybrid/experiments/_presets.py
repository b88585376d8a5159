"""The training budgets of the experiments, one table: preset name -> :class:`Budget`.

A preset names a budget ("quick", "paper"; "tiny" for the tests). ``hyst fit``, ``hyst compare``,
``hyst reproduce`` and the benchmarks read their training settings here and nowhere else. A
budget's network settings (:class:`TrainingSettings`) hold for any registered network, so a
network added to :data:`hybrid.networks.NETWORKS` runs in every experiment without a line here; a
network that needs other settings (the paper's LSTM trains on fewer windows in the quick preset)
gets its own changes.

"quick" spends two network budgets on purpose: ``hyst reproduce`` trains Table I's six models
(40 epochs, patience 8: under 3 minutes on 2 cores), ``hyst fit`` and ``hyst compare`` train the
learned and residual networks of every direction and training set (30 epochs, patience 6; the
LSTM 20: a comparison in about 10 minutes). "paper" is the seed paper's 500 epochs on every
window for both.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from hybrid.learning._settings import TrainingSettings
from physics.data import DataError

__all__ = ["PAPER_NETWORKS", "NetworkBudget", "Budget", "BUDGETS", "check_preset", "folder_network", "folder_training"]

#: The seed paper's three networks, in its order: Table I's rows and what the experiments train by default.
PAPER_NETWORKS = ("fnn", "fnn-hib", "lstm")
#: Presets kept for the tests; not offered in messages.
TEST_ONLY = ("tiny",)


@dataclass(frozen=True)
class NetworkBudget:
    """The training settings of every network (``common``), changed for some by ``per_network[name]``."""

    common: TrainingSettings
    per_network: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)

    def for_network(self, name: str, **changes: Any) -> TrainingSettings:
        """The settings network ``name`` trains with, with ``changes`` (a seed, a progress bar) on top."""
        return self.common.replace(**{**self.per_network.get(name, {}), **changes})


@dataclass(frozen=True)
class Budget:
    """What one preset spends on training, per experiment.

    Attributes
    ----------
    networks : NetworkBudget
        ``hyst fit`` and ``hyst compare``: the learned networks and the hybrids' residuals.
    table : NetworkBudget
        ``hyst reproduce`` (the seed paper's Table I).
    ode : mapping
        ``NeuralODEHybrid`` settings of ``hyst compare`` (epochs, segment length, batch size).
    peers : mapping
        Settings of the peers ``hyst compare`` scores (the SUBNET's iterations).
    inverse : mapping
        ``ModelInverse`` horizon of ``hyst compare`` (``window``, ``commit`` samples).
    extra_directions : tuple of str
        The directions ``hyst compare``'s extra trainings (ood_baseline, data_1/3) run in.
    ode_extra : bool
        Whether those extra trainings fit the neural ODE too.
    """

    networks: NetworkBudget
    table: NetworkBudget
    ode: Mapping[str, Any]
    peers: Mapping[str, Mapping[str, Any]]
    inverse: Mapping[str, int]
    extra_directions: tuple[str, ...]
    ode_extra: bool


#: The paper's budget: 500 epochs on every window, one torch thread.
_PAPER = NetworkBudget(TrainingSettings(epochs=500, stride=1, threads=1))

#: Every preset's budget. Read it; a changed number changes every experiment that runs the preset.
BUDGETS: dict[str, Budget] = {
    "quick": Budget(
        networks=NetworkBudget(TrainingSettings(epochs=30, stride=2, validation=0.1, patience=6, threads=1),
                               {"lstm": dict(epochs=20, stride=6, patience=5)}),
        table=NetworkBudget(TrainingSettings(epochs=40, stride=2, validation=0.1, patience=8, threads=1),
                            {"lstm": dict(stride=4, patience=10)}),
        ode=dict(epochs=3, segment_len=50, batch_size=16),
        peers={"subnet": dict(iterations=1000)},
        inverse=dict(window=20, commit=10), extra_directions=("forward",), ode_extra=False),
    "paper": Budget(
        networks=_PAPER, table=_PAPER,
        ode=dict(epochs=100, segment_len=50, batch_size=16),
        peers={"subnet": dict(iterations=3000)},
        inverse=dict(window=50, commit=25), extra_directions=("forward", "inverse"), ode_extra=True),
    "tiny": Budget(
        networks=NetworkBudget(TrainingSettings(epochs=1, stride=10, threads=1)),
        table=NetworkBudget(TrainingSettings(epochs=2, stride=5, threads=1), {"lstm": dict(stride=20)}),
        ode=dict(epochs=1, segment_len=25, batch_size=64),
        peers={"subnet": dict(iterations=30, batch_size=32)},
        inverse=dict(window=10, commit=10), extra_directions=("forward",), ode_extra=False),
}


def check_preset(preset: str, presets: Mapping[str, Any] = BUDGETS) -> None:
    """Reject a preset that is not in ``presets``, listing the ones a user may choose."""
    if preset not in presets:
        raise DataError(f"unknown preset {preset!r}. Must be one of {[p for p in presets if p not in TEST_ONLY]}.")


def folder_network(name: str):
    """The network ``name`` as a model folder's fit trains it: a controller steps the model, so a recurrent
    network carries its state (one cell step per sample)."""
    from hybrid.networks import make_network

    return make_network(name).for_control()


def folder_training(name: str, networks: tuple):
    """The TrainingSettings network ``name`` trains with in a folder's fit (``networks``: preset, seed, device)."""
    preset, seed, device = networks
    return BUDGETS[preset].networks.for_network(name, seed=seed, progress=False, threads=1, device=device)
