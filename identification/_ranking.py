"""What ranks physics specs to try in order: the :class:`Ranking` protocol (``Selection`` declares it)."""

from __future__ import annotations

from typing import Protocol, runtime_checkable

__all__ = ["Ranking"]


@runtime_checkable
class Ranking(Protocol):
    """Specs ranked best first, with the parameters fitted on subsets of the runs that start each spec's fit.

    :class:`~identification.discovery.Selection` declares it; :func:`~identification.fitted_series`
    and :func:`~identification.fit_physics` try ``ranked()`` in order, each spec's fit started also
    from its ``fold_parameters`` (spec -> parameter sets).
    """

    fold_parameters: dict[str, list[dict[str, float]]]

    def ranked(self) -> list[str]:
        """The specs, best first: the order in which to try fitting them on all runs."""
        ...
