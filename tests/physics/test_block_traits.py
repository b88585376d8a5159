"""A block's traits: declared once by its class, frozen in one object, never written per instance; the
selection's vocabulary is read from them."""

import dataclasses
import pickle

import pytest

from identification.discovery import SELECT_BLOCKS, SELECT_REFINEMENTS
from physics import BLOCKS, Backlash, BlockTraits, Creep, GPI, Preisach, in_signal_order, make_block
from physics._traits import NAMES

#: Blocks built with settings that change their structure (parameters, identity, ODE states, smoothness).
STRUCTURED = [Backlash(smoothing=0.0), Creep(time_constants_s=(1.0, 4.0)), GPI(widths=(0.1, 0.3)), Preisach(levels=3)]


@pytest.mark.parametrize("block", [make_block(n) for n in BLOCKS] + STRUCTURED, ids=lambda b: repr(b)[:40])
def test_an_instance_writes_no_class_flag_and_its_traits_are_frozen(block):
    assert not set(vars(block)) & set(NAMES), sorted(set(vars(block)) & set(NAMES))
    traits = block.traits
    assert isinstance(traits, BlockTraits)
    assert {name: getattr(traits, name) for name in NAMES} == {name: getattr(block, name) for name in NAMES}
    with pytest.raises(dataclasses.FrozenInstanceError):
        traits.rank = 9
    back = pickle.loads(pickle.dumps(block))  # the folds' worker processes receive blocks so
    assert back.traits == traits


def test_structural_settings_set_the_instances_traits_at_construction():
    assert Backlash(smoothing=0.0).smooth_in_input is False and Backlash().smooth_in_input is True
    assert Backlash.smooth_in_input is True  # the class is untouched
    creep = Creep(time_constants_s=(1.0, 4.0))
    assert [p.name for p in creep.parameters] == ["gain_1", "gain_2"]
    assert creep.identity == {"gain_1": 0.0, "gain_2": 0.0} and creep.continuous_states == ("mode_1", "mode_2")
    assert len(Preisach(levels=3).parameters) == 6 and Preisach.parameters == ()
    with pytest.raises(AttributeError, match=r"Creep.parameters is a trait: set it at construction"):
        creep.parameters = ()
    with pytest.raises(TypeError, match=r"no trait\(s\) \['colour'\]"):
        BlockTraits.of(Creep, colour="red")


def test_the_selections_vocabulary_is_the_built_in_blocks_declared_order():
    """The candidates the greedy search tries, in the order it tries them, as the hand-kept lists had them."""
    assert tuple(SELECT_BLOCKS) == ("lag", "backlash", "boucwen", "gpi", "creep", "resonance", "poly")
    assert dict(SELECT_REFINEMENTS) == {"resonance": ("hysteretic_oscillator",)}
    assert in_signal_order(["linear", "poly", "gpi", "backlash", "delay", "lag", "drift"]) == \
        ["lag", "delay", "backlash", "gpi", "poly", "linear", "drift"]
    with pytest.raises(Exception, match="Unknown block 'nope'"):
        in_signal_order(["nope"])
