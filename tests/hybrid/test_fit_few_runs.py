"""``hyst fit`` from one or two runs, as a new lab starts: the residual is chosen on pieces of the runs it
was not trained on, the intervals are calibrated on pieces, and the card says what was done."""

import json

import numpy as np
import pytest

pytest.importorskip("torch")

from hybrid.experiments._fit import fit_model_dir, residual_split  # noqa: E402
from identification.discovery import FALLBACK, PhysicsPolicy  # noqa: E402
from physics import Series  # noqa: E402
from physics.data import Trajectory  # noqa: E402

DT = 0.1


def _loop(seed: int, n: int = 600, source: str = "loop") -> Trajectory:
    """Slow loops of a tendon through a play (backlash) and a line, with noise."""
    truth = Series.from_spec("backlash+linear", dt=DT).set_params(**{"backlash.width": 0.6, "linear.gain": 10.0})
    t = np.arange(n) * DT
    u = 2.0 - 1.6 * np.cos(2 * np.pi * t / (n * DT / 3)) * (1 - 0.3 * t / t[-1])
    rng = np.random.default_rng(seed)
    return Trajectory(t, u, truth.simulate(u) + rng.normal(0, 0.05, n), source=f"{source}{seed}.csv")


def test_the_residual_of_one_or_two_runs_is_held_out_on_its_last_stretch_after_all_it_was_trained_on():
    # what the user predicts next: the run's last branch or stretch, cut into pieces for the intervals'
    # groups, each from the 10 measured samples before it; the network trains on the run before it only
    one = [_loop(0)]
    fit_on, held, how = residual_split(one, warmup=10)
    assert [t.source for t in held] == ["loop0.csv[490:550]", "loop0.csv[540:600]"]
    assert [t.source for t in fit_on] == ["loop0.csv[0:500]"] and "last branch or stretch" in how
    assert all(t.n == 60 for t in held) and max(t.n for t in fit_on) == 500  # nothing held out was trained on
    two = [_loop(0), _loop(1)]
    fit_on, held, _ = residual_split(two, warmup=10)
    assert len(held) == 4 and {t.source.split("[")[0] for t in held} == {"loop0.csv", "loop1.csv"}
    three = [_loop(i) for i in range(3)]
    assert [t.source for t in residual_split(three, warmup=10)[1]] == ["loop1.csv"]


def test_one_run_fit_chooses_its_residual_out_of_sample_and_has_intervals(tmp_path):
    run, test = _loop(0), _loop(5, source="test")
    result = fit_model_dir([run], tmp_path / "m", test=[test], residual="auto", preset="tiny", progress=False)
    assert result.spec == "backlash+linear"
    report = (tmp_path / "m" / "report.md").read_text()
    assert "trained without loop0[490:550], loop0[540:600]" in report and "(fewer than 3 runs" in report
    assert "scored on them" in report and "training runs (fewer than 3 runs) and scored on them" not in report
    assert "A weaker assumption than held-out runs" in report
    assert "too few to trust" in report and "linear ARX (peer, same folds and warm-up)" in report
    assert result.intervals is not None, result.calibration
    assert result.intervals.runs_ == ["loop0.csv[290:400]", "loop0.csv[390:500]", "loop0.csv[490:600]"]  # the next branches
    cover = [r["coverage"] for r in result.rows if r["set"] == "test"]
    assert cover and cover[0] > 0.6


def test_identify_minimises_and_reports_the_error_the_card_scores(tmp_path):
    # identification used to minimise (and report) the error from rest over every sample, the card the
    # error after each run's first samples, which set its state: one objective now
    runs = [_loop(i, n=400) for i in range(3)]
    result = fit_model_dir(runs, tmp_path / "m", physics="lag+backlash+linear", residual="none", preset="tiny",
                           progress=False, warmup=20)
    fit = json.loads((tmp_path / "m" / "physics.json").read_text())
    from hybrid.experiments._card import pooled

    card = pooled([r for r in result.rows if r["set"] == "train"], "physics_rmse")
    assert fit["train_rmse"] == pytest.approx(card, rel=1e-9)
    report = (tmp_path / "m" / "report.md").read_text()
    assert f"| **pooled (train)** | train | {card:.4g} |" in report and f"train RMSE {fit['train_rmse']:.4g}" in report


def _high_pass(seed: int, n: int = 400) -> Trajectory:
    """A linear system no block of the library holds (a zero near 1: it answers the input's changes)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * DT
    u = np.convolve(rng.normal(0, 1, n + 20), np.ones(20) / 20, "valid")[:n] * 3
    y = np.zeros(n)
    for k in range(2, n):
        y[k] = 0.8 * y[k - 1] + 2.0 * (u[k - 1] - u[k - 2]) + 0.3 * u[k - 1] + 1.0
    return Trajectory(t, u, y + rng.normal(0, 0.01, n), source=f"hp{seed}.csv")


def test_a_peer_that_beats_the_physics_held_out_is_the_model_exported_and_used_like_any_other(tmp_path):
    from hybrid.cli import main
    from hybrid.export import ExportedModel, load
    from physics.data import rmse, warmup_split

    runs, test = [_high_pass(i) for i in range(3)], _high_pass(9)
    out = tmp_path / "m"
    policy = PhysicsPolicy("auto", fallback=FALLBACK, select_options={"blocks": ("lag",), "refinements": {}})
    result = fit_model_dir(runs, out, test=[test], preset="tiny", progress=False, physics=policy)
    assert result.residual == "none" and type(result.model).__name__ == "LinearARX"
    report = (out / "report.md").read_text()
    assert "# Model card: linear ARX (peer)" in report and "beats `" in report
    row = [r for r in result.rows if r["set"] == "test"][0]
    assert row["model_rmse"] == pytest.approx(row["arx_rmse"]) and row["model_rmse"] < 0.3 * row["physics_rmse"]
    loaded = load(out)  # the folder's model, as hyst predict reads it
    window, rest = warmup_split(test, 10)
    assert rmse(rest.y, loaded.predict(rest, warmup=window)) == pytest.approx(row["model_rmse"])
    step = ExportedModel.load(out / "step.casadi")  # the export from the measured window equals predict
    x = np.asarray(step.init(window.u[None, :], window.y[None, :])).ravel()
    ys = []
    for v in rest.u:
        x, y = step.step(x, v)
        ys.append(float(y))
    assert np.max(np.abs(np.array(ys) - loaded.predict(rest, warmup=window))) < 1e-9
    assert result.intervals is not None  # calibrated on the peer's held-out folds
    test_csv = test.to_csv(tmp_path / "t.csv")
    assert main(["predict", str(out), str(test_csv), "--out", str(tmp_path / "p.csv")]) == 0
