"""The chain of a model of several outputs, chosen on runs left out of the fit."""

from __future__ import annotations

from dataclasses import replace

from .._outputs import output_columns
from ._select import select_physics

__all__ = ["select_outputs_chain", "select_outputs"]


def select_outputs_chain(trajectories, outputs, warmup: int = 0, **options) -> str:
    """The spec :func:`select_physics` chooses for the first of ``outputs`` (what ``hyst fit`` does for one
    output): the chain the others read too, through :func:`~identification.identify_outputs`, whose spec's
    last ``linear`` becomes a cubic map per output. ``options`` go to :func:`select_physics`."""
    return select_outputs(trajectories, outputs, warmup, **options).spec


def select_outputs(trajectories, outputs, warmup: int = 0, **options):
    """The :class:`~identification.discovery.Selection` behind :func:`select_outputs_chain`: its folds and each
    fold's parameters of the chain fitted without them (on the first output)."""
    runs = list(trajectories)
    first = [replace(t, y=output_columns(t, [outputs[0]])[:, 0], output_name=outputs[0], extra={}) for t in runs]
    return select_physics(first, warmup=warmup, **options)
