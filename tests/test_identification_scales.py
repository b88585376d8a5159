"""Identification is scale-free: the same catheter data in other units (1e-6 to 1e3) fit to the
same relative error in the same iterations, with parameters in the data's units."""

from __future__ import annotations

import numpy as np
import pytest

from identification import identify
from physics import Series
from physics.data import Trajectory
from physics.virtual import DecayingSinusoid, VirtualCatheter

SPEC = "lag+backlash+boucwen+linear"


@pytest.fixture(scope="module")
def runs():
    cath = VirtualCatheter(effects=("actuator_lag", "backlash", "hysteresis"), seed=0)
    return [cath.run(DecayingSinusoid(f, b)) for f in (0.2, 0.4) for b in ("zero", "mid")], cath.noise_floor


@pytest.fixture(scope="module")
def reference(runs):
    data, _ = runs
    return identify(Series.from_spec(SPEC, dt=0.04), data)


@pytest.mark.parametrize("su,sy", [(1e-6, 1e-6), (1e3, 1e-3), (1e-3, 1e3), (150.0, 1e-6)])
def test_the_same_data_in_other_units_fit_the_same(runs, reference, su, sy):
    data, noise = runs
    scaled = [Trajectory(r.time, r.u * su, r.y * sy) for r in data]
    fit = identify(Series.from_spec(SPEC, dt=0.04), scaled)
    assert fit.success
    # measured: rmse / noise 0.985-0.986 at every scale (before: 3.3 at 1e-6, 19 with u in 1e-3)
    assert fit.train_rmse / sy == pytest.approx(reference.train_rmse, rel=2e-3)
    assert fit.train_rmse / (sy * noise) < 1.05
    p, q = fit.parameters, reference.parameters
    # the smoothing of the backlash and Bouc-Wen follows the data's decade, so a scale that is
    # not a power of ten (150) fits a model smoothed a little differently: 2 % apart (measured 1.8 %)
    rel = 1e-3 if abs(np.log10(su) - round(np.log10(su))) < 1e-9 else 3e-2
    assert p["lag.time_constant_s"] == pytest.approx(q["lag.time_constant_s"], rel=rel)
    assert p["backlash.width"] / su == pytest.approx(q["backlash.width"], rel=rel)
    assert p["linear.gain"] * su / sy == pytest.approx(q["linear.gain"], rel=rel)
    assert p["linear.offset"] / sy == pytest.approx(q["linear.offset"], rel=rel)
    # the fitted model simulates the data it was fitted to, in the data's units
    y = fit.model().simulate(scaled[0].u)
    assert np.sqrt(np.mean((y - scaled[0].y) ** 2)) / sy < 1.1 * noise
