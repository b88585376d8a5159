"""``compare(..., outputs=...)`` (issue 55): every model of the tip's pose side by side, forward, scored per output
beside a linear ARX of all outputs; what it does not offer refused in one line."""

import csv
import json
from dataclasses import replace

import numpy as np
import pytest

from hybrid.cli import main
from hybrid.experiments._compare_outputs import compare_outputs, pooled_table
from hybrid.experiments._datasets import CompareData
from hybrid.virtual import DecayingSinusoid, TipArc, VirtualCatheter
from identification import output_columns
from physics.data import DataError, Dataset

POSE = ("Angle x", "Pos x", "Pos y")


@pytest.fixture(scope="module")
def data():
    cath = VirtualCatheter(seed=3, tip=TipArc())
    runs = [cath.run(DecayingSinusoid(frequency_hz=f, baseline=b), name=f"f{f}_{b}")
            for f, b in ((0.2, "zero"), (0.5, "end"), (0.3, "mid"), (0.4, "zero"))]
    return CompareData(Dataset(runs[:3]), {"id": Dataset(runs[3:])}, name="virtual tip")


def test_every_model_of_every_output_is_scored_per_output(data, tmp_path):
    """The true chain (``backlash+boucwen``, a map per output) beats the ARX of all outputs on each; the table's
    pooled RMSE is the model's own prediction scored after the warm-up window; each network is one of every
    output."""
    result = compare_outputs(data, tmp_path, POSE, preset="tiny", physics=("backlash+boucwen+linear",),
                             networks=("fnn-hib",), peers=("arx",), progress=False)
    with (tmp_path / "compare.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert {r["model"] for r in rows} == {"physics", "fnn-hib", "fnn-hib+physics", "peer:arx"}
    assert {r["output"] for r in rows} == set(POSE) and {r["kind"] for r in rows} == {"physics", "learned", "hybrid",
                                                                                      "peer"}
    table = pooled_table([(r.direction, r.model, r.kind, r.test, r.rmse, r.nrmse, r.n) for r in result.rows], POSE, "id")
    for o in POSE:
        assert table["physics"][o] < 0.5 * table["peer:arx"][o], (o, table)
    run = json.loads((tmp_path / "run.json").read_text())
    assert run["outputs"] == list(POSE) and run["physics_used"] == "backlash+boucwen+maps"
    # the physics row is the physics of every output predicted from the test run's window
    from identification import identify_outputs, predict_outputs

    fit = identify_outputs("backlash+boucwen+linear", list(data.train), POSE, warmup=10)
    test = data.tests["id"][0]
    y = output_columns(test, POSE)
    mine = predict_outputs(fit.series, test.u, y, 10)
    expected = np.sqrt(np.mean((mine - y[10:]) ** 2, axis=0))
    np.testing.assert_allclose([table["physics"][o] for o in POSE], expected, rtol=1e-3)
    assert "| fnn-hib+physics | hybrid |" in (tmp_path / "compare.md").read_text()
    assert (tmp_path / "figures" / "rmse_per_output.png").is_file()
    # the hybrid row or its network alone, chosen on the run held out of both fits (every third of three)
    choice = run["hybrid_choice"]["fnn-hib+physics"]
    assert choice["held_out_runs"] == [str(data.train[1].source)] and set(choice["held_out_rmse"]) == {
        "hybrid", "network alone"}
    lower = min(choice["held_out_rmse"], key=choice["held_out_rmse"].get)
    assert choice["kept"] == ("network alone" if lower == "network alone" else "hybrid")
    if choice["kept"] == "network alone":
        assert all(table["fnn-hib+physics"][o] == table["fnn-hib"][o] for o in POSE)
    assert "## Hybrids or their networks alone" in (tmp_path / "compare.md").read_text()


def test_what_the_comparison_of_several_outputs_does_not_offer_is_refused(data, tmp_path, capsys):
    with pytest.raises(DataError, match="has no output column 'Pos q'"):
        compare_outputs(data, tmp_path, ("Angle x", "Pos q"), preset="tiny", networks=("fnn",))
    still = CompareData(Dataset([replace(t, extra={**t.extra, "Pos x": np.full(t.n, 3.0)}) for t in data.train]),
                        data.tests, name="still")
    with pytest.raises(DataError, match="output 'Pos x' is constant"):
        compare_outputs(still, tmp_path, POSE, preset="tiny", networks=("fnn",))
    with pytest.raises(DataError, match="Unknown peer"):
        compare_outputs(data, tmp_path, POSE, preset="tiny", networks=("fnn",), peers=("sindy",))
    for extra, message in ((["--output", "Angle x,Pos x", "--interval", "0.9"], "calibrates no intervals"),
                           (["--output", "Angle x,Angle x"], "two or more distinct output columns")):
        assert main(["compare", "--data", "virtual", "--preset", "tiny", "--out", str(tmp_path / "c"), *extra]) == 2
        err = capsys.readouterr().err.strip()
        assert message in err and err.count("\n") == 0, err
