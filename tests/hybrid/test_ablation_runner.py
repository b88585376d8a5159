"""Ablation sweeps on a Dask LocalCluster (2 worker processes): results, resume, failures, CLI.

Scheduling tests use the torch-free ``model = "dummy"`` run type; one test trains a real
(tiny) FNN-HIB on a worker.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import math

import pytest

from hybrid.cli._main import main
from hybrid.experiments.ablation import AblationConfig, config_path, run_ablation

DATA = {"frequencies": [0.4, 0.5], "tests": [0.45], "baselines": ["mid", "end"]}
TOML = """\
name = "dummy"
[data]
frequencies = [0.4, 0.5]
tests = [0.45]
baselines = ["mid", "end"]
[grid]
model = "dummy"
buffer = {buffers}
seed = [0, 1]
"""


@pytest.fixture(scope="module")
def scheduler():
    """One local cluster for the module, reached by address: the --scheduler code path."""
    from dask.distributed import LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0") as cluster:
        yield cluster.scheduler_address


def dummy(buffers=(5, 10)):
    return AblationConfig.from_dict({"name": "dummy", "data": DATA,
                                     "grid": {"model": "dummy", "buffer": list(buffers), "seed": [0, 1]}})


def read_csv(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_sweep_writes_runs_table_and_figures(scheduler, tmp_path):
    cfg = dummy()
    result = run_ablation(cfg, tmp_path, scheduler=scheduler, progress=False)
    ids = [s.run_id for s in cfg.runs()]
    assert sorted(result.ran) == sorted(ids) and not result.skipped and not result.failed
    assert sorted(p.name for p in (tmp_path / "runs").iterdir()) == sorted(f"{i}.json" for i in ids)
    record = json.loads((tmp_path / "runs" / f"{ids[0]}.json").read_text())
    assert record["settings"]["buffer"] == 5 and record["settings"]["seed"] == 0
    prov = record["provenance"]
    assert prov["package"] == "hysteresis-hybrid" and "git_commit" in prov and prov["seed"] == 0
    assert prov["data"]["source"] == "virtual" and len(prov["data"]["digest"]) == 64
    rows = read_csv(tmp_path / "results.csv")
    assert [r["run_id"] for r in rows] == ids
    assert {"model", "buffer", "seed", "n_train", "rmse", "nrmse", "rmse_test_f0.45_mid", "fit_seconds"} <= set(rows[0])
    assert "seq_len" not in rows[0]  # applies to no run here
    assert all(r["status"] == "ok" and float(r["rmse"]) > 0 for r in rows)
    assert [p.name for p in result.figures] == ["rmse_vs_buffer.png"] and result.figures[0].stat().st_size > 0
    summary = json.loads((tmp_path / "ablation.json").read_text())
    assert summary["runs"] == ids and summary["failed"] == []


def test_rerun_skips_finished_runs_and_reruns_a_deleted_one(scheduler, tmp_path):
    cfg = dummy()
    first = run_ablation(cfg, tmp_path, scheduler=scheduler, progress=False, figures=False)
    second = run_ablation(cfg, tmp_path, scheduler=scheduler, progress=False, figures=False)
    assert second.ran == [] and len(second.skipped) == 4
    assert second.table == first.table
    victim = cfg.runs()[2].run_id
    (tmp_path / "runs" / f"{victim}.json").unlink()
    third = run_ablation(cfg, tmp_path, scheduler=scheduler, progress=False, figures=False)
    assert third.ran == [victim] and len(third.skipped) == 3
    strip = [{k: v for k, v in row.items() if k != "fit_seconds"} for row in third.table]
    assert strip == [{k: v for k, v in row.items() if k != "fit_seconds"} for row in first.table]


def test_a_failing_run_is_recorded_and_the_others_finish(scheduler, tmp_path):
    cfg = dummy(buffers=(5, 100_000))  # a buffer longer than every trajectory
    result = run_ablation(cfg, tmp_path, scheduler=scheduler, progress=False)
    bad = [s.run_id for s in cfg.runs() if s.settings["buffer"] == 100_000]
    assert sorted(result.failed) == sorted(bad) and len(result.ran) == 2
    error = json.loads((tmp_path / "runs" / f"{bad[0]}.error.json").read_text())
    assert error["status"] == "failed" and error["settings"]["buffer"] == 100_000
    assert error["error"]["type"] == "DataError" and "buffer = 100000" in error["error"]["message"]
    assert "Traceback" in error["error"]["traceback"] and "in execute_run" in error["error"]["traceback"]
    rows = {r["run_id"]: r for r in read_csv(tmp_path / "results.csv")}
    assert [rows[i]["status"] for i in bad] == ["failed", "failed"] and "buffer = 100000" in rows[bad[0]]["error"]
    assert sum(r["status"] == "ok" for r in rows.values()) == 2
    # a rerun retries the failed runs only
    again = run_ablation(cfg, tmp_path, scheduler=scheduler, progress=False, figures=False)
    assert sorted(again.failed) == sorted(bad) and again.ran == [] and len(again.skipped) == 2


def test_one_real_learned_run_on_a_worker(scheduler, tmp_path):
    cfg = AblationConfig.from_toml(config_path("tiny"))
    cfg = dataclasses.replace(cfg, grid={**cfg.grid, "buffer": (5,), "seed": (0,)})
    result = run_ablation(cfg, tmp_path, scheduler=scheduler, progress=False, figures=False)
    assert len(result.ran) == 1 and not result.failed
    (row,) = result.table
    assert row["kind"] == "learned" and row["model"] == "fnn-hib" and row["unit"] == "deg"
    assert math.isfinite(row["rmse"]) and row["fit_seconds"] > 0
    record = json.loads((tmp_path / "runs" / f"{row['run_id']}.json").read_text())
    assert record["worker"]["torch"] and record["settings"]["epochs"] == 2


def test_the_seeds_of_a_grid_point_train_as_one_pass_each_as_it_would_alone(scheduler, tmp_path):
    """Runs that differ only in their seed (an MLP on all the training runs) are one task whose networks
    train as one batched pass (issue 54 item 4): each record scores what the run gets alone, to float
    tolerance, and names the runs it shared the pass with; the grid's other axes stay tasks of their own."""
    from hybrid.experiments.ablation import execute_run
    from hybrid.experiments.ablation._runner import seed_groups

    cfg = AblationConfig.from_toml(config_path("tiny"))  # fnn-hib, buffers 5 and 10, seeds 0 and 1
    specs = cfg.runs()
    tasks = seed_groups(specs)
    assert [sorted(s.settings["seed"] for s in t) for t in tasks] == [[0, 1], [0, 1]]
    assert [{s.settings["buffer"] for s in t} for t in tasks] == [{5}, {10}]
    assert [len(t) for t in seed_groups(dummy().runs())] == [1, 1, 1, 1]  # not a network: alone
    result = run_ablation(cfg, tmp_path, scheduler=scheduler, progress=False, figures=False)
    assert sorted(result.ran) == sorted(s.run_id for s in specs) and not result.failed
    for task in tasks:
        for spec in task:
            record = json.loads((tmp_path / "runs" / f"{spec.run_id}.json").read_text())
            assert record["trained_with"] == [o.run_id for o in task if o is not spec]
            alone = execute_run(spec)
            assert record["metrics"]["rmse"] == pytest.approx(alone["metrics"]["rmse"], rel=1e-4)


def test_cli_exit_status_counts_failures(scheduler, tmp_path, capsys):
    path = tmp_path / "a.toml"
    path.write_text(TOML.format(buffers="[5, 100000]"))
    rc = main(["ablate", str(path), "--out", str(tmp_path / "out"), "--scheduler", scheduler, "--no-progress",
               "--no-figures"])
    out, err = capsys.readouterr()
    assert rc == 1
    assert "4 runs: 2 ran, 0 already done, 2 failed" in out
    assert "2 of 4 runs failed" in err and "Run the same command again to retry them" in err


def test_cli_bad_input_is_one_line_exit_2(tmp_path, capsys):
    path = tmp_path / "a.toml"
    path.write_text(TOML.format(buffers="[5, 0]"))
    assert main(["ablate", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "[grid] buffer must be an integer >= 1" in err
    assert main(["ablate", str(path), "--out", str(tmp_path), "--workers", "2", "--scheduler", "tcp://x:1"]) == 2


def test_cli_default_local_cluster(tmp_path, capsys):
    """No --scheduler: the command starts (and closes) its own LocalCluster."""
    path = tmp_path / "a.toml"
    path.write_text(TOML.format(buffers="[5]"))
    assert main(["ablate", str(path), "--out", str(tmp_path / "out"), "--workers", "2", "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "2 runs: 2 ran, 0 already done, 0 failed" in out
    assert len(read_csv(tmp_path / "out" / "results.csv")) == 2
