"""Bounded caches of what is costly to build (CasADi functions), by a key; the oldest go first."""

from __future__ import annotations

from collections.abc import Callable, Hashable
from typing import TypeVar

T = TypeVar("T")


def built(cache: dict, key: Hashable, size: int, build: Callable[[], T]) -> T:
    """``cache[key]``, from ``build()`` the first time; once ``cache`` holds ``size`` entries, the oldest
    makes room for a new one."""
    if key not in cache:
        if len(cache) >= size:
            cache.pop(next(iter(cache)))
        cache[key] = build()
    return cache[key]
