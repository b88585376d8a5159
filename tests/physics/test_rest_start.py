"""A run started from rest at its first input is at a steady state there (issue 53, item 2b): every block."""

import numpy as np
import pytest

from physics import BLOCKS, LinearMap, Series, make_block

#: (first input, input scale): at zero, far from zero (motor steps), small and negative.
INPUTS = [(0.0, 1.0), (1900.0, 1000.0), (-0.3, 1.0)]


def _series(name, u0, scale):
    """``name+linear`` at its default parameters, resolved for an input of ``scale`` around ``u0``. A block
    with several outputs ends the model: an output map alone, one that reads the output (an arc) after ``linear``."""
    block = make_block(name)
    if block.output_size > 1:
        spec = f"linear+{name}" if block.rank > LinearMap.rank else name
    else:
        spec = name if name == "linear" else f"{name}+linear"
    series = Series.from_spec(spec, dt=0.02).for_scales(scale, 1.0, (u0 - scale, u0 + scale))
    series.params = series.params * series.signal_scales(scale, 1.0)[0]
    offsets = {k: 1.0 + v for k, v in series.param_dict().items() if ".offset_" in k}
    return series.set_params(**offsets)  # several maps' offsets default to 0


def _holds_a_loop(series) -> bool:
    """A block with a set of steady states (plays, hysteresis operators): where it settles follows the path."""
    return any(b.takes_loop_width or b.effect == "hysteresis" or "hysteresis" in b.holds_effects
               for b in series.blocks)


@pytest.mark.parametrize(("u0", "scale"), INPUTS)
@pytest.mark.parametrize("name", list(BLOCKS))
def test_the_rest_start_at_a_constant_input_is_its_steady_state(name, u0, scale):
    series = _series(name, u0, scale)
    y = series.simulate(np.full(3000, u0))
    assert np.all(y[0] != 0.0)  # the output map's offset: the check below is not of zeros
    np.testing.assert_allclose(y, np.broadcast_to(y[0], y.shape), rtol=0, atol=1e-9 * max(1.0, np.max(np.abs(y[0]))))
    # a long settle from rest one scale below, ramped up to u0 and held
    path = np.r_[np.linspace(u0 - scale, u0, 200), np.full(20000, u0)]
    settled = series.simulate(path)
    if not _holds_a_loop(series):  # one steady state: the rest start is it
        np.testing.assert_allclose(settled[-1], y[0], rtol=1e-9, atol=1e-9)
