"""What a block declares about itself besides its equations, as one frozen object: :class:`BlockTraits`.

A block class declares its traits as class attributes (``rank = 3``, ``effect = "hysteresis"``), the
syntax a new block is written in. :attr:`AbstractBlock.traits` gathers them into a frozen
:class:`BlockTraits`. The four traits that may follow a block's structural settings (its
``parameters``, ``identity``, ``continuous_states`` and ``smooth_in_input``: a Preisach plane's relay
weights, a sharp backlash) are set once, at construction, as the instance's whole ``traits`` object
(:meth:`BlockTraits.of` with the changes); an instance never writes a class-level flag.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import Any, Mapping


@dataclass(frozen=True)
class BlockTraits:
    """A block's declared facts (see :class:`~physics.AbstractBlock` for each one's meaning).

    Not among them: the block's ``signature`` (how discovery recognises its effect: functions of the
    class, which a traits object carried by every instance would have to pickle).
    """

    parameters: tuple[Any, ...] = ()  # of physics.Parameter
    smooth_in_input: bool = True
    effect: str | None = None
    aliases: tuple[str, ...] = ()
    rank: int | None = None
    affine_output: tuple[str, str] | None = None
    takes_loop_width: bool = False
    starts: int = 1
    searched_setting: str | None = None
    unit_static_gain: bool = False
    closes_minor_loops: bool = True
    pure_delay: bool = False
    identity: Mapping[str, float] | None = None
    continuous_states: tuple[str, ...] | None = ()
    selectable: bool = True
    selection_order: float = float("inf")
    refines: tuple[str, ...] = ()
    holds_effects: tuple[str, ...] = ()

    @classmethod
    def of(cls, block: type, **changes: Any) -> BlockTraits:
        """The traits ``block`` (a class) declares, with ``changes`` (the instance's own, at construction)."""
        unknown = sorted(set(changes) - set(NAMES))
        if unknown:
            raise TypeError(f"{block.__name__}: no trait(s) {unknown}; the traits are: {', '.join(NAMES)}.")
        return replace(cls(**{name: getattr(block, name) for name in NAMES}), **changes)


#: The names of the traits, in declaration order.
NAMES = tuple(f.name for f in fields(BlockTraits))
#: The traits an instance may set at construction (they follow its structural settings).
STRUCTURAL = ("parameters", "identity", "continuous_states", "smooth_in_input")


class _Structural:
    """A trait that may follow the structural settings: read from the instance's ``traits`` when it set
    its own at construction, else the class's declaration (``default`` on the base class)."""

    def __init__(self, default: Any):
        self.default = default

    def __set_name__(self, owner, name: str) -> None:
        self.name = name

    def __get__(self, obj, owner=None):
        if obj is None:
            return self.default
        own = obj.__dict__.get("traits")
        return self.default if own is None else getattr(own, self.name)

    def __set__(self, obj, value) -> None:
        raise AttributeError(f"{type(obj).__name__}.{self.name} is a trait: set it at construction with "
                             f"self.traits = BlockTraits.of(type(self), {self.name}=...).")


class _Traits:
    """``block.traits``: the instance's own (set at construction) or the class's declarations, frozen."""

    def __get__(self, obj, owner=None) -> BlockTraits:
        return BlockTraits.of(owner if obj is None else type(obj))
