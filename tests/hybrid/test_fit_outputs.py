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


def _runs():
    cath = VirtualCatheter(seed=6, tip=TipArc())
    return [cath.run(DecayingSinusoid(frequency_hz=f, baseline=b))
            for f, b in ((0.2, "zero"), (0.5, "end"), (0.3, "mid"), (0.4, "zero"), (0.25, "mid"))]


def test_the_maps_are_kept_unless_the_arc_is_lower_held_out_by_the_margin():
    runs = _runs()
    specs = ["backlash+boucwen+linear", "backlash+boucwen+linear+arc"]
    fit, (held, pieces, how), tried = _identify(specs, runs[0].dt, runs, POSE, 10, None)
    scores = tried["specs"]
    assert set(scores) == set(specs) and all(isinstance(v, float) for v in scores.values())
    # both at the sensors' noise on the virtual truth (an arc of 75 mm over 65 deg: a cubic follows it)
    arc_wins = int(np.sqrt(scores[specs[1]]) < 0.97 * np.sqrt(scores[specs[0]]))
    assert tried["kept"] == specs[arc_wins] and fit.series.spec == ("backlash+boucwen+linear+arc" if arc_wins
                                                                     else "backlash+boucwen+maps")
    assert len(held) == 2 and all(len(fit_on) == 3 for *_, fit_on in held) and not pieces and "every third run" in how
    run, prediction, _ = held[0]
    assert np.asarray(prediction).shape == (run.n - 10, 3)


def test_an_arc_clearly_lower_held_out_is_kept_and_fitted_on_every_run(monkeypatch):
    """Where the arc's held-out error is clearly lower (here: its held-out predictions made the measurements
    themselves), it replaces the maps and is fitted on every run: its length recovered against the truth."""
    import hybrid.experiments._fit_outputs as fo
    from identification import output_columns

    real = fo._held_out_fit

    def held_out_fit(spec, dt, fit_on, held, outputs, warmup, chain=None):
        if spec.endswith("+arc"):
            return [output_columns(t, outputs)[warmup:].tolist() for t in held]
        return real(spec, dt, fit_on, held, outputs, warmup, chain)

    monkeypatch.setattr(fo, "_held_out_fit", held_out_fit)
    runs = _runs()
    specs = ["backlash+boucwen+linear", "backlash+boucwen+linear+arc"]
    fit, _, tried = _identify(specs, runs[0].dt, runs, POSE, 10, None)
    assert tried["specs"][specs[1]] == 0.0 and tried["kept"] == specs[1] and fit.series.spec == specs[1]
    assert fit.parameters["arc.length"] == pytest.approx(75.0, rel=0.02)


def test_the_intervals_are_calibrated_on_the_selections_folds_where_the_maps_are_kept():
    """With the chain chosen by the selection, each run left out of its fold's chain and maps predicts it: as many
    held-out runs as training runs, none of them seen by the model that predicts it."""
    from hybrid.experiments._fit_outputs import _fold_held_out, _select
    from identification import output_columns

    cath = VirtualCatheter(seed=3, tip=TipArc())
    runs = [cath.run(DecayingSinusoid(frequency_hz=f, baseline=b))
            for f, b in ((0.2, "zero"), (0.5, "end"), (0.3, "mid"), (0.4, "zero"))]
    selection = _select(runs, POSE, 10, None)
    held, pieces, how = _fold_held_out(selection.spec, selection, runs, POSE, 10)
    assert len(held) == len(runs) and not pieces and f"{len(runs)} folds" in how
    for run, prediction, fit_on in held:
        assert run not in fit_on and len(fit_on) == len(runs) - 1
        error = np.asarray(prediction) - output_columns(run, POSE)[10:]
        # a fold's chain and maps predict the run they left out near the sensors' noise (0.15 deg, 0.1 mm)
        assert np.all(np.sqrt(np.mean(error**2, axis=0)) < [0.5, 0.4, 0.4]), np.sqrt(np.mean(error**2, axis=0))
    assert _fold_held_out(selection.spec + "+arc", selection, runs, POSE, 10) is None  # no folds of that spec


def test_the_margin_the_arc_must_clear_is_the_selections():
    from hybrid.experiments._fit_outputs import MARGIN
    from identification.discovery import SelectionSettings

    assert MARGIN == SelectionSettings().margin
