"""The block registry: names for model specs such as ``"lag+boucwen+linear"``, and the effect vocabulary.

Everything that needs to know the blocks (specs, discovery, reports, the
virtual catheter, serialization) reads this registry and what each block
declares about itself; a new block is one file plus one
``register_block(MyBlock)`` line.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

from ._arc import Arc
from ._backlash import Backlash
from ._block import AbstractBlock
from ._boucwen import BoucWen
from ._creep import Creep
from ._delay import Delay
from ._drift import Drift
from ._gpi import GPI
from ._hysteretic_oscillator import HystereticOscillator
from ._errors import PhysicsError
from ._lag import Lag
from ._linear import LinearMap
from ._output_maps import OutputMaps
from ._poly import Poly
from ._preisach import Preisach
from ._resonance import Resonance

#: Spec name -> block class, in registration order.
BLOCKS: dict[str, type[AbstractBlock]] = {}


def register_block(cls: type[AbstractBlock]) -> type[AbstractBlock]:
    """Make ``cls`` known by its ``name`` to specs, discovery and serialization (usable as a decorator)."""
    if not (isinstance(cls, type) and issubclass(cls, AbstractBlock)):
        raise PhysicsError(f"register_block takes a subclass of physics.AbstractBlock; got {cls!r}.")
    key = getattr(cls, "name", None)
    if not isinstance(key, str) or not key or key != key.strip().lower() or "+" in key:
        raise PhysicsError(f"{cls.__name__}.name must be a lower-case spec name without '+'; got {key!r}.")
    if key in BLOCKS and BLOCKS[key] is not cls:
        raise PhysicsError(f"A block named '{key}' is already registered ({BLOCKS[key].__name__}); "
                           "choose another name or unregister_block it first.")
    if cls.rank is not None and not isinstance(cls.rank, int):
        raise PhysicsError(f"{cls.__name__}.rank must be a whole number (its place in signal order) or None.")
    if not isinstance(cls.selection_order, (int, float)) or isinstance(cls.selection_order, bool):
        raise PhysicsError(f"{cls.__name__}.selection_order must be a number (lower: tried earlier by the "
                           f"selection); got {cls.selection_order!r}.")
    for trait in ("refines", "holds_effects"):
        value = getattr(cls, trait)
        if not isinstance(value, tuple) or not all(isinstance(v, str) for v in value):
            raise PhysicsError(f"{cls.__name__}.{trait} must be a tuple of names; got {value!r}.")
    BLOCKS[key] = cls
    return cls


def unregister_block(name: str) -> None:
    """Forget a registered block (a test's teardown)."""
    if name not in BLOCKS:
        raise PhysicsError(f"No block named '{name}' is registered.")
    del BLOCKS[name]


for _cls in (Lag, Delay, Backlash, BoucWen, Preisach, Poly, LinearMap, Drift, Creep, GPI, Resonance,
             HystereticOscillator, OutputMaps, Arc):
    register_block(_cls)


def make_block(name: str, **settings):
    """A block from its spec name, e.g. ``make_block("lag")``."""
    key = name.strip().lower()
    if key not in BLOCKS:
        raise PhysicsError(
            f"Unknown block '{name}'. Must be one of: {', '.join(sorted(BLOCKS))}."
        )
    return BLOCKS[key](**settings)


def _in_signal_order() -> list[type[AbstractBlock]]:
    order = {cls: i for i, cls in enumerate(BLOCKS.values())}
    return sorted(BLOCKS.values(), key=lambda c: (math.inf if c.rank is None else c.rank, order[c]))


def in_signal_order(names: Sequence[str]) -> list[str]:
    """Registered block names in signal order: each block's ``rank``, ties in registration order,
    blocks without a rank last."""
    order = {cls.name: i for i, cls in enumerate(_in_signal_order())}
    unknown = [n for n in names if n not in order]
    if unknown:
        raise PhysicsError(f"Unknown block {unknown[0]!r}. Must be one of: {', '.join(sorted(BLOCKS))}.")
    return sorted(names, key=order.__getitem__)


def effects() -> tuple[str, ...]:
    """The effect vocabulary: effects of the registered blocks, in signal order."""
    return tuple(dict.fromkeys(c.effect for c in _in_signal_order() if c.effect))


def effect_blocks(effect: str) -> list[type[AbstractBlock]]:
    """Registered blocks that model ``effect``, in signal order."""
    return [c for c in _in_signal_order() if c.effect == effect]


def resolve_effect(name: str) -> str:
    """The effect named by ``name``: an effect, a block's name or one of its aliases."""
    key = str(name).strip().lower()
    if key in effects():
        return key
    for cls in _in_signal_order():
        if cls.effect and (key == cls.name or key in cls.aliases):
            return cls.effect
    raise PhysicsError(f"Unknown effect {name!r}. Must be among: {', '.join(effects())} "
                       "(or a block's name for its effect).")


class LiveTuple(Sequence):
    """A read-only tuple computed by ``build()`` on each use: a list read from a registry at the
    moment it is needed, so it follows components registered later (:data:`EFFECTS`, the selection's
    blocks, the residual choices)."""

    def __init__(self, build: Callable[[], tuple]):
        self._build = build

    def __getitem__(self, i):
        return self._build()[i]

    def __len__(self) -> int:
        return len(self._build())

    def __eq__(self, other) -> bool:
        return tuple(self) == tuple(other) if isinstance(other, Sequence) else NotImplemented

    __hash__ = None

    def __repr__(self) -> str:
        return repr(self._build())


#: The effect vocabulary (live): ``('actuator_lag', 'time_delay', 'backlash', ...)``.
EFFECTS = LiveTuple(effects)
