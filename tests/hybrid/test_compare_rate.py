"""``hyst compare --rate`` and ``--jobs`` (#43): a folder recorded at 500 Hz compared at the rate the
model will run at, and the physics selection's folds fitted in worker processes."""

import argparse
import json

import numpy as np
import pytest

from hybrid.cli._main import main

RAW_HZ = 500.0
DURATION_S = 6.0  # 3,001 samples at 500 Hz, 301 at 50 Hz


def _write_folder(folder, runs=((0.4, "train"), (0.7, "train"), (0.55, "test"))):
    """``train/`` and ``test/`` CSVs at 500 Hz: a lagged, scaled sinusoid with a little noise."""
    rng = np.random.default_rng(0)
    t = np.arange(int(DURATION_S * RAW_HZ) + 1) / RAW_HZ
    for i, (f, part) in enumerate(runs):
        u = 2.0 + 1.5 * np.sin(2 * np.pi * f * t)
        lagged = np.empty_like(u)
        lagged[0] = u[0]
        a = np.exp(-1 / (RAW_HZ * 0.1))  # a 0.1 s first-order lag
        for k in range(1, u.size):
            lagged[k] = a * lagged[k - 1] + (1 - a) * u[k]
        y = 10.0 * lagged + 3.0 + 0.05 * rng.standard_normal(u.size)
        (folder / part).mkdir(parents=True, exist_ok=True)
        np.savetxt(folder / part / f"run{i}.csv", np.column_stack([t, u, y]), delimiter=",",
                   header="time,u,y", comments="", fmt="%.9g")
    return folder


def _args(data, rate):
    return argparse.Namespace(data=str(data), rate=rate, seed=0, preset="tiny")


def test_a_folder_is_loaded_at_its_own_rate_or_resampled_to_rate(tmp_path):
    from hybrid.cli._commands.compare import _data_at_rate

    folder = _write_folder(tmp_path / "lab")
    own = _data_at_rate(_args(folder, "auto"))
    assert own.train[0].dt == pytest.approx(1 / RAW_HZ) and own.train[0].n == 3001
    data = _data_at_rate(_args(folder, 50.0))
    runs = [*data.train, *data.tests["id"], *(t for d in data.subsets.values() for t in d)]
    assert all(t.dt == pytest.approx(0.02) and t.n == 301 and t.meta["rate_hz"] == 50.0 for t in runs)
    # down-sampled with its anti-aliasing filter: the slow signal is kept
    np.testing.assert_allclose(data.train[0].u, np.interp(data.train[0].time, own.train[0].time, own.train[0].u),
                               atol=0.02)


def test_compare_a_500_hz_folder_at_rate_50(tmp_path, capsys):
    folder = _write_folder(tmp_path / "lab")
    out = tmp_path / "cmp"
    assert main(["compare", "--data", str(folder), "--rate", "50", "--preset", "tiny", "--physics", "linear",
                 "--networks", "fnn", "--peers", "none", "--out", str(out), "--no-progress", "--no-figures"]) == 0
    assert "at 50 Hz" in capsys.readouterr().out
    run = json.loads((out / "run.json").read_text())
    assert run["rate_hz"] == 50.0
    assert run["physics_used"]["all/forward"] == "linear"
    rows = (out / "compare.csv").read_text().splitlines()
    assert any(",physics,physics,id:all," in r for r in rows)


@pytest.mark.parametrize("rate", ["0", "-50", "fifty", "nan", "inf", "1e99"])
def test_a_bad_rate_is_refused_in_one_line(tmp_path, capsys, rate):
    assert main(["compare", "--data", str(tmp_path), "--rate", rate, "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--rate" in err and "auto" in err


def test_a_rate_for_the_virtual_data_is_refused_in_one_line(tmp_path, capsys):
    assert main(["compare", "--rate", "50", "--preset", "tiny", "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "virtual data is simulated at 25 Hz" in err


def test_a_bad_jobs_count_is_refused_in_one_line(tmp_path, capsys):
    assert main(["compare", "--jobs", "0", "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--jobs" in err


def test_jobs_reaches_the_physics_selection(tmp_path, monkeypatch):
    """``--jobs N`` goes to compare's physics policy (``Workers(n_jobs=N)``) and from there to
    ``select_physics(workers=...)``."""
    import identification.discovery._policy
    from identification.discovery import Workers
    from hybrid.cli._commands.compare import _data_at_rate
    from hybrid.experiments import _compare

    seen = {}

    def fake_compare(data, out, **kwargs):
        seen.update(kwargs)
        out = tmp_path / "cmp"
        out.mkdir()
        (out / "compare.md").write_text("")
        return _compare.CompareResult(out, [], {}, 0.0)

    monkeypatch.setattr(_compare, "compare", fake_compare)
    folder = _write_folder(tmp_path / "lab")
    assert main(["compare", "--data", str(folder), "--jobs", "2", "--out", str(tmp_path / "cmp"),
                 "--no-progress"]) == 0
    assert seen["physics"].select_options["workers"] == Workers(n_jobs=2)

    def fake_select(train, **kwargs):
        seen["select"] = kwargs
        raise identification.IdentificationError("stop here")

    monkeypatch.setattr(identification.discovery._policy, "select_physics", fake_select)  # the policy's selection
    job = _compare._Job(cfg={}, networks=(), seed=0, progress=False,
                        policy=_compare.compare_policy(_compare.AUTO, Workers(n_jobs=2)))
    train = _data_at_rate(_args(folder, 50.0)).train
    _compare._physics_fit(job, train, "all/forward")
    assert seen["select"]["workers"].n_jobs == 2
    assert job.physics_selection["all/forward"] == {"error": "stop here", "fallback": list(_compare.PHYSICS)}
    assert job.candidates["all"][0] == list(_compare.PHYSICS)  # the specs tried where the selection failed
