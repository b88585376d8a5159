"""Multi-start by default where a spec is prone to local minima, deterministic, and no extra
starts where the first already fits down to the data's noise."""

from __future__ import annotations

import numpy as np
import pytest

from identification import identify
from physics import Series
from physics.virtual import DecayingSinusoid, VirtualCatheter


@pytest.fixture(scope="module")
def runs():
    cath = VirtualCatheter(effects=("actuator_lag", "backlash", "hysteresis"), seed=3)
    return [cath.run(DecayingSinusoid(f, "mid", cycles=3)) for f in (0.2, 0.5)], cath


def test_a_spec_with_a_lag_gets_three_seeded_starts_when_the_first_leaves_room(runs):
    data, _ = runs
    model = Series.from_spec("lag+linear", dt=0.04)  # misses the loop: the first start is far above the noise
    auto = identify(model, data)
    assert len(auto.starts) == 3 and sum(s["best"] for s in auto.starts) == 1
    best = min(s["cost"] for s in auto.starts)
    assert next(s for s in auto.starts if s["best"])["cost"] == best <= auto.starts[0]["cost"]
    explicit = identify(model, data, starts=3)  # the same three starts, in the same order
    assert explicit.parameters == auto.parameters
    assert [s["cost"] for s in explicit.starts] == [s["cost"] for s in auto.starts]
    again = identify(model, data)
    assert again.parameters == auto.parameters and again.starts == tuple(
        {**s, "wall_time_s": a["wall_time_s"]} for s, a in zip(auto.starts, again.starts))
    other_seed = identify(model, data, seed=1)
    assert [s["cost"] for s in other_seed.starts][0] == auto.starts[0]["cost"]  # the first is the guess


def test_no_extra_start_where_the_first_fits_down_to_the_noise(runs):
    _, cath = runs
    truth = cath.truth_model()  # the right structure: the first start reaches the noise
    data = [cath.run(DecayingSinusoid(f, "mid", cycles=3)) for f in (0.2, 0.5)]
    fit = identify(Series.from_spec(truth.spec, dt=truth.dt), data)
    assert len(fit.starts) == 1 and fit.success
    assert fit.train_rmse < 1.1 * cath.noise_floor


def test_a_spec_without_such_blocks_keeps_one_start(runs):
    data, _ = runs
    assert len(identify("poly+linear", data).starts) == 1
    assert len(identify("lag+linear", data, starts=1).starts) == 1
