"""The abstract network spec: settings, training windows and a torch-module factory.

A spec is a small frozen dataclass holding settings only (no weights). It knows
how to cut a feature matrix of shape (n, n_features) into training windows and
how to build the torch module that learns from them. The module (see
``_modules``) holds the weights and runs the network two ways: batched over a
whole trajectory (``sequence``) and one sample at a time with explicit state
(``initial_state`` / ``step``), the way a controller calls it.
"""

from __future__ import annotations

import abc
import dataclasses
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from physics.data import DataError

__all__ = ["AbstractNetwork"]


class AbstractNetwork(abc.ABC):
    """Base of :class:`FNNNet`, :class:`FNNHIBNet` and :class:`LSTMNet` (never subclass those)."""

    #: Registry name ("fnn", "fnn-hib", "lstm").
    name: ClassVar[str]
    #: Prediction schemes the module supports; the first is the default.
    modes: ClassVar[tuple[str, ...]] = ("window",)

    @property
    @abc.abstractmethod
    def history(self) -> int:
        """Samples of input history one output depends on in training (1 for a plain FNN)."""

    @abc.abstractmethod
    def windows(self, features: NDArray[np.float64]) -> NDArray[np.float32]:
        """Training inputs, one window per sample: shape (n, history, n_features), oldest first."""

    @abc.abstractmethod
    def build(self, n_features: int, n_outputs: int = 1):
        """A fresh torch module for ``n_features`` inputs and ``n_outputs`` outputs."""

    # ---------------------------------------------------------------- shared
    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable settings; :func:`network_from_dict` rebuilds the spec."""
        return {"name": self.name, **dataclasses.asdict(self)}  # type: ignore[call-overload]

    def check_features(self, features: NDArray[np.float64]) -> NDArray[np.float64]:
        arr = np.asarray(features, dtype=np.float64)
        if arr.ndim == 1:
            arr = arr[:, None]
        if arr.ndim != 2 or arr.shape[0] == 0:
            raise DataError(
                f"{type(self).__name__} needs a feature matrix of shape (n, n_features) with n >= 1; "
                f"got shape {arr.shape}."
            )
        if not np.all(np.isfinite(arr)):
            i = int(np.flatnonzero(~np.isfinite(arr).all(axis=1))[0])
            raise DataError(f"features have a non-finite value at sample {i}. Remove or interpolate NaN/inf first.")
        return arr


def check_int(owner: str, name: str, value: object, minimum: int = 1) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise DataError(f"The {name!r} parameter of {owner} must be an integer >= {minimum}. Got {value!r} instead.")
