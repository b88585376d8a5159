"""Exceptions raised by :mod:`hybrid.data`."""

from __future__ import annotations

__all__ = ["DataError", "DataNotFoundError", "NotFittedError"]


class DataError(ValueError):
    """Bad input data: the message says what was wrong, where, and how to fix it."""


class DataNotFoundError(DataError, FileNotFoundError):
    """The shared data folder (or a file inside it) does not exist."""


class NotFittedError(DataError, AttributeError):
    """An estimator was used before ``fit`` was called."""
