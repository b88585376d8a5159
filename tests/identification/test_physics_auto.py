"""``physics="auto"`` in the hybrid estimator and in ``hyst compare``: the spec chosen on held-out runs,
and the choice reported."""

import numpy as np
import pytest

from hybrid.cli._main import main
from hybrid.experiments._compare import PHYSICS, _Job, _physics_fit, compare_policy

from test_select_physics import _run

pytest.importorskip("torch")


@pytest.fixture(autouse=True)
def few_blocks(monkeypatch):
    # the search itself is tested in test_select_physics.py; here a short one keeps the wiring test fast
    monkeypatch.setattr("identification.discovery._select.SELECT_BLOCKS", ("lag", "poly", "creep"))


@pytest.fixture(scope="module")
def runs():
    return [_run(lo, lo + 2.0, 0.1 + 0.1 * i, i) for i, lo in enumerate((0.0, 1.5, 3.0, 4.5))]


def test_compare_auto_chooses_on_held_out_runs_and_reports_it(runs):
    job = _Job(cfg={}, networks=(), seed=0, progress=False, policy=compare_policy(("auto",)))
    fit = _physics_fit(job, runs, "all/forward")
    report = job.physics_selection["all/forward"]
    assert fit.spec == "linear" == report["spec"] and job.physics_used == {"all/forward": "linear"}
    assert report["cv_rmse"]["poly+linear"] > 2 * report["cv_rmse"]["linear"]
    assert report["how"] == "leave-one-run-out" and len(report["folds"]) == 4
    scored = {k: v for k, v in report["cv_rmse"].items() if v is not None and k not in report["stopped"]}
    assert min(scored.values()) == report["cv_rmse"]["linear"]  # stopped specs' errors cover fewer folds
    # the inverse direction trains on the same runs: the choice and the fit are reused, not made again
    assert _physics_fit(job, runs, "all/inverse") is fit and list(job.physics_selection) == ["all/forward"]
    assert job.physics_used == {"all/forward": "linear", "all/inverse": "linear"}


def test_compare_auto_with_one_run_holds_out_its_later_stretches(runs):
    job = _Job(cfg={}, networks=(), seed=0, progress=False, policy=compare_policy(("auto",)))
    fit = _physics_fit(job, runs[:1], "data_1/forward")
    report = job.physics_selection["data_1/forward"]
    assert report["how"].startswith("next-") and len(report["folds"]) == len(report["fold_rmse"]["linear"]) >= 2
    starts = [int(f[0].split("[")[1].split(":")[0]) for f in report["folds"]]
    assert starts == sorted(starts) and starts[0] > 0  # each after the run before it, never interleaved
    assert fit.spec == report["spec"] == job.physics_used["data_1/forward"]


def test_compare_auto_with_one_short_run_falls_back_to_the_default_specs(runs):
    from physics.data import Trajectory

    short = Trajectory(runs[0].time[:100], runs[0].u[:100], runs[0].y[:100])
    job = _Job(cfg={}, networks=(), seed=0, progress=False, policy=compare_policy(("auto",)))
    fit = _physics_fit(job, [short], "data_1/forward")
    assert "at least two runs, or one of at least 120 samples" in job.physics_selection["data_1/forward"]["error"]
    assert fit.spec in PHYSICS


def test_hybrid_model_auto_keeps_and_saves_its_selection(runs, tmp_path):
    from hybrid import HybridModel, TrainingSettings

    model = HybridModel("auto", "fnn", training=TrainingSettings(epochs=1, progress=False, seed=0)).fit(runs)
    sel = model.physics_selection_
    assert model.physics_.spec == sel.spec == "linear"
    assert sel.cv_rmse["linear"] < sel.cv_rmse["creep+linear"]  # the greedy search tried creep and dropped it
    assert np.isfinite(model.predict(runs[0])).all()
    path = model.save(tmp_path / "auto.pt")
    back = HybridModel.load(path)
    assert back.physics_selection_["spec"] == "linear"
    np.testing.assert_allclose(back.predict(runs[0]), model.predict(runs[0]), atol=1e-9)


def test_auto_with_other_specs_is_a_clear_cli_error(tmp_path, capsys):
    assert main(["compare", "--preset", "tiny", "--physics", "auto,linear", "--out", str(tmp_path / "o")]) == 2
    assert "auto" in capsys.readouterr().err


def _loops():
    """Backlash loops at three rates and offsets: two to train on, one to test."""
    from hybrid.experiments._datasets import CompareData
    from physics import Series
    from physics.data import Dataset, Trajectory

    truth = Series.from_spec("backlash+linear", dt=0.1).set_params(**{"backlash.width": 0.8, "linear.gain": 10.0})
    t = np.arange(400) * 0.1
    loops = [Trajectory(t, u, truth.simulate(u) + np.random.default_rng(i).normal(0, 0.05, t.size), source=f"r{i}")
             for i, u in enumerate(m - 1.8 * np.cos(2 * np.pi * f * t) for m, f in ((2.0, 0.1), (3.0, 0.2), (2.5, 0.3)))]
    return CompareData(Dataset(loops[:2]), {"id": Dataset(loops[2:])}, None, {}, None, "loops")


def test_compare_goes_on_without_the_neural_ode_when_the_physics_has_no_continuous_form(tmp_path):
    import json

    from hybrid.experiments._compare import compare

    result = compare(_loops(), tmp_path / "cmp", preset="tiny", networks=("fnn",), physics="gpi+linear",
                     directions=("forward",), figures=False)
    models = {r.model for r in result.rows}
    assert {"physics", "fnn", "fnn+physics"} <= models and "neural-ode" not in models
    run = json.loads((tmp_path / "cmp" / "run.json").read_text())
    assert "no continuous-time form" in run["skipped"]["all/forward/neural-ode"]


def test_the_neural_ode_takes_the_next_spec_with_a_continuous_form(tmp_path):
    """gpi has no ODE form and poly+linear no state: the hybrids keep gpi+linear, the neural ODE runs
    on backlash+linear (the next spec tried with a state to correct), fitted to the same loops, and
    run.json says which physics each used."""
    import json

    from hybrid.experiments._compare import compare

    result = compare(_loops(), tmp_path / "cmp", preset="tiny", networks=("fnn",),
                     physics=("gpi+linear", "preisach+linear", "poly+linear", "backlash+linear"), directions=("forward",),
                     figures=False)
    scores = {r.model: r.rmse for r in result.rows if r.test == "id:all"}
    run = json.loads((tmp_path / "cmp" / "run.json").read_text())
    assert run["physics_used"] == {"all/forward": "gpi+linear", "all/forward/neural-ode": "backlash+linear"}
    assert not run["skipped"]
    # the loops span 36: measured 0.94 (the continuous play under RK4 at 10 Hz), the network alone 24
    assert scores["neural-ode"] < 1.5 < 10 < scores["fnn"]


def test_the_neural_ode_passes_over_a_physics_whose_ode_form_is_unstable(tmp_path, monkeypatch):
    """The hybrids' physics fits, but its ODE form diverges at the data's rate (the neural ODE's
    fit refuses it, a PhysicsError): the neural ODE runs on the next spec, and run.json says why."""
    import json

    from hybrid.experiments._compare import compare
    from hybrid.models import NeuralODEHybrid
    from physics import PhysicsError

    fit = NeuralODEHybrid.fit

    def refuse_backlash(self, data):
        if "backlash" in self.physics.spec:
            raise PhysicsError(f"The ODE form of '{self.physics.spec}' diverges (stand-in)")
        return fit(self, data)

    monkeypatch.setattr(NeuralODEHybrid, "fit", refuse_backlash)
    result = compare(_loops(), tmp_path / "cmp", preset="tiny", networks=("fnn",),
                     physics=("backlash+linear", "lag+linear"), directions=("forward",), figures=False)
    run = json.loads((tmp_path / "cmp" / "run.json").read_text())
    assert run["physics_used"] == {"all/forward": "backlash+linear", "all/forward/neural-ode": "lag+linear"}
    assert "neural-ode" in {r.model for r in result.rows} and not run["skipped"]
