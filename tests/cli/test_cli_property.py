"""Property: whatever CSV content and flag values ``hyst predict`` is given, it exits 0 with the right
predictions or 2 with one line and no traceback, and never modifies its input (#42).

The model is a physics-only folder (``hyst fit --physics linear --residual none``), made once, so an
example costs a few tens of milliseconds. The content is drawn as numbers (time steps, values, some of
them NaN, inf, huge or a word) and written twice: plainly, and in another valid CSV dialect (quoted
cells, an unused text column, CRLF line ends, a BOM, blank lines, spaces). Both files must give the
same exit status and, on 0, byte-identical predictions on the model's 25 Hz grid over the file's span.
"""

from __future__ import annotations

import hashlib
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from hybrid.cli._main import main

PROPERTY = settings(max_examples=120, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
RATE_HZ = 25.0


@pytest.fixture(scope="module")
def model(fitted_linear) -> Path:
    return fitted_linear / "model"


# ------------------------------------------------------------------ the content
ORDINARY = st.floats(-100, 100, allow_nan=False)
SPECIAL = st.sampled_from([0.0, 1e-300, 1e30, -1e200, 1e300, math.nan, math.inf, -math.inf, "abc", "", "1..2"])
STEPS = st.sampled_from([0.0, -0.04, 0.001, 40.0, 1000.0])  # a repeated stamp, time backwards, kHz, ms, a gap


@st.composite
def tables(draw) -> list[list]:
    """Rows of (time, u, y): ordinary numbers on a drawn step, with up to three drawn defects (a special
    value in a cell, a special step of the time)."""
    n = draw(st.integers(0, 40))
    step = draw(st.sampled_from([0.04, 0.01, 0.1, 0.0371]))
    steps = [step] * n
    rows = [[0.0, draw(ORDINARY), draw(ORDINARY)] for _ in range(n)]
    for _ in range(draw(st.integers(0, 3)) if n else 0):
        i = draw(st.integers(0, n - 1))
        if draw(st.booleans()):
            rows[i][draw(st.integers(1, 2))] = draw(SPECIAL)
        else:
            steps[i] = draw(STEPS)
    time = float(np.round(draw(st.floats(-10, 10)), 3))
    for row, dt in zip(rows, steps):
        row[0] = time
        time += dt
    return rows


def cell(value) -> str:
    return value if isinstance(value, str) else repr(float(value))


def plain(rows) -> str:
    return "time,u,y\n" + "".join(",".join(cell(v) for v in row) + "\n" for row in rows)


@st.composite
def dialects(draw, rows) -> bytes:
    """The same rows in another valid CSV dialect."""
    quote = draw(st.booleans())
    text_column = draw(st.sampled_from([None, 0, 1, 3]))  # where an unused text column goes
    newline = draw(st.sampled_from(["\n", "\r\n"]))
    spaces = draw(st.booleans())
    blank = draw(st.booleans())

    def line(cells, note):
        cells = [f'"{c}"' if quote else c for c in cells]
        if text_column is not None:
            cells.insert(text_column, note)
        return (", " if spaces and not quote else ",").join(cells)

    lines = [line(["time", "u", "y"], "note")]
    for i, row in enumerate(rows):
        if blank and i == len(rows) // 2:
            lines.append("")
        lines.append(line([cell(v) for v in row], ['"moved, fast"', "", "ok", "n/a"][i % 4]))
    data = (newline.join(lines) + newline).encode()
    return (b"\xef\xbb\xbf" + data) if draw(st.booleans()) else data


# ------------------------------------------------------------------ the contract
def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def predict(model: Path, data: Path, out: Path, flags: list[str], capsys) -> int:
    """Run ``hyst predict``; check the contract for its exit status and return it."""
    before = digest(data)
    capsys.readouterr()
    rc = main(["predict", str(model), str(data), "--out", str(out), *flags])
    stdout, err = capsys.readouterr()
    assert "Traceback" not in err
    assert digest(data) == before, "the input was modified"
    lines = [ln for ln in err.splitlines() if ln.strip()]
    if rc == 2:
        assert len(lines) == 1 and lines[0].startswith("hyst predict: error: "), err
        assert not out.exists()
    else:
        assert rc == 0, (rc, err)
        assert all(ln.startswith("hyst predict: warning: ") for ln in lines), err
        assert out.exists() and "wrote" in stdout
    return rc


def folder_warmup(model: Path) -> int:
    """The warm-up ``hyst predict`` takes from a model folder when --warmup is left out (0 for a file)."""
    import json

    card = model / "card.json"
    return int(json.loads(card.read_text()).get("warmup", 10)) if card.is_file() else 0


def check_grid(rows, out: Path, warmup: int = 0) -> None:
    """The predictions of a file that was read: the model's 25 Hz grid over its span (after ``warmup``
    samples), all finite."""
    table = np.loadtxt(out, delimiter=",", skiprows=1, ndmin=2)
    t = np.array([r[0] for r in rows], dtype=float)
    n = int(np.floor((t[-1] - t[0]) * RATE_HZ + 1e-9)) + 1
    assert table.shape[0] == n - warmup
    np.testing.assert_allclose(table[:, 0], t[0] + np.arange(warmup, n) / RATE_HZ, rtol=0, atol=1e-6)
    assert np.all(np.isfinite(table))


@PROPERTY
@given(data=st.data())
def test_any_csv_content_in_any_dialect_predicts_or_is_refused_in_one_line(model, tmp_path, capsys, data):
    rows = data.draw(tables(), label="rows")
    a, b = tmp_path / "plain.csv", tmp_path / "dialect.csv"
    a.write_text(plain(rows))
    b.write_bytes(data.draw(dialects(rows), label="dialect"))
    for p in (tmp_path / "a.csv", tmp_path / "b.csv"):
        p.unlink(missing_ok=True)
    rc_a = predict(model, a, tmp_path / "a.csv", [], capsys)
    rc_b = predict(model, b, tmp_path / "b.csv", [], capsys)
    assert rc_a == rc_b, (rows, b.read_bytes()[:300])
    event(f"exit {rc_a}")
    if rc_a == 0:
        check_grid(rows, tmp_path / "a.csv", folder_warmup(model))
        assert (tmp_path / "a.csv").read_bytes() == (tmp_path / "b.csv").read_bytes()


FLAG_VALUES = {
    "--rate": st.sampled_from(["auto", "25", "25.0", "0", "-25", "1e308", "nan", "12.5", "x"]),
    "--warmup": st.one_of(st.integers(-3, 500).map(str), st.sampled_from(["99999999999", "1.5", ""])),
    "--measure-every": st.one_of(st.integers(-1, 500).map(str), st.sampled_from([str(2**40), "e"])),
    "--interval": st.one_of(st.floats(-0.5, 1.5, allow_nan=False).map(repr), st.sampled_from(["0.9", "1", "nan"])),
}


@PROPERTY
@given(data=st.data())
def test_any_flag_values_predict_or_are_refused_naming_the_flag(model, tmp_path, capsys, data):
    run = model.parent / "run.csv"
    names = data.draw(st.lists(st.sampled_from(sorted(FLAG_VALUES)), min_size=1, max_size=3, unique=True))
    flags = [f"{name}={data.draw(FLAG_VALUES[name], label=name)}" for name in names]
    out = tmp_path / "p.csv"
    out.unlink(missing_ok=True)
    rc = predict(model, run, out, flags, capsys)
    event(f"exit {rc}")
    if rc == 0:
        rows = np.loadtxt(run, delimiter=",", skiprows=1)[:, :3].tolist()
        warmup = next((int(f.split("=")[1]) for f in flags if f.startswith("--warmup=")), folder_warmup(model))
        check_grid(rows, out, warmup)


# ------------------------------------------------------------------ every number option
def number_options() -> list[tuple[str, str, object]]:
    """(command, flag, type) of every option whose type is one of the checked number types."""
    import argparse

    from hybrid.cli import _options as O
    from hybrid.cli._main import build_parser

    def checked(kind) -> bool:
        return kind is O.RATE_OR_AUTO or getattr(kind, "__name__", "").startswith(("a number", "an integer"))

    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return [(c, a.option_strings[0], a.type) for c, p in sub.choices.items() for a in p._actions
            if a.option_strings and checked(a.type)]


def stated_range(kind) -> tuple[float, bool, float]:
    """(low, strict, high) from the type's own description, e.g. 'a number > 0 and <= 1e+07 (Hz)'."""
    import re

    from hybrid.cli import _options as O

    name = O.RATE.__name__ if kind is O.RATE_OR_AUTO else kind.__name__
    low = re.search(r"(>=?) (\S+)", name)
    high = re.search(r"<= ([^\s(]+)", name)
    return (float(low.group(2)) if low else -math.inf, bool(low) and low.group(1) == ">",
            float(high.group(1)) if high else math.inf)


NUMBER_TEXT = st.one_of(st.floats().map(repr), st.integers().map(str), st.floats(-1e12, 1e12).map(str),
                        st.sampled_from(["1e308", "-1e308", "1e400", "2147483648", "4294967296", "auto", " 7 "]),
                        st.text(max_size=6))


@settings(max_examples=200, deadline=None, derandomize=True)
@given(text=NUMBER_TEXT)
def test_every_number_option_takes_only_finite_values_in_its_stated_range(text):
    import argparse

    options = number_options()
    assert len(options) >= 40
    for command, flag, kind in options:
        try:
            value = kind(text)
        except argparse.ArgumentTypeError as exc:
            assert repr(text) in str(exc) and "\n" not in str(exc), (flag, text, exc)
            continue
        if value == "auto":
            continue
        low, strict, high = stated_range(kind)
        assert math.isfinite(value) and (value > low if strict else value >= low) and value <= high, \
            (command, flag, text, value)
