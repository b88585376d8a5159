"""When discovery keeps a block, stops, and fits look-alikes: :class:`DiscoveryThresholds`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["DiscoveryThresholds"]


@dataclass(frozen=True)
class DiscoveryThresholds:
    """The thresholds of :func:`~identification.discovery.discover`'s tests, in one object.

    The search's budget (``max_steps``, ``max_tries``) and its data (``holdout``, ``working_rate_hz``)
    stay arguments of ``discover``; these four numbers say how much evidence each decision needs.

    Parameters
    ----------
    margin : float
        A block is kept only if it closes more than this share of the gap between the held-out
        RMSE and the noise floor, and if the drop in mean square error is more than ``z`` standard
        errors of what the noise alone could do: ``z * 2 sigma rms(dy) / sqrt(n)``, with ``dy`` the
        change of the simulated output on the ``n`` held-out samples.
    z : float
        Standard errors the drop must exceed (see ``margin``).
    floor_tolerance : float
        Stop when the held-out RMSE is within this fraction above the noise floor and the held-out
        residual is white (no autocorrelation at lags 1-10 above ``4 / sqrt(n)``).
    ambiguity : float
        Candidates of one family whose diagnosis scores are within this share of each other are all
        fitted, and the best held-out one is kept.

    Examples
    --------
    >>> from identification.discovery import DiscoveryThresholds
    >>> DiscoveryThresholds(margin=0.3).z
    2.0
    """

    margin: float = 0.2
    z: float = 2.0
    floor_tolerance: float = 0.05
    ambiguity: float = 0.85

    def __post_init__(self) -> None:
        for name, low, high in (("margin", 0.0, np.inf), ("floor_tolerance", 0.0, np.inf), ("ambiguity", 0.0, 1.0),
                                ("z", 0.0, np.inf)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)) \
                    or not low <= value <= high or np.isnan(value):
                bound = f"in [{low:g}, {high:g}]" if np.isfinite(high) else f">= {low:g}"
                raise ValueError(f"The '{name}' of DiscoveryThresholds must be a number {bound}. Got {value!r} instead.")
