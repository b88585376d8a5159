"""Features of an input path and the exact residual shapes of the blocks a model may miss.

Each block declares its own shapes beside its equations (``physics/_lag.py``,
``_delay.py``, ``_backlash.py``, ``_boucwen.py``: its
:class:`physics.Signature`); they are gathered here under their old names and
checked against the blocks' CasADi steps in ``tests/identification/test_discover_signatures.py``.
"""

from __future__ import annotations

import numpy as np

from physics import backlash_shapes, boucwen_shapes, delay_shapes, direction, lag_shapes, since_reversal

__all__ = ["direction", "since_reversal", "lag_shapes", "delay_shapes", "backlash_shapes", "boucwen_shapes",
           "along", "free_drops"]

#: ``Signature.signal`` -> the attribute of a ``ResidualTrace`` that the shapes run along.
_SIGNAL_ATTR = {"drive": "drive", "hysteresis": "hyst", "static": "static"}


def along(trace, signal: str) -> np.ndarray:
    """The signal of ``trace`` (a ``ResidualTrace``) that a signature's shapes are computed along."""
    return getattr(trace, _SIGNAL_ATTR[signal])


def free_drops(f: np.ndarray, r: np.ndarray, gain: float, positive: bool) -> tuple[np.ndarray, np.ndarray]:
    """Each column of ``f`` at its least-squares coefficient against ``r``: the drop in ``r``'s sum of
    squares and the coefficient (both 0 for a null column, and for a ``positive`` signature's column
    whose coefficient has not the sign of the model's ``gain``)."""
    ff, fr = np.einsum("ij,ij->j", f, f), f.T @ r
    ok = (ff > 1e-18) & ((fr * gain > 0) if positive else True)
    safe = np.where(ok, ff, 1.0)
    return np.where(ok, fr**2 / safe, 0.0), np.where(ok, fr / safe, 0.0)
