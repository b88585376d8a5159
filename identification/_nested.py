"""Nested models: a simpler fitted model as a point of a richer model's parameter space.

A model ``simple`` is nested in ``model`` when ``model``'s blocks are ``simple``'s (in the same
order, with the same structural settings) plus blocks that can pass their input through
(each block's declared ``identity`` values). Setting those blocks to their identity and copying
``simple``'s parameters gives a point of ``model`` that simulates as ``simple`` does: a fit of
``model`` can start there, and should never end worse than it.

A block without identity values is never left out: a ``delay`` of one sample is a fixed
shift, not a parameter that can be zero, so ``delay+backlash+linear`` does not contain
``backlash+linear``.
"""

from __future__ import annotations

import numpy as np

from physics import BLOCKS, Series

from ._errors import IdentificationError

__all__ = ["is_nested", "embed"]


def is_nested(simple: str, spec: str) -> bool:
    """``simple`` is a proper simpler spec of ``spec``: its blocks a subsequence of ``spec``'s, and
    each block of ``spec`` it lacks has identity values.

    >>> is_nested("backlash+linear", "lag+backlash+linear"), is_nested("backlash+linear", "delay+backlash+linear")
    (True, False)
    """
    a, b = simple.split("+"), spec.split("+")
    return len(a) < len(b) and _match(a, b) is not None


def _match(small: list[str], big: list[str]) -> list[int | None] | None:
    """For each name of ``big``, the index of the same block in ``small`` or None (an extra block
    that must have an identity); None when ``small`` is not nested in ``big``."""
    out, i = [], 0
    for name in big:
        if i < len(small) and small[i] == name:
            out.append(i)
            i += 1
        elif name in BLOCKS and BLOCKS[name]().identity is not None:  # some set it per instance
            out.append(None)
        else:
            return None
    return out if i == len(small) else None


def _settings(block) -> dict:
    # settings a fit resolves from the data (None until then) do not decide the structure
    return {k: v for k, v in block.get_settings().items() if v is not None}


def embed(model: Series, simple: Series) -> np.ndarray:
    """``model``'s parameter vector that simulates as the fitted ``simple``: ``simple``'s values for
    its blocks, the identity for the others (their remaining parameters keep ``model``'s values).

    Raises
    ------
    IdentificationError
        ``simple`` is not nested in ``model`` (another order, a block it lacks without identity
        values, or a block whose structural settings differ, such as a delay's length).
    """
    names = [b.name for b in model.blocks]
    match = _match([b.name for b in simple.blocks], names)
    if match is None:
        raise IdentificationError(f"'{simple.spec}' is not nested in '{model.spec}': the richer spec must "
                                  "hold its blocks in the same order, plus blocks that can pass their "
                                  "input through (a delay cannot).")
    values: list[float] = []
    for block, j in zip(model.blocks, match):
        own = dict(zip((p.name for p in block.parameters), block.param_values()))
        if j is None:
            own.update(block.identity)
        else:
            other = simple.blocks[j]
            mine, theirs = _settings(block), _settings(other)
            clash = {k for k in mine.keys() & theirs.keys() if mine[k] != theirs[k]}
            if clash or block.n_p != other.n_p:
                raise IdentificationError(
                    f"'{simple.spec}' is not nested in '{model.spec}': block '{block.name}' differs in "
                    f"{sorted(clash) or 'its parameters'} ({ {k: theirs.get(k) for k in clash} } vs "
                    f"{ {k: mine.get(k) for k in clash} }).")
            own.update(zip((p.name for p in other.parameters), other.param_values()))
        values += [float(own[p.name]) for p in block.parameters]
    return np.array(values, dtype=float)
