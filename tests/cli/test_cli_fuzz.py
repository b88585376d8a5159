"""Fuzzing every `hyst` sub-command with bad input, as a hurried user would.

Each case runs the CLI's ``main`` in-process on generated bad input and checks the contract:
exit status 2, one line on stderr naming the flag or the file, no traceback, the input files
byte-identical and nothing written. The option values are drawn from outside the domain each
option's type declares (read from the parser itself, so a new option is fuzzed without being
listed here); the files are valid ones with one defect each. A few cases run `hyst` as a process.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hybrid.cli import _options as O
from hybrid.cli._main import COMMANDS, build_parser, main
from hybrid.experiments.ablation import config_path

FUZZ = settings(max_examples=40, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


# ------------------------------------------------------------------ the inputs
@pytest.fixture(scope="module")
def files(tmp_path_factory) -> Path:
    """One good file of each kind a command reads: a CSV, a fit, a checkpoint, an exported model, a config."""
    root = tmp_path_factory.mktemp("inputs")
    assert main(["simulate", "--duration", "16", "--out", str(root / "run.csv")]) == 0
    assert main(["identify", str(root / "run.csv"), "--model", "linear", "--out", str(root / "fit.json")]) == 0
    assert main(["export", str(root / "fit.json"), "--out", str(root / "step.casadi")]) == 0
    assert main(["train", str(root / "run.csv"), "--model", "fnn", "--epochs", "1", "--validation", "0",
                 "--out", str(root / "m.pt")]) == 0
    shutil.copy(config_path("tiny"), root / "grid.toml")
    return root


def digest(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def check_refused(argv: list[str], capsys, names: list[str], watched: list[Path]) -> str:
    """The contract: exit 2, one line naming one of ``names``, no traceback, ``watched`` untouched."""
    before = [digest(w) for w in watched]
    capsys.readouterr()
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert rc == 2, (argv, rc, err)
    assert len(lines) == 1 and lines[0].startswith("hyst"), (argv, err)
    assert "Traceback" not in err
    assert any(n in lines[0] for n in names), (argv, names, lines[0])
    assert [digest(w) for w in watched] == before, argv
    return lines[0]


# ------------------------------------------------- options outside their domain
def _bad_values(kind) -> st.SearchStrategy[str]:
    """Text an option of type ``kind`` must refuse."""
    text = st.sampled_from(["", "abc", "1e", "--", "0x10", "½", "1,5", "None"])
    nonfinite = st.sampled_from(["nan", "inf", "-inf", "NaN", "1e400"])
    if kind in (O.POSITIVE_INT, O.NONNEGATIVE_INT, O.SEED):
        low = {O.POSITIVE_INT: 1, O.NONNEGATIVE_INT: 0, O.SEED: 0}[kind]
        ints = st.integers(max_value=low - 1).map(str)
        fractional = st.floats(0.1, 1e6).filter(lambda v: v != int(v)).map(repr)
        extra = st.integers(min_value=2**32).map(str) if kind is O.SEED else st.nothing()
        return st.one_of(ints, fractional, text, nonfinite, extra)
    if kind in (O.POSITIVE_FLOAT, O.NONNEGATIVE_FLOAT, O.RATE_OR_AUTO):
        negative = st.floats(max_value=-1e-300, allow_nan=False, allow_infinity=False).map(repr)
        return st.one_of(negative, st.just("0") if kind is not O.NONNEGATIVE_FLOAT else st.nothing(), text, nonfinite)
    if kind in (O.FRACTION, O.validation_fraction, O.open_fraction):
        outside = st.one_of(st.floats(max_value=-1e-9, allow_nan=False, allow_infinity=False),
                            st.floats(min_value=1.0000001, allow_nan=False, allow_infinity=False)).map(repr)
        edges = st.sampled_from(["1"] + (["0"] if kind is O.open_fraction else []))
        return st.one_of(outside, edges, text, nonfinite)
    raise AssertionError(f"no bad values for {kind}")


def typed_options() -> list[tuple[str, str, object]]:
    """(command, flag, type) of every option declared with one of the checked number types."""
    checked = (O.POSITIVE_INT, O.NONNEGATIVE_INT, O.SEED, O.POSITIVE_FLOAT, O.NONNEGATIVE_FLOAT, O.FRACTION,
               O.validation_fraction, O.open_fraction, O.RATE_OR_AUTO)
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    found = []
    for command, parser in sub.choices.items():
        for action in parser._actions:
            if action.option_strings and action.type in checked:
                found.append((command, action.option_strings[0], action.type))
    return found


def test_every_numeric_option_is_typed():
    """Every int/float option of every command is one of the checked types (so it is fuzzed below)."""
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    assert set(sub.choices) == set(COMMANDS)
    raw = [(c, a.option_strings[0]) for c, p in sub.choices.items() for a in p._actions
           if a.type in (int, float)]
    assert raw == []
    assert len(typed_options()) >= 25


def base_argv(command: str, files: Path, out: Path) -> list[str]:
    """A command line that would run: the positionals and required options, --out inside ``out``."""
    return {
        "simulate": ["simulate", "--out", out / "s.csv"],
        "identify": ["identify", files / "run.csv", "--model", "linear", "--out", out / "f.json"],
        "train": ["train", files / "run.csv", "--model", "fnn", "--out", out / "m.pt"],
        "predict": ["predict", files / "m.pt", files / "run.csv", "--out", out / "p.csv"],
        "reproduce": ["reproduce", "--out", out / "r"],
        "compare": ["compare", "--out", out / "c"],
        "discover": ["discover", files / "run.csv", "--out", out / "d"],
        "fit": ["fit", files / "run.csv", "--physics", "linear", "--residual", "none", "--out", out / "m"],
        "export": ["export", files / "fit.json", "--out", out / "o.casadi"],
        "mpc": ["mpc", "--model", files / "fit.json", "--out", out / "mpc"],
        "ablate": ["ablate", files / "grid.toml", "--out", out / "a"],
    }[command]


@pytest.mark.parametrize("command", COMMANDS)
@FUZZ
@given(data=st.data())
def test_an_option_outside_its_domain_is_refused_naming_the_flag(files, tmp_path, capsys, command, data):
    options = [(flag, kind) for c, flag, kind in typed_options() if c == command]
    if not options:
        pytest.skip(f"{command} has no numeric options")
    flag, kind = data.draw(st.sampled_from(options), label="option")
    value = data.draw(_bad_values(kind), label="value")
    out = tmp_path / "out"
    out.mkdir(exist_ok=True)
    line = check_refused([*base_argv(command, files, out), f"{flag}={value}"], capsys, [f"argument {flag}"],
                         [files, out])
    assert f"hyst {command}: error: argument {flag}:" in line
    assert not any(out.iterdir())


@pytest.mark.parametrize("command", COMMANDS)
@FUZZ
@given(data=st.data())
def test_unknown_flags_choices_and_missing_arguments_are_one_line(files, tmp_path, capsys, command, data):
    out = tmp_path / "out"
    out.mkdir(exist_ok=True)
    argv = base_argv(command, files, out)
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction)).choices[command]
    choices = [(a.option_strings[0], a.choices) for a in sub._actions if a.option_strings and a.choices]
    how = data.draw(st.sampled_from(["unknown", "choice", "no --out"] if choices else ["unknown", "no --out"]))
    if how == "unknown":
        flag = "--" + data.draw(st.from_regex(r"[a-z][a-z-]{2,12}", fullmatch=True))
        known = {s for a in sub._actions for s in a.option_strings}
        if any(k.startswith(flag) for k in known):  # argparse accepts unique prefixes
            return
        line = check_refused([*argv, flag], capsys, [flag], [files, out])
    elif how == "choice":
        flag, allowed = data.draw(st.sampled_from(choices))
        value = data.draw(st.text(st.characters(codec="ascii", categories=["L", "N"]), min_size=1, max_size=8)
                          .filter(lambda v: v not in allowed))
        line = check_refused([*argv, flag, value], capsys, [flag], [files, out])
    else:
        i = argv.index("--out")
        line = check_refused(argv[:i] + argv[i + 2:], capsys, ["--out"], [files, out])
    assert "(see 'hyst " in line


# ---------------------------------------------------------- CSV files with one defect
def _mutate_csv(text: str, how: str, row: int, token: str) -> bytes:
    lines = text.splitlines()
    r = 1 + row % (len(lines) - 1)
    cells = lines[r].split(",")
    if how == "cell":  # a bad value in the u or y column
        cells[1 + row % 2] = token
        lines[r] = ",".join(cells)
    elif how == "extra cell":
        lines[r] += ",1"
    elif how == "missing cell":
        lines[r] = ",".join(cells[:-1])
    elif how == "no column":
        lines[0] = lines[0].replace(",y,", ",angle,")
    elif how == "semicolons":
        lines = [ln.replace(",", ";") for ln in lines]
    elif how == "header only":
        lines = lines[:1]
    elif how == "time backwards":  # without resampling only; resampled: a glitch in time
        cells[0] = "-1e30"
        lines[r] = ",".join(cells)
    data = ("\n".join(lines) + "\n").encode()
    if how == "latin-1":
        return data.replace(b"\n", "\n# \xe9\n".encode("latin-1"), 1)
    if how == "utf-16":
        return data.decode().encode("utf-16")
    if how == "empty":
        return b""
    return data


CSV_DEFECTS = ["cell", "extra cell", "missing cell", "no column", "semicolons", "header only", "time backwards",
               "latin-1", "utf-16", "empty"]
BAD_TOKENS = ["", "abc", "nan", "inf", "-inf", "1e30", "-1e300", "1..2", "0x1f", "--"]


@pytest.mark.parametrize("command", ["identify", "train", "predict", "discover", "fit", "identify --test"])
@FUZZ
@given(how=st.sampled_from(CSV_DEFECTS), row=st.integers(0, 10**6), token=st.sampled_from(BAD_TOKENS))
def test_a_csv_with_one_defect_is_refused_naming_the_file(files, tmp_path, capsys, command, how, row, token):
    bad_dir = tmp_path / "bad"
    bad_dir.mkdir(exist_ok=True)
    bad = bad_dir / "bad run.csv"
    bad.write_bytes(_mutate_csv((files / "run.csv").read_text(), how, row, token))
    out = tmp_path / "out"
    out.mkdir(exist_ok=True)
    argv = {"identify": ["identify", bad, "--model", "linear", "--out", out / "f.json"],
            "identify --test": ["identify", files / "run.csv", "--test", bad, "--model", "linear",
                                "--out", out / "f.json"],
            "train": ["train", bad, "--model", "fnn", "--epochs", "1", "--out", out / "m.pt"],
            "predict": ["predict", files / "m.pt", bad, "--out", out / "p.csv"],
            "discover": ["discover", bad, "--out", out / "d"],
            "fit": ["fit", bad, "--physics", "linear", "--residual", "none", "--out", out / "m"]}[command]
    capsys.readouterr()
    check_refused(argv, capsys, [str(bad)], [files, bad_dir])
    assert not any(out.iterdir())


@pytest.mark.parametrize("what", ["missing", "folder"])
def test_a_missing_file_or_a_folder_is_named(files, tmp_path, capsys, what):
    path = tmp_path / "missing.csv" if what == "missing" else tmp_path
    for argv in (["identify", path, "--out", tmp_path / "f.json"],
                 ["predict", files / "m.pt", path, "--out", tmp_path / "p.csv"],
                 ["ablate", path, "--out", tmp_path / "a"],
                 ["mpc", "--model", "linear", "--reference", path, "--out", tmp_path / "m"]):
        check_refused(argv, capsys, [str(path)], [files])


# ------------------------------------------------------- saved models with one defect
@FUZZ
@given(cut=st.floats(0.0, 0.999))
def test_a_truncated_checkpoint_or_sidecar_is_named(files, tmp_path, capsys, cut):
    for name in ("m.pt", "m.json"):
        for suffix in (".pt", ".json"):
            shutil.copy(files / f"m{suffix}", tmp_path / f"m{suffix}")
        data = (files / name).read_bytes()
        (tmp_path / name).write_bytes(data[:int(cut * len(data))])
        check_refused(["predict", tmp_path / "m.pt", files / "run.csv", "--out", tmp_path / "p.csv"], capsys,
                      [str(tmp_path / name)], [files])
        assert not (tmp_path / "p.csv").exists()


@FUZZ
@given(cut=st.floats(0.0, 0.999), junk=st.binary(max_size=40))
def test_a_damaged_casadi_file_is_named(files, tmp_path, capsys, cut, junk):
    for suffix in (".casadi", ".casadi.json"):
        shutil.copy(files / f"step{suffix}", tmp_path / f"step{suffix}")
    data = (files / "step.casadi").read_bytes()
    (tmp_path / "step.casadi").write_bytes(data[:int(cut * len(data))] + junk)
    for argv in (["mpc", "--model", tmp_path / "step.casadi", "--out", tmp_path / "mpc"],
                 ["export", tmp_path / "step.casadi", "--out", tmp_path / "again.casadi"]):
        check_refused(argv, capsys, [str(tmp_path / "step.casadi")], [files])


JSON_VALUES = st.one_of(st.none(), st.booleans(), st.text(max_size=5), st.lists(st.integers(), max_size=2),
                        st.sampled_from([float("nan"), float("inf"), -float("inf")]), st.just({}))


@FUZZ
@given(where=st.sampled_from(["parameters", "series.parameters", "series.dt", "model", "series.blocks"]),
       value=JSON_VALUES, drop=st.booleans())
def test_a_hand_edited_fit_is_named(files, tmp_path, capsys, where, value, drop):
    info = json.loads((files / "fit.json").read_text())
    holder = info["series"] if where.startswith("series.") else info
    key = where.split(".")[-1]
    if where.endswith("parameters"):
        holder, key = holder[key], "linear.gain"
    if drop:
        holder.pop(key)
    else:
        holder[key] = value
    fit = tmp_path / "fit.json"
    fit.write_text(json.dumps(info))
    capsys.readouterr()
    rc = main(["export", str(fit), "--out", str(tmp_path / "o.casadi")])
    err = capsys.readouterr().err
    if rc == 0:  # the edit left a valid fit (the spec is only read when 'series' is absent, ...)
        assert where in ("model",) and err == ""
        return
    check_refused(["export", fit, "--out", tmp_path / "o.casadi"], capsys, [str(fit)], [files])


REFERENCE_DEFECTS = {
    "not a number": lambda rng, n: "\n".join(["40"] * n + [rng]),
    "no reference column": lambda rng, n: "time,angle\n" + "\n".join(f"{i},40" for i in range(n)),
    "semicolon table without it": lambda rng, n: "time;angle\n" + "\n".join(f"{i};40" for i in range(n)),
    "latin-1": lambda rng, n: "reference\n40\n" + rng + "\u00e9",
    "one angle": lambda rng, n: "reference\n40",
    "empty": lambda rng, n: "",
    "non-finite": lambda rng, n: "\n".join(["40"] * n + ["inf"]),
}


@FUZZ
@given(how=st.sampled_from(sorted(REFERENCE_DEFECTS)), n=st.integers(1, 30),
       junk=st.text(st.characters(codec="ascii", categories=["L", "P"]), min_size=1, max_size=6))
def test_a_bad_reference_file_is_named(files, tmp_path, capsys, how, n, junk):
    ref = tmp_path / "ref.csv"
    text = REFERENCE_DEFECTS[how](junk, n)
    ref.write_bytes(text.encode("latin-1" if how == "latin-1" else "utf-8"))
    check_refused(["mpc", "--model", files / "fit.json", "--reference", ref, "--horizon", "1",
                   "--out", tmp_path / "mpc"], capsys, [str(ref)], [files])
    assert not (tmp_path / "mpc").exists()


# ------------------------------------------------------------- as a process
@pytest.mark.parametrize("argv, needle", [
    (["identify", "{files}/nothing.csv", "--out", "{tmp}/f.json"], "nothing.csv does not exist"),
    (["simulate", "--seed", "-1", "--out", "{tmp}/s.csv"], "argument --seed"),
    (["predict", "{tmp}/cut.pt", "{files}/run.csv", "--out", "{tmp}/p.csv"], "cut.pt"),
])
def test_as_a_process_a_bad_input_is_one_line_and_exit_2(files, tmp_path, argv, needle):
    (tmp_path / "cut.pt").write_bytes((files / "m.pt").read_bytes()[:100])
    shutil.copy(files / "m.json", tmp_path / "cut.json")
    hyst = Path(sys.executable).parent / "hyst"
    cmd = [str(hyst)] if hyst.exists() else [sys.executable, "-m", "hybrid.cli._main"]
    proc = subprocess.run(cmd + [a.format(files=files, tmp=tmp_path) for a in argv], capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 2, proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1 and needle in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr
