"""A richer model starts from a simpler fitted model nested in it, and never ends worse than it."""

from __future__ import annotations

import numpy as np
import pytest

from identification import IdentificationError, SolverSettings, identify
from identification._nested import embed, is_nested
from physics import Series

from _synthetic import make_runs, truth_model


def test_nesting_needs_the_same_order_and_blocks_that_can_pass_their_input_through():
    assert is_nested("linear", "lag+backlash+linear") and is_nested("backlash+linear", "lag+backlash+boucwen+linear")
    assert not is_nested("backlash+linear", "backlash+linear")  # not a proper simpler spec
    assert not is_nested("backlash+linear", "delay+backlash+linear")  # a delay of one sample is no identity
    assert not is_nested("boucwen+backlash+linear", "backlash+boucwen+linear")


def test_the_embedded_simpler_model_simulates_as_it_does():
    simple = truth_model("backlash+linear")
    rich = Series.from_spec("lag+backlash+boucwen+linear", dt=simple.dt)
    rich.params = embed(rich, simple)
    u = make_runs(simple, 0.0)[0].u
    np.testing.assert_allclose(rich.simulate(u), simple.simulate(u), atol=1e-3 * np.ptp(simple.simulate(u)))
    with pytest.raises(IdentificationError, match="not nested"):
        embed(Series.from_spec("delay+backlash+linear", dt=simple.dt), simple)


def test_a_fit_never_ends_worse_than_a_nested_fit_it_is_given():
    runs = make_runs(truth_model("backlash+linear"), 0.15, seed=2)
    simple = identify("backlash+linear", runs)
    # two IPOPT iterations cannot fit the richer model from its own guess: it falls back to the
    # simpler model's optimum (or improves on it), and says so
    rich = identify(Series.from_spec("lag+backlash+boucwen+linear", dt=0.04), runs, nested=[simple],
                    solver=SolverSettings(max_iter=2), starts=1, allow_failure=True)
    assert rich.train_rmse <= simple.train_rmse * (1 + 1e-3)
    assert any(s["iterations"] <= 2 for s in rich.starts) and len(rich.starts) >= 2
    if rich.status == "Nested_Start_Kept":
        assert rich.parameters["boucwen.A"] == 0.0
        assert rich.parameters["backlash.width"] == pytest.approx(simple.parameters["backlash.width"])
    with pytest.raises(IdentificationError, match="not nested"):
        identify(Series.from_spec("delay+backlash+linear", dt=0.04), runs, nested=[simple], solver=SolverSettings(max_iter=2), starts=1,
                 allow_failure=True)
