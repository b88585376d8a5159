"""Issue 53 item 9 in ``hyst compare``: a hybrid is never kept where its network alone does better held out."""

import json

import numpy as np
import pytest

pytest.importorskip("torch")

from hybrid.experiments._hybrid_or_alone import ALONE_KEPT, HYBRID, hybrid_or_alone, pooled_rmse  # noqa: E402
from hybrid.experiments._presets import BUDGETS  # noqa: E402
from hybrid.experiments._split import residual_split  # noqa: E402
from hybrid.learning import LearnedModel  # noqa: E402
from hybrid.models import HybridModel  # noqa: E402
from hybrid.networks import make_network  # noqa: E402
from physics import Series  # noqa: E402
from physics.data import Trajectory  # noqa: E402


def _runs():
    """Six runs of a static tanh loop, the held-out ones (every third) three times longer than the rest."""
    def run(i, seconds):
        t = np.arange(0, seconds, 0.04)
        u = 1.5 * (1 - np.cos(2 * np.pi * (0.3 + 0.02 * i) * t)) / 2
        return Trajectory(t, u, 10 * np.tanh(u) + np.random.default_rng(i).normal(0, 0.05, t.size), source=f"r{i}")

    return [run(i, 60.0 if i in (1, 4) else 20.0) for i in range(6)]


def test_where_the_physics_misleads_the_residual_the_compare_row_is_the_network_alone():
    """A physics that drifts (a lag of 50 s on runs of 20-60 s) leads the hybrid's network outside what it was
    trained on, on the longer held-out runs: the rule keeps the network alone, and its scores are the two
    models' pooled RMSE on exactly the runs :func:`residual_split` holds out, fitted without them."""
    runs = _runs()
    drifting = Series.from_spec("lag+linear", dt=0.04).set_params(
        **{"lag.time_constant_s": 50.0, "linear.gain": 10.0, "linear.offset": 0.0})
    settings = BUDGETS["tiny"].networks.for_network("fnn-hib", seed=0, progress=False)
    fitted = {}

    def fit_as(name, make):  # the unfitted model, remembered so the test can score it on the held-out runs
        def new():
            fitted[name] = make()
            return fitted[name]
        return new

    choice = hybrid_or_alone(fit_as(HYBRID, lambda: HybridModel(drifting, "fnn-hib", training=settings)),
                             fit_as(ALONE_KEPT, lambda: LearnedModel(make_network("fnn-hib"), training=settings)),
                             pooled_rmse("forward", 10), runs, 10, make_network("fnn-hib").history)
    fit_on, held, _ = residual_split(runs, 10, 50)
    assert [t.source for t in held] == ["r1", "r4"] == choice.held_out_runs
    for name, model in fitted.items():  # fitted on the runs left in, scored on those held out
        assert choice.held_out_rmse[name] == pooled_rmse("forward", 10)(model, held)
    assert choice.kept == ALONE_KEPT and choice.held_out_rmse[ALONE_KEPT] < choice.held_out_rmse[HYBRID]
    assert "the network alone kept" in choice.line("fnn-hib+physics")
    # a physics that does not mislead keeps the hybrid
    right = Series.from_spec("linear", dt=0.04).set_params(**{"linear.gain": 10.0, "linear.offset": 0.0})
    kept = hybrid_or_alone(lambda: HybridModel(right, "fnn", training=settings),
                           lambda: LearnedModel(make_network("fnn"), training=settings),
                           lambda model, on: 0.0 if isinstance(model, HybridModel) else 1.0, runs, 10)
    assert kept.kept == HYBRID


def test_runs_too_short_to_hold_out_keep_the_hybrid_and_say_why():
    short = [Trajectory(np.arange(30) * 0.04, np.linspace(0, 1, 30), np.linspace(0, 10, 30), source="s")]
    never = lambda: pytest.fail("nothing is held out: no held-out fit")  # noqa: E731
    choice = hybrid_or_alone(never, never, pooled_rmse("forward", 10), short, 10, 50)
    assert choice.kept == HYBRID and choice.held_out_rmse == {} and "too short" in choice.how
    assert "the hybrid (" in choice.line("fnn-hib+physics")


def test_compare_records_the_choice_of_every_hybrid_row(tmp_path):
    """``hyst compare`` writes which model each hybrid row is, with the held-out evidence, in run.json and
    compare.md; a row whose network alone was kept scores exactly as that network's row."""
    import csv

    from hybrid.experiments._compare import compare
    from hybrid.experiments._datasets import CompareData
    from physics.data import Dataset

    runs = _runs()
    data = CompareData(Dataset(runs[:5]), {"id": Dataset([runs[5]])}, name="tanh")
    compare(data, tmp_path, preset="tiny", progress=False, figures=False, directions=("forward",),
            networks=("fnn", "fnn-hib"), physics="lag+linear", peers=())
    run = json.loads((tmp_path / "run.json").read_text())
    choices = run["hybrid_choice"]
    assert set(choices) == {"all/forward/fnn+physics", "all/forward/fnn-hib+physics"}
    for key, c in choices.items():
        assert c["kept"] in (HYBRID, ALONE_KEPT) and set(c["held_out_rmse"]) == {HYBRID, ALONE_KEPT}
        assert c["held_out_runs"] == ["r1", "r4"]
        assert c["kept"] == (ALONE_KEPT if c["held_out_rmse"][ALONE_KEPT] < c["held_out_rmse"][HYBRID] else HYBRID)
    with open(tmp_path / "compare.csv") as fh:
        pooled = {r["model"]: float(r["rmse"]) for r in csv.DictReader(fh) if r["test"] == "id:all"}
    for m in ("fnn", "fnn-hib"):
        if choices[f"all/forward/{m}+physics"]["kept"] == ALONE_KEPT:
            assert pooled[f"{m}+physics"] == pooled[m]
    md = (tmp_path / "compare.md").read_text()
    assert "## Hybrids or their networks alone" in md and "all/forward/fnn-hib+physics:" in md
