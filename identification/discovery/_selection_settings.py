"""How a physics selection judges its candidates: :class:`SelectionSettings`."""

from __future__ import annotations

from dataclasses import dataclass
from numbers import Integral, Real

from identification._errors import IdentificationError

__all__ = ["SelectionSettings", "MAX_SAMPLES"]

#: Default most samples the folds' fits see over all runs (``SelectionSettings.max_samples``).
MAX_SAMPLES = 10_000


@dataclass(frozen=True)
class SelectionSettings:
    """The folds a selection scores candidates on, and the margin a richer spec must win by.

    :func:`~identification.discovery.select_physics` takes what is searched (``candidates``, ``start``,
    ``blocks``, ``refinements``, ``peers``) and the protocol (``warmup``) as its own arguments; these
    four numbers say how the evidence is gathered and weighed, the same whatever is searched.

    Parameters
    ----------
    margin : float
        Relative drop of the held-out error a block must bring (0.03: 3 %), pooled over the folds
        (with the paired per-fold tests of ``select_physics``).
    group_by : str, optional
        Runs sharing ``meta[group_by]`` are held out together (a condition: ``"frequency_hz"``,
        ``"baseline"``); default one run per fold.
    max_folds : int
        At most this many folds (groups dealt round-robin).
    max_samples : int or None
        When the runs hold more samples than this, the folds are fitted on the runs resampled to the
        rate that brings them to it (anti-aliased; ``Selection.rate_hz``), never below
        :data:`~identification.discovery._select.RATE_FACTOR` times the inputs' bandwidth and never for a
        spec with a pure delay (its length counts samples). None: always at the runs' own rate.

    Examples
    --------
    >>> from identification.discovery import SelectionSettings
    >>> SelectionSettings(max_folds=3).margin
    0.03
    """

    margin: float = 0.03
    group_by: str | None = None
    max_folds: int = 6
    max_samples: int | None = MAX_SAMPLES

    def __post_init__(self) -> None:
        if isinstance(self.margin, bool) or not isinstance(self.margin, Real) or not 0 <= self.margin < 1:
            raise IdentificationError(f"margin must be in [0, 1). Got {self.margin} instead.")
        if isinstance(self.max_folds, bool) or not isinstance(self.max_folds, Integral) or self.max_folds < 2:
            raise IdentificationError(f"max_folds must be >= 2. Got {self.max_folds} instead.")
        if self.group_by is not None and not (isinstance(self.group_by, str) and self.group_by):
            raise IdentificationError(f"group_by must be a meta key every run carries, or None (one run per fold). "
                                      f"Got {self.group_by!r} instead.")
        m = self.max_samples
        if m is not None and (isinstance(m, bool) or not isinstance(m, Real) or int(m) != m or m < 100):
            raise IdentificationError(f"max_samples must be a whole number of at least 100, or None. Got {m}.")
