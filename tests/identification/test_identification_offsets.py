"""Identification does not care where the input lies: the same loops with the input in motor steps
(raw counts offset by 1900) or in nanometres (offset by 200 nm) fit every standard spec to
the same error as in plain units, and the truth's own spec recovers its parameters."""

from __future__ import annotations

import numpy as np
import pytest

from identification import identify
from identification.discovery import SELECT_BLOCKS
from physics import Backlash, Lag, LinearMap, Series
from physics.data import Trajectory

DT, NOISE = 0.04, 0.1
TRUTH = dict(time_constant_s=0.3, width=0.5, gain=11.0, offset=30.0)  # output in degrees
#: (input scale, input offset): plain units, motor steps far from zero, nanometres far from zero
UNITS = {"counts": (1.0, 1900.0), "nanometres": (1e-9, 2e-7)}
STANDARD = ("linear", "lag+linear", "backlash+linear", "gpi+linear", "lag+gpi+linear", "boucwen+linear",
            "lag+backlash+linear")
SPECS = tuple(dict.fromkeys(STANDARD + tuple(f"{b}+linear" for b in SELECT_BLOCKS)))
#: Creep's default start is relaxed at ``rest_input = 0`` in the input's units: a setting with a unit,
#: so its model (not only its fit) differs once the input sits far from 0. Only its convergence is checked.
UNIT_BEARING = {"creep+linear"}


def _loops(seed: int) -> list:
    """Decaying cycles through lag + backlash + linear, input 0-5.8 (plain units), noise 0.1 deg."""
    truth = Series(Lag(time_constant_s=TRUTH["time_constant_s"]), Backlash(width=TRUTH["width"]),
                   LinearMap(gain=TRUTH["gain"], offset=TRUTH["offset"]), dt=DT)
    rng, out = np.random.default_rng(seed), []
    for f, amplitude, phase in ((0.2, 2.9, -np.pi / 2), (0.3, 2.0, 0.0)):
        t = np.arange(0, 6 / f, DT)
        u = 2.9 + amplitude * np.sin(2 * np.pi * f * t + phase) * np.exp(-f * np.log(7 / 6) * t)
        out.append(Trajectory(t, u, truth.simulate(u) + rng.normal(0, NOISE, t.size)))
    return out


def _in_units(runs, su, offset):
    return [Trajectory(r.time, r.u * su + offset, r.y) for r in runs]


def _held_out_rmse(fit, runs) -> float:
    model = fit.model()
    return float(np.sqrt(np.mean(np.concatenate([model.simulate(r.u) - r.y for r in runs]) ** 2)))


@pytest.fixture(scope="module")
def data():
    return _loops(0), _loops(1)


@pytest.fixture(scope="module")
def reference(data):
    train, test = data
    return {spec: _held_out_rmse(identify(Series.from_spec(spec, dt=DT), train), test) for spec in SPECS}


@pytest.mark.parametrize("units", sorted(UNITS))
@pytest.mark.parametrize("spec", SPECS)
def test_every_spec_fits_an_input_far_from_zero_as_in_plain_units(data, reference, units, spec):
    su, offset = UNITS[units]
    train, test = (_in_units(runs, su, offset) for runs in data)
    fit = identify(Series.from_spec(spec, dt=DT), train)
    assert fit.success, fit.status
    if spec in UNIT_BEARING:
        return
    # measured: the same held-out RMSE to 4 digits for every spec; before, with the input in steps
    # offset by 1900, lag+gpi+linear stalled at 0.999 deg (0.103 in plain units) and gpi+linear
    # ended at 2.17 (2.14): the envelope's centre near 1900 was solved for as a multiple of itself
    assert _held_out_rmse(fit, test) == pytest.approx(reference[spec], rel=2e-2)


@pytest.mark.parametrize("units", sorted(UNITS))
def test_the_truths_spec_recovers_it_far_from_zero(data, units):
    su, offset = UNITS[units]
    train, test = (_in_units(runs, su, offset) for runs in data)
    fit = identify(Series.from_spec("lag+backlash+linear", dt=DT), train)
    assert fit.success, fit.status
    p = fit.parameters
    assert p["lag.time_constant_s"] == pytest.approx(TRUTH["time_constant_s"], rel=3e-2)
    assert p["backlash.width"] / su == pytest.approx(TRUTH["width"], rel=3e-2)
    assert p["linear.gain"] * su == pytest.approx(TRUTH["gain"], rel=1e-2)
    # the output at the input's zero: far outside the data, so compare it where the data are
    assert p["linear.offset"] + p["linear.gain"] * offset == pytest.approx(TRUTH["offset"], abs=0.2)
    assert _held_out_rmse(fit, test) < 1.1 * NOISE
    for spec in ("lag+gpi+linear",):  # a richer hysteresis block reaches the noise too
        assert _held_out_rmse(identify(Series.from_spec(spec, dt=DT), train), test) < 1.1 * NOISE
