"""Every number and every CSV value is checked before work starts (#42).

Rates, durations and counts are bounded by what the machine can hold (the refusal names the flag and
the range); a run's length (duration x rate, or a file's span x rate) is bounded before anything is
allocated; data no model can be identified from are refused in one line or warned about; valid CSV
dialects (quoted numbers, unused text columns) are read; the simulator names a bad seed.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pytest

from hybrid.cli import _options as O
from hybrid.cli._main import main


@pytest.fixture(scope="module")
def files(fitted_linear) -> Path:
    """A 16 s run at 25 Hz and a physics-only model folder fitted on it."""
    return fitted_linear


def columns(files: Path) -> np.ndarray:
    """time, u, y of the run."""
    return np.loadtxt(files / "run.csv", delimiter=",", skiprows=1)[:, :3]


def rows(table: np.ndarray) -> list[list[float]]:
    """The table as Python floats (whose repr is the shortest exact text)."""
    return table.tolist()


def write(path: Path, table: np.ndarray, header: str = "time,u,y") -> Path:
    np.savetxt(path, table, delimiter=",", header=header, comments="", fmt="%.17g")
    return path


def run(argv, capsys) -> tuple[int, str, str]:
    capsys.readouterr()
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    assert "Traceback" not in err
    return rc, out, err


def refused(argv, capsys, *needles: str) -> str:
    """Exit 2 and one line holding every needle."""
    rc, _, err = run(argv, capsys)
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert rc == 2 and len(lines) == 1, (argv, rc, err)
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
    return lines[0]


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


# ------------------------------------------------------------------ flag bounds
@pytest.mark.parametrize("argv", [
    ["simulate", "--rate", "1e308", "--out", "{tmp}/s.csv"],
    ["fit", "{files}/run.csv", "--physics", "linear", "--residual", "none", "--rate", "1e308", "--out", "{tmp}/m"],
    ["export", "linear", "--rate", "1e308", "--out", "{tmp}/e.casadi"],
    ["mpc", "--model", "linear", "--rate", "1e308", "--out", "{tmp}/mpc"],
])
def test_a_rate_beyond_what_a_run_holds_is_refused_naming_the_flag_and_range(files, tmp_path, capsys, argv):
    argv = [a.format(files=files, tmp=tmp_path) for a in argv]
    refused(argv, capsys, "argument --rate", "<= 1e+07")
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize("argv, flag", [
    (["mpc", "--model", "linear", "--duration", "1e9", "--out", "{tmp}/mpc"], "--duration"),
    (["simulate", "--duration", "1e9", "--out", "{tmp}/s.csv"], "--duration"),
    (["train", "{files}/run.csv", "--epochs", "99999999999", "--out", "{tmp}/m.pt"], "--epochs"),
    (["export", "{files}/model", "--controller", "{tmp}/c", "--horizon", "100000", "--out", "{tmp}/e.casadi"],
     "--horizon"),  # was: a 75 GB allocation
    (["simulate", "--qmax", "1e12", "--out", "{tmp}/s.csv"], "--qmax"),
    (["simulate", "--noise", "1e308", "--out", "{tmp}/s.csv"], "--noise"),  # was: "overflowed ... --qmax 3 mm"
    (["mpc", "--model", "linear", "--noise", "1e308", "--out", "{tmp}/mpc"], "--noise"),
    (["export", "{files}/model", "--estimator", "100000000", "--out", "{tmp}/e.casadi"], "--estimator"),  # was:
    (["export", "{files}/model", "--warmup", "100000000", "--out", "{tmp}/e.casadi"], "--warmup"),  # killed, OOM
])
def test_durations_counts_and_amplitudes_are_bounded_naming_the_flag(files, tmp_path, capsys, argv, flag):
    argv = [a.format(files=files, tmp=tmp_path) for a in argv]
    line = refused(argv, capsys, f"argument {flag}", "<=")
    assert "got" in line
    assert not any(tmp_path.iterdir())


def test_mpc_refuses_a_reference_longer_than_memory_before_allocating(tmp_path, capsys):
    refused(["mpc", "--model", "linear", "--duration", "1e5", "--rate", "1000", "--out", tmp_path / "mpc"], capsys,
            "--duration 100000 s at --rate 1000 Hz", "1e+08 samples", f"{O.MAX_SAMPLES:.0e}")


@pytest.mark.parametrize("extra, needles", [
    (["--rate", "1e4", "--duration", "100"], ["--duration 100 s at --rate 10000 Hz", "1e+07 integration steps"]),
    (["--freq", "1e-4"], ["7 cycles of --freq 0.0001 Hz", "raise --freq"]),
    (["--paper-dataset", "--rate", "1e4"], ["the paper dataset's longest run"]),
])
def test_simulate_refuses_a_run_longer_than_memory_before_allocating(tmp_path, capsys, extra, needles):
    refused(["simulate", *extra, "--out", tmp_path / "out"], capsys, *needles, f"{O.MAX_SIMULATED_STEPS:.0e}")
    assert not (tmp_path / "out").exists()


def test_a_csv_rate_giving_too_many_samples_is_refused_before_resampling(files, tmp_path, capsys):
    before = digest(files / "run.csv")
    refused(["fit", files / "run.csv", "--physics", "linear", "--residual", "none", "--rate", "1e7",
             "--out", tmp_path / "m"], capsys, str(files / "run.csv"), "1.6e+08 samples", "--rate", "6.25e+05 Hz")
    assert digest(files / "run.csv") == before and not (tmp_path / "m").exists()


def test_the_simulator_names_a_negative_seed():
    from physics.virtual import DecayingSinusoid, Multisine, RandomSteps, VirtualCatheter

    with pytest.raises(ValueError, match=r"'seed' of VirtualCatheter must be a whole number >= 0.*Got -1"):
        VirtualCatheter(seed=-1).run(DecayingSinusoid(cycles=1))
    with pytest.raises(ValueError, match=r"'seed' of Multisine .* Got -3"):
        Multisine(duration_s=10, seed=-3)
    with pytest.raises(ValueError, match=r"'seed' of RandomSteps .* Got 1.5"):
        RandomSteps(duration_s=10, seed=1.5)
    assert VirtualCatheter(seed=None).run(DecayingSinusoid(cycles=1)).n == VirtualCatheter(seed=np.int64(2)).run(
        DecayingSinusoid(cycles=1)).n


# ------------------------------------------------------------------ data checks
@pytest.mark.parametrize("command", ["fit", "predict", "identify"])
def test_values_beyond_1e150_are_refused_naming_file_column_and_line(files, tmp_path, capsys, command):
    table = columns(files)
    table[5:, 2] *= 1e160  # the whole tail: no outlier among the others, just too large
    bad = write(tmp_path / "huge.csv", table)
    argv = {"fit": ["fit", bad, "--physics", "linear", "--residual", "none", "--out", tmp_path / "m"],
            "predict": ["predict", files / "model", bad, "--out", tmp_path / "p.csv"],
            "identify": ["identify", bad, "--model", "linear", "--out", tmp_path / "f.json"]}[command]
    refused(argv, capsys, str(bad), "line 7", "column 'y'", "1e+150")


@pytest.mark.parametrize("command", ["fit", "identify"])
def test_a_constant_output_is_refused_for_fit_and_identify(files, tmp_path, capsys, command):
    table = columns(files)
    table[:, 2] = 4.2
    flat = write(tmp_path / "flat.csv", table)
    argv = {"fit": ["fit", flat, "--physics", "linear", "--residual", "none", "--out", tmp_path / "m"],
            "identify": ["identify", flat, "--model", "lag+linear", "--out", tmp_path / "f.json"]}[command]
    refused(argv, capsys, "--output column 'y' is constant (4.2)", str(flat))


def test_a_constant_output_is_still_predicted(files, tmp_path, capsys):
    table = columns(files)
    table[:, 2] = 4.2
    rc, _, err = run(["predict", files / "model", write(tmp_path / "flat.csv", table), "--out", tmp_path / "p.csv"],
                     capsys)
    assert rc == 0, err


def test_a_gap_in_the_time_stamps_is_warned_naming_file_and_gap(files, tmp_path, capsys):
    table = columns(files)
    table[200:, 0] += 1000.0
    gap = write(tmp_path / "gap.csv", table)
    rc, _, err = run(["predict", files / "model", gap, "--out", tmp_path / "p.csv"], capsys)
    assert rc == 0, err
    assert f"hyst predict: warning: {gap}: the time stamps jump by 1000 s (from 7.96 s" in err


def test_a_refused_file_with_a_gap_is_still_one_line(files, tmp_path, capsys):
    table = columns(files)
    table[200:, 0] += 1000.0
    table[300, 0] = table[299, 0] - 1.0  # and time running backwards: refused
    bad = write(tmp_path / "gap.csv", table)
    refused(["predict", files / "model", bad, "--out", tmp_path / "p.csv"], capsys, str(bad))


def test_time_in_milliseconds_is_warned(files, tmp_path, capsys):
    table = columns(files)[:100]
    table[:, 0] = np.round(table[:, 0] * 1000)  # 0, 40, 80, ... : milliseconds
    ms = write(tmp_path / "ms.csv", table)
    rc, _, err = run(["identify", ms, "--model", "linear", "--out", tmp_path / "f.json"], capsys)
    assert rc == 0, err
    assert f"warning: {ms}: the time stamps step by 40 (median), a rate of 0.025 Hz" in err
    assert "milliseconds, divide the time column by 1000 (the data would then be 25 Hz)" in err


def test_seconds_at_a_normal_rate_give_no_warning(files, tmp_path, capsys):
    rc, _, err = run(["predict", files / "model", files / "run.csv", "--out", tmp_path / "p.csv"], capsys)
    assert rc == 0 and "warning" not in err


def test_one_data_row_is_named_as_one_sample(files, tmp_path, capsys):
    one = tmp_path / "one.csv"
    one.write_text("time,u,y\n0,1,2\n")
    for argv in (["fit", one, "--physics", "linear", "--residual", "none", "--out", tmp_path / "m"],
                 ["predict", files / "model", one, "--out", tmp_path / "p.csv"]):
        line = refused(argv, capsys, str(one), "one data row", "at least two")
        assert "never increase" not in line


# ------------------------------------------------------------------ CSV dialects
def predictions(files, path, tmp_path, capsys) -> np.ndarray:
    out = tmp_path / f"{path.stem}_pred.csv"
    rc, _, err = run(["predict", files / "model", path, "--out", out], capsys)
    assert rc == 0, err
    return np.loadtxt(out, delimiter=",", skiprows=1)


def test_quoted_numbers_and_unused_text_columns_are_read(files, tmp_path, capsys):
    table = columns(files)
    plain = predictions(files, files / "run.csv", tmp_path, capsys)
    quoted = tmp_path / "quoted.csv"
    quoted.write_text('"time","u","y"\n' + "".join(f'"{t!r}","{u!r}","{y!r}"\n' for t, u, y in rows(table)))
    texts = tmp_path / "texts.csv"
    texts.write_text("operator,time,u,y,note\n" + "".join(
        f'ana,{t!r},{u!r},{y!r},{"" if i % 3 else chr(34) + "moved, fast" + chr(34)}\n'
        for i, (t, u, y) in enumerate(rows(table))))
    before = {p: digest(p) for p in (quoted, texts)}
    np.testing.assert_allclose(predictions(files, quoted, tmp_path, capsys)[:, 3], plain[:, 3], rtol=1e-12)
    np.testing.assert_allclose(predictions(files, texts, tmp_path, capsys)[:, 3], plain[:, 3], rtol=1e-12)
    assert {p: digest(p) for p in (quoted, texts)} == before


def test_a_text_cell_in_a_used_column_is_still_named(files, tmp_path, capsys):
    table = columns(files)
    bad = tmp_path / "bad.csv"
    lines = [f"{t!r},{u!r},moved,x" if i == 3 else f"{t!r},{u!r},{y!r},x" for i, (t, u, y) in enumerate(rows(table))]
    bad.write_text("time,u,y,note\n" + "\n".join(lines) + "\n")
    refused(["predict", files / "model", bad, "--out", tmp_path / "p.csv"], capsys, str(bad), "line 5",
            "column 'y'", "'moved' is not a number")


@pytest.mark.parametrize("how, needles", [
    ("no header", ["has no header line", "'0,", "naming the 3 columns"]),  # was: "no column 'time'. Available
    ("comment", ["starts with a comment line", "'# logged by rig 2'", "delete the lines above"]),  # columns: ['0', ..."
    ("spaces", ["separates its columns with spaces"]),  # was: "no column 'time'. Available columns: ['time u y']"
    ("case", ["no column 'time' (did you mean 'Time'? names are case-sensitive)"]),
])
def test_a_file_without_its_header_first_is_named_so(files, tmp_path, capsys, how, needles):
    table = columns(files)
    header = {"no header": "", "comment": "# logged by rig 2\ntime,u,y", "spaces": "time,u,y", "case": "Time,u,y"}
    path = write(tmp_path / "run.csv", table, header=header[how])
    if how == "no header":
        path.write_text(path.read_text().lstrip("\n"))
    if how == "spaces":
        path.write_text(path.read_text().replace(",", " "))
    refused(["fit", path, "--physics", "linear", "--residual", "none", "--out", tmp_path / "m"], capsys, str(path),
            *needles)


def test_unix_time_stamps_are_read_at_the_rate_they_were_taken(files, tmp_path, capsys):
    """1.7e9 s + k / 25: the float64 steps are 0.04 +/- 2.4e-7 s; the model runs at 25 Hz (was 25.00002384,
    and `hyst mpc --rate 25` was then refused)."""
    table = columns(files)
    table[:, 0] += 1.7e9
    unix = write(tmp_path / "unix.csv", table)
    rc, out, err = run(["fit", unix, "--physics", "linear", "--residual", "none", "--no-progress",
                        "--out", tmp_path / "m"], capsys)
    assert rc == 0, err
    assert "model rate 25 Hz" in out
    import json

    assert json.loads((tmp_path / "m" / "physics.json").read_text())["dt"] == 0.04
    rc, _, err = run(["mpc", "--model", tmp_path / "m", "--rate", "25", "--duration", "1", "--no-figures",
                      "--out", tmp_path / "mpc"], capsys)
    assert rc == 0, err


@pytest.mark.parametrize("argv, needles", [
    (["fit", "{run}", "{run}", "--physics", "linear", "--residual", "none", "--out", "{tmp}/m"],
     ["run.csv is given twice"]),
    (["fit", "{run}", "--test", "{run}", "--physics", "linear", "--residual", "none", "--out", "{tmp}/m"],
     ["run.csv is both a training run and a held-out run (--test)"]),
    (["identify", "{run}", "--test", "{run}", "--model", "linear", "--out", "{tmp}/f.json"],
     ["run.csv is both a training run and a held-out run"]),
    (["train", "{run}", "{run}", "--model", "fnn", "--out", "{tmp}/m.pt"], ["run.csv is given twice"]),
    (["fit", "", "--physics", "linear", "--out", "{tmp}/m"], ["path is empty ('')"]),  # was: ". is a folder"
])
def test_a_run_given_twice_is_refused(files, tmp_path, capsys, argv, needles):
    """It counted twice in the fit and in the intervals' calibration (two 'conditions' that were one run)."""
    argv = [a.format(run=files / "run.csv", tmp=tmp_path) for a in argv]
    refused(argv, capsys, *needles)
    assert not any(tmp_path.iterdir())


def test_residual_auto_leaves_out_networks_longer_than_the_runs(files, tmp_path, capsys):
    """Runs of 30 samples, shorter than FNN-HIB's and the LSTM's history of 50: auto keeps the physics alone
    (was: refused, advising 'a shorter buffer/seq_len', which no flag sets)."""
    table = columns(files)
    runs = [write(tmp_path / f"short{k}.csv", table[30 * k:30 * (k + 1)]) for k in range(4)]
    rc, out, err = run(["fit", *runs, "--physics", "linear", "--residual", "auto", "--warmup", "5", "--no-progress",
                        "--out", tmp_path / "m"], capsys)
    assert rc == 0, err
    assert "residual none" in out


def test_a_run_too_short_for_discover_is_named(files, tmp_path, capsys):
    short = write(tmp_path / "short.csv", columns(files)[:12])
    refused(["discover", short, "--max-steps", "1", "--no-figures", "--out", tmp_path / "d"], capsys,
            f"Trajectory 0 ({short}) needs", ">= 20 samples", "got shapes (12,)")  # was: "Trajectory 0" alone


@pytest.mark.parametrize("device", ["/dev/null"])  # /dev/stdin: a regular file under "< file"
def test_a_device_given_as_data_is_not_said_missing(files, tmp_path, capsys, device):
    """/dev/null exists: it was 'Csv file /dev/null does not exist. Check the path.'"""
    if not Path(device).exists():
        pytest.skip(f"no {device} here")
    refused(["predict", files / "model", device, "--out", tmp_path / "p.csv"], capsys,
            f"{device} is not a regular file", "save the data to a file")
