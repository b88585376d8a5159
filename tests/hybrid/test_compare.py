"""``hyst compare --preset tiny`` end to end."""

import csv
import json

import pytest

from hybrid.cli._main import main


def test_compare_tiny_writes_every_kind_and_category(tmp_path, capsys):
    out = tmp_path / "cmp"
    # a given spec: the default, physics chosen on held-out runs, is tested in test_physics_auto
    # (here it took 150 of the test's 180 s)
    assert main(["compare", "--preset", "tiny", "--physics", "backlash+boucwen+linear", "--out", str(out),
                 "--no-progress"]) == 0
    with open(out / "compare.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert list(rows[0]) == ["direction", "model", "kind", "test", "rmse", "nrmse"]
    assert {r["kind"] for r in rows} == {"physics", "learned", "hybrid", "peer"}
    assert {r["direction"] for r in rows} == {"forward", "inverse"}
    categories = {r["test"].split(":")[0] for r in rows}
    assert categories == {"id", "ood_freq", "ood_amp", "ood_baseline", "ood_steps", "data_1", "data_3", "data_all"}
    models = {r["model"] for r in rows}
    assert {"physics", "fnn", "fnn-hib", "lstm", "fnn+physics", "lstm+physics", "neural-ode",
            "model-inverse:fnn-hib+physics"} <= models
    assert (out / "compare.md").is_file() and list((out / "figures").glob("*.png"))
    printed = capsys.readouterr().out
    assert "best hybrid" in printed and "best peer peer:" in printed  # ours against the peers, as a ratio
    assert {"peer:arx"} <= models
    with open(out / "run.json") as fh:
        run = json.load(fh)
    inverse = run["physics_inverse"]
    assert run["warmup"] == 10  # every model set its state from each test run's first 10 samples
    from hybrid.peers import available_peers

    for name, note in available_peers().items():  # a peer whose package is missing is skipped with its note
        assert (f"peer:{name}" in models) == (note is None)
        assert note is None or run["skipped"]["all/forward/" + name] == note
    lo, hi = inverse["all/inverse"]["bounds"]  # the virtual catheter's 0-6 mm, widened by 20 % of its span
    assert -1.5 < lo < 0 and 6 < hi < 7.5 and isinstance(inverse["all/inverse"]["quasi_static"], bool)


def test_compare_bad_preset_is_one_line_and_exit_2(tmp_path, capsys):
    assert main(["compare", "--preset", "huge", "--out", str(tmp_path)]) == 2
    assert "Must be one of" in capsys.readouterr().err


def test_a_physics_spec_that_does_not_fit_is_listed_and_the_next_one_is_used():
    from identification import IdentificationError
    from hybrid.experiments._compare import _Job, _physics_fit, compare_policy
    from physics.virtual import DecayingSinusoid, VirtualCatheter

    cath = VirtualCatheter(seed=0)
    train = [cath.run(DecayingSinusoid(f, "mid")) for f in (0.3, 0.5)]
    job = _Job(cfg={}, networks=(), seed=0, progress=False, policy=compare_policy(("poly", "backlash+linear")))
    fit = _physics_fit(job, train, "all/forward")
    assert fit.spec == "backlash+linear" and job.physics_used == {"all/forward": "backlash+linear"}
    assert "no output map" in job.physics_failed["all/forward/poly"]
    with pytest.raises(IdentificationError, match=r"None of the physics specs \['poly'\] could be fitted"):
        _physics_fit(_Job(cfg={}, networks=(), seed=0, progress=False, policy=compare_policy(("poly",))), train, "x")


def test_compare_on_a_kHz_folder_in_volts_and_metres(tmp_path):
    """Other people's units and rates: every cell of the tables is a number (micrometre errors printed
    0.000 before), and the model-based inverse moves the input (its input-rate weight swamped an
    output in metres: 40 % of the input's span before it was made unit-free)."""
    from _synthetic import piezo_runs

    folder = tmp_path / "piezo"
    runs = piezo_runs((4.0, 10.0, 16.0, 7.0))  # 1,665 samples at 1 kHz
    for part, some in {"train": runs[:3], "test": runs[3:]}.items():
        (folder / part).mkdir(parents=True)
        for i, run in enumerate(some):
            run.to_csv(folder / part / f"run{i}.csv")
    out = tmp_path / "cmp"
    assert main(["compare", "--data", str(folder), "--preset", "tiny", "--physics", "backlash+linear",
                 "--networks", "fnn", "--out", str(out), "--no-progress", "--no-figures"]) == 0
    with open(out / "compare.csv") as fh:
        rows = {(r["direction"], r["model"]): float(r["rmse"]) for r in csv.DictReader(fh) if r["test"] == "id:all"}
    assert rows["forward", "physics"] < 1e-7  # metres: the backlash's 1.5 um loop is fitted
    assert rows["inverse", "model-inverse:fnn-hib+physics"] < 0.1 * 140  # volts, of a 140 V span
    text = (out / "compare.md").read_text()
    assert "e-0" in text and "| 0.000 |" not in text


def test_compare_interval_calibrates_every_forward_model_on_held_out_runs_serial_and_in_two_workers(tmp_path):
    """--interval: each forward model fitted again on the folds of the three training runs and
    calibrated on the run each left out; coverage and width per category, in the data's units. The folds
    run on the selection's pool: two local workers write the same intervals.csv (coverage, width, held-out
    runs of every forward model) as one process."""
    from _synthetic import piezo_runs

    from hybrid.experiments._compare import compare, compare_policy
    from hybrid.experiments._datasets import CompareData
    from identification.discovery import Workers
    from physics.data import Dataset

    runs = piezo_runs((2.0, 5.0, 8.0, 3.5), rate=250.0)  # 832 samples: every model is fitted four times
    data = CompareData(Dataset(runs[:3]), {"id": Dataset(runs[3:])}, name="piezo")
    tables = []
    for n_jobs in (1, 2):
        out = tmp_path / f"jobs{n_jobs}"
        compare(data, out, preset="tiny", figures=False, directions=("forward",), networks=("fnn",),
                physics=compare_policy("backlash+linear", Workers(n_jobs=n_jobs)), peers=("arx",), interval=0.8)
        with open(out / "intervals.csv") as fh:
            tables.append(list(csv.DictReader(fh)))
        timings = json.loads((out / "run.json").read_text())["fit_seconds"]
        assert {f"fold{k}/forward/physics" for k in range(3)} <= set(timings)  # the folds' fit times came back
    assert tables[0] == tables[1]
    bands = {r["model"]: r for r in tables[0]}
    assert {"physics", "fnn", "fnn+physics", "peer:arx"} <= set(bands)
    assert all(r["held_out_runs"] == "3" and 0 <= float(r["coverage"]) <= 1 for r in bands.values())
    assert float(bands["physics"]["coverage"]) >= 0.8 and 0 < float(bands["physics"]["width"]) < 1e-5  # metres
    assert "## Forward, 80% conformal intervals" in (tmp_path / "jobs1" / "compare.md").read_text()
    with pytest.raises(ValueError, match="between 0 and 1"):
        compare(data, tmp_path / "x", preset="tiny", interval=1.0)


def test_the_neural_ode_is_scored_through_its_export_with_the_same_numbers():
    """compare scores the neural ODE on its CasADi export (its torch rollout steps from Python once
    per sample, minutes on a long test run): the same predictions to rounding."""
    import numpy as np

    from hybrid import NeuralODEHybrid
    from hybrid.experiments._compare import _ViaExport
    from physics.virtual import paper_protocol

    split = paper_protocol(frequencies=(0.5,), tests=(0.45,), baselines=("mid",))
    model = NeuralODEHybrid("backlash+boucwen+linear", hidden=8, epochs=2, progress=False).fit(split.train)
    assert model.module_.net[-1].weight.abs().max() > 1e-4  # a correction that is not zero
    scored = _ViaExport(model)
    assert scored.direction == "forward"
    np.testing.assert_allclose(scored.predict(split.test[0]), model.predict(split.test[0]), rtol=0, atol=1e-9)


def test_a_model_that_diverges_on_a_test_run_scores_inf_and_the_others_are_scored():
    """A prediction that is not finite ends as 'diverged' in the table, not as the comparison's end."""
    import numpy as np

    from hybrid.experiments._compare_table import markdown, rows
    from hybrid.experiments._datasets import CompareData
    from hybrid.experiments._scoring import score_model
    from physics.data import DataError, Dataset, Trajectory

    class Stub:
        direction = "forward"

        def predict(self, traj):
            if traj.source == "runaway":  # finite, but 1e74 where the data span 3 (an unstable ARX)
                return traj.u * np.exp(np.arange(traj.n) * 1.7)
            return np.where(traj.u > 2.5, np.nan, traj.u) if traj.source == "bad" else traj.u + 0.1

    t = np.arange(0, 4, 0.04)
    runs = [Trajectory(t, 3 * np.sin(t) ** 2, 3 * np.sin(t) ** 2, source=s) for s in ("good", "bad", "runaway")]
    scores = {s.test: s.rmse for s in score_model(Stub(), runs, "stub", diverged="inf")}
    assert scores["good"] == pytest.approx(0.1)
    assert scores["bad"] == scores["runaway"] == scores["all"] == float("inf")
    table = markdown(rows(score_model(Stub(), runs, "stub", diverged="inf"), "learned", "id"),
                     CompareData(Dataset(runs), {"id": Dataset(runs)}, name="stub data"))
    assert "| stub | learned | diverged |" in table
    with pytest.raises(DataError, match="non-finite value"):  # elsewhere (ablations, Table I) it says so
        score_model(Stub(), runs, "stub")
