"""The model folder of several outputs tries the arc beside a map per output, on runs held out of both fits,
and keeps the better one (issue 55: the selection tries the kinematics block)."""

import numpy as np
import pytest

from hybrid.experiments._fit_outputs import _identify, candidates
from hybrid.virtual import DecayingSinusoid, TipArc, VirtualCatheter

POSE = ("Angle x", "Pos x", "Pos y")


def test_the_arc_is_tried_only_for_an_angle_and_its_position_after_a_chosen_chain():
    assert candidates("lag+gpi+linear", POSE, given=False) == ["lag+gpi+linear", "lag+gpi+linear+arc"]
    assert candidates("lag+gpi+linear", POSE, given=True) == ["lag+gpi+linear"]  # the user's spec is fitted as given
    assert candidates("lag+gpi+linear", POSE[:2], given=False) == ["lag+gpi+linear"]  # no angle and x, y
    assert candidates("lag+gpi+poly", POSE, given=False) == ["lag+gpi+poly"]


def test_the_spec_with_the_lower_held_out_error_is_kept_and_fitted_on_every_run():
    cath = VirtualCatheter(seed=6, tip=TipArc())
    runs = [cath.run(DecayingSinusoid(frequency_hz=f, baseline=b))
            for f, b in ((0.2, "zero"), (0.5, "end"), (0.3, "mid"), (0.4, "zero"), (0.25, "mid"))]
    specs = ["backlash+boucwen+linear", "backlash+boucwen+linear+arc"]
    fit, (held, fit_on, predictions, pieces), how, tried = _identify(specs, runs[0].dt, runs, POSE, 10, None)
    scores = tried["specs"]
    assert set(scores) == set(specs) and all(isinstance(v, float) for v in scores.values())
    assert tried["kept"] == min(scores, key=scores.get)
    # the truth is an arc: held out, it is at the sensors' noise (each output's error over its spread, squared)
    assert tried["kept"] == specs[1] and fit.series.spec == specs[1]
    assert fit.parameters["arc.length"] == pytest.approx(75.0, rel=0.02)
    assert len(held) == 2 and len(fit_on) == 3 and not pieces and "every third run" in how
    assert np.asarray(predictions[0]).shape == (held[0].n - 10, 3)
