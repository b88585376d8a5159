"""Reading trajectories from CSV files (and the JSON files that travel with data and models)."""

from __future__ import annotations

import csv
import io
import json
import os
import re
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ._checks import MAX_MAGNITUDE, find_outlier, time_notes
from ._errors import DataError, DataNotFoundError
from ._resample import raw_rate
from ._trajectory import Trajectory

__all__ = ["load_csv", "load_csvs", "read_csv_columns", "read_text", "read_json"]


def load_csv(
    path: str | os.PathLike[str],
    time: str = "time",
    input: str = "u",  # noqa: A002 - mirrors the column role
    output: str = "y",
    rate_hz: float | str | None = None,
    extra: Sequence[str] | None = None,
    *,
    input_unit: str = "",
    output_unit: str = "",
    meta: dict[str, Any] | None = None,
    check_outliers: bool = False,
) -> Trajectory:
    """Load one trajectory from a CSV file with a header line.

    Parameters
    ----------
    path : path-like
        Comma-separated file; the first line names the columns (any names).
    time, input, output : str
        Names of the time (s), input and output columns.
    rate_hz : float, "auto" or None
        ``None`` keeps the samples as they are (time must then be strictly
        increasing); a number resamples with :func:`resample`, which also
        accepts repeated stamps and irregular steps; ``"auto"`` resamples at
        the file's own rate (:func:`raw_rate`: irregular stamps made uniform).
    extra : sequence of str, optional
        Further columns to keep in :attr:`Trajectory.extra`.
    input_unit, output_unit : str
        Units recorded on the trajectory.
    meta : dict, optional
        Metadata; ``rate_hz`` is added when resampling.
    check_outliers : bool, default False
        Also refuse a sample far outside the range of the others (more than
        1000 times their spread from their median: a 1e30 glitch, see
        :func:`physics.data._checks.find_outlier`) or beyond +/-1e150 (no
        measurement, and more than a fit's squares hold), naming its line and
        column. ``hyst`` always checks.

    Returns
    -------
    Trajectory
        ``input_name``/``output_name`` are the column names, ``source`` the path.

    Raises
    ------
    DataError
        Missing or empty file, a folder, text that is not UTF-8, unknown column (the
        available ones are listed), non-numeric cell, NaN or inf, or (with
        ``check_outliers``) a value far outside the range of the others (line and
        column named), or time not strictly increasing when ``rate_hz`` is None.
    """
    return load_csvs([path], time, input, output, rate_hz, extra, input_unit=input_unit, output_unit=output_unit,
                     meta=meta, check_outliers=check_outliers)[0]


def load_csvs(
    paths: Sequence[str | os.PathLike[str]],
    time: str = "time",
    input: str = "u",  # noqa: A002 - mirrors the column role
    output: str = "y",
    rate_hz: float | str | None = "auto",
    extra: Sequence[str] | None = None,
    **kwargs: Any,
) -> list[Trajectory]:
    """Load several runs of one data set at one rate (the runs of a fit must share their step).

    ``rate_hz="auto"`` (the default) resamples every run at the rate the files were recorded at,
    pooled over all of them (:func:`raw_rate`), so kHz data stay kHz and irregular stamps become
    uniform; a number resamples at that rate; ``None`` keeps the samples. The other arguments are
    those of :func:`load_csv`, and two keywords of the command line's: ``max_samples`` refuses, before
    resampling, a file whose span at the rate gives more samples than that (naming the file and the
    highest rate it takes), and ``warn`` is called with a sentence (file first) for each file whose time
    stamps have a gap or look like milliseconds (:func:`physics.data._checks.time_notes`).

    Only the named columns are read: other columns may hold text or be empty, and quoted numbers
    (``"1.0"``) are numbers.
    """
    check = kwargs.pop("check_outliers", False)
    max_samples, warn = kwargs.pop("max_samples", None), kwargs.pop("warn", None)
    columns = [time, input, output] + list(extra or [])
    raw = [(Path(p), read_csv_columns(p, columns, check_outliers=check)) for p in paths]
    for p, cols in raw if rate_hz is not None else ():
        if cols[time].size < 2:
            raise DataError(f"{p} has one data row, so one sample; resampling needs at least two (and a fit many "
                            "more). Give the whole recording.")
    if rate_hz == "auto":
        rate_hz = _raw_rate(", ".join(str(p) for p, _ in raw), [cols[time] for _, cols in raw])
    for p, cols in raw if max_samples is not None and rate_hz is not None else ():
        _check_length(p, cols[time], float(rate_hz), max_samples)
    trajs = [_trajectory(p, cols, time, input, output, rate_hz, extra, **kwargs) for p, cols in raw]
    for p, cols in raw if warn is not None else ():  # once every file is read: a refusal stays one line
        for note in time_notes(cols[time]):
            warn(f"{p}: {note}")
    return trajs


def _check_length(path, time, rate_hz: float, max_samples: int) -> None:
    """Refuse, before resampling allocates them, more than ``max_samples`` samples from one file."""
    span = float(np.max(time) - np.min(time))
    n = span * rate_hz  # a float: no overflow, however large
    if n + 1 > max_samples:
        raise DataError(f"{path}: {span:g} s of time stamps at {rate_hz:g} Hz would be {n:.3g} samples, more than "
                        f"the {max_samples:.0e} one run may hold; give a rate <= {max_samples / span:.4g} Hz "
                        "(--rate, rate_hz=), or split the file.")


def _raw_rate(where, times) -> float:
    try:
        return raw_rate(times)
    except DataError as exc:
        raise DataError(f"{where}: {exc}") from None


def unit_in_name(name: str) -> str:
    """The unit a column's header carries at its end, ``"Angle x [deg]"`` or ``"q (mm)"`` -> ``"deg"``,
    ``"mm"``; ``""`` when it carries none.

    >>> unit_in_name("Angle x [deg]"), unit_in_name("q (mm)"), unit_in_name("Tendon Disp.")
    ('deg', 'mm', '')
    """
    match = re.search(r"[\[(]\s*([^\[\]()]+?)\s*[\])]\s*$", str(name))
    return match.group(1) if match else ""


def _trajectory(path, cols, time, input, output, rate_hz, extra,  # noqa: A002
                input_unit="", output_unit="", meta=None) -> Trajectory:
    meta = dict(meta or {})
    kwargs: dict[str, Any] = dict(
        input_name=input, output_name=output, input_unit=input_unit or unit_in_name(input),
        output_unit=output_unit or unit_in_name(output),
        source=str(path), extra={name: cols[name] for name in (extra or [])}, meta=meta,
    )
    try:
        if rate_hz is None:
            return Trajectory(cols[time], cols[input], cols[output], **kwargs)
        return Trajectory.from_raw(cols[time], cols[input], cols[output], rate_hz=rate_hz, **kwargs)
    except DataError as exc:
        hint = "" if rate_hz is not None else " (or pass rate_hz=... to resample raw samples)"
        raise DataError(f"{path}: {exc}{hint}") from None


def read_text(path: str | os.PathLike[str], what: str = "file") -> str:
    """The text of ``path`` (UTF-8, a BOM dropped), or a :class:`DataError` naming the file and
    what is wrong: missing, a folder, unreadable, or another encoding (the one it looks like)."""
    path = Path(path)
    if path.is_dir():
        raise DataError(f"{path} is a folder; give the path of a {what}.")
    if path.exists() and not path.is_file():  # /dev/stdin, a pipe: "does not exist" would be wrong
        raise DataError(f"{path} is not a regular file (a device or a pipe); save the data to a file and give its "
                        "path.")
    if not path.is_file():
        raise DataNotFoundError(f"{what[:1].upper()}{what[1:]} {path} does not exist. Check the path.")
    raw = path.read_bytes()
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise DataError(f"{path} is not UTF-8 text (byte {raw[exc.start]:#04x} at offset {exc.start}; it looks like "
                        f"{_guess_encoding(raw)}). Save it as UTF-8.") from None


def _guess_encoding(raw: bytes) -> str:
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")):
        return "UTF-16"
    if raw[:200].count(b"\x00") > len(raw[:200]) // 4:
        return "UTF-16 without a BOM"
    if not any(b >= 0x80 for b in raw[:65536]) and b"\x00" not in raw:
        return "ASCII with bad bytes later on"
    return "Latin-1 / Windows-1252" if raw.count(b"\x00") == 0 else "a binary file"


def read_json(path: str | os.PathLike[str], what: str = "JSON file") -> Any:
    """The JSON value in ``path``, or a :class:`DataError` naming the file, the line and how to fix it."""
    text = read_text(path, what)
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise DataError(f"{path} is not valid JSON (line {exc.lineno}, column {exc.colno}: {exc.msg}); it is "
                        f"corrupt or truncated: write the {what} again.") from None


def read_csv_columns(path: str | os.PathLike[str], names: Sequence[str],
                     check_outliers: bool = False) -> dict[str, NDArray[np.float64]]:
    """Read the named columns of a CSV file as float64 arrays (shared with the presets, not public)."""
    path = Path(path)
    text = read_text(path, "CSV file")
    lines = text.splitlines()
    if not any(line.strip() for line in lines):
        raise DataError(f"{path} is empty. Expected a header line (e.g. 'time,u,y') and data rows.")
    header = [h.strip() for h in next(csv.reader([lines[0]], skipinitialspace=True))]
    if len(header) == 1 and any(sep in lines[0] for sep in ";\t"):
        sep = ";" if ";" in lines[0] else "tab"
        raise DataError(f"{path} separates its columns with {sep}s; CSV files here use commas "
                        "(save it again as comma-separated).")
    missing = [n for n in names if n not in header]
    if missing and lines[0].lstrip().startswith("#"):
        raise DataError(f"{path} starts with a comment line ({lines[0].strip()[:40]!r}); the first line must be the "
                        "header naming the columns (e.g. 'time,u,y'): delete the lines above it.")
    if missing and all(_is_number(h) for h in header):
        raise DataError(f"{path} has no header line: its first line ({lines[0].strip()[:40]!r}) holds numbers. Add a "
                        f"first line naming the {len(header)} columns (e.g. 'time,u,y').")
    if missing and len(header) == 1 and len(lines[0].split()) > 1 and len(lines[0].split()) == len(
            (lines[1] if len(lines) > 1 else "").split()):
        raise DataError(f"{path} separates its columns with spaces; CSV files here use commas (save it again as "
                        "comma-separated).")
    if missing:
        near = [h for h in header if h.casefold() == missing[0].casefold()]
        hint = f" (did you mean {near[0]!r}? names are case-sensitive)" if near else ""
        raise DataError(
            f"{path} has no column {missing[0]!r}{hint}. Available columns: {header}. "
            "Pass the right names via time=, input=, output= or extra= (--time, --input, --output in hyst)."
        )
    dupes = sorted({h for h in header if header.count(h) > 1 and h in names})
    if dupes:
        raise DataError(f"{path} has the column {dupes[0]!r} more than once; make the header names unique.")
    if not any(line.strip() for line in lines[1:]):
        raise DataError(f"{path} has a header but no data rows.")
    idx = [header.index(n) for n in names]
    table = _parse_table(path, text, lines, header, idx)  # the asked-for columns, in the order of ``names``
    bad_rows = np.flatnonzero(~np.isfinite(table).all(axis=1))
    if bad_rows.size:
        line_no, col, cell = _locate(lines, int(bad_rows[0]), idx, header, lambda v: not np.isfinite(v))
        kind = "NaN" if np.isnan(float(cell)) else "inf"
        raise DataError(f"{path}, line {line_no}, column {col!r}: {kind} value ({cell.strip()!r}). "
                        "Fill or drop the row before loading.")
    huge = np.flatnonzero((np.abs(table) > MAX_MAGNITUDE).any(axis=1)) if check_outliers else []
    if len(huge):
        line_no, col, cell = _locate(lines, int(huge[0]), idx, header, lambda v: abs(v) > MAX_MAGNITUDE)
        raise DataError(f"{path}, line {line_no}, column {col!r}: {cell.strip()} is beyond +/-{MAX_MAGNITUDE:.0e}, "
                        "larger than any measurement and than a fit's arithmetic holds; fix the row, or rescale the "
                        "column.")
    for k, i in enumerate(idx) if check_outliers else ():
        row = find_outlier(table[:, k])
        if row is not None:
            value = float(table[row, k])
            line_no, col, cell = _locate(lines, row, [i], header, lambda v: v == value)
            others = np.delete(table[:, k], row)
            raise DataError(
                f"{path}, line {line_no}, column {col!r}: {cell.strip()} is far outside the range of the other "
                f"samples ({np.min(others):.4g} to {np.max(others):.4g}); fix or drop the row (a sensor glitch?)."
            )
    return {n: np.ascontiguousarray(table[:, k]) for k, n in enumerate(names)}


def _parse_table(path: Path, text: str, lines: list[str], header: list[str], idx: list[int]) -> NDArray[np.float64]:
    """The columns ``idx`` of the data rows: numpy's fast parse of an all-numeric file, else :func:`_read_rows`."""
    try:
        table = np.loadtxt(io.StringIO(text), delimiter=",", skiprows=1, ndmin=2, comments=None, dtype=np.float64)
    except ValueError:
        table = None
    if table is not None and table.shape[1] == len(header):
        return table[:, idx]
    return _read_rows(path, lines, header, idx)


def _read_rows(path: Path, lines: list[str], header: list[str], idx: list[int]) -> NDArray[np.float64]:
    """The columns ``idx`` read row by row with the csv module (run when the fast parse failed): quoted
    numbers (``"1.0"``, also after a space: ``1.0, "a, b"``) are numbers and the columns not asked for are
    not read (text, empty cells); a row of the wrong length or a cell that is not a number is named by
    its line."""
    n_cols, rows = len(header), []
    reader = csv.reader(lines[1:], skipinitialspace=True)
    for row in reader:
        line_no = reader.line_num + 1
        if not row or (len(row) == 1 and not row[0].strip()):
            continue
        if len(row) != n_cols:
            raise DataError(
                f"{path}, line {line_no}: {len(row)} cells but the header has {n_cols} columns. "
                "Every row needs one value per header column."
            )
        values = []
        for i in idx:
            try:
                values.append(float(row[i]))
            except ValueError:
                raise DataError(
                    f"{path}, line {line_no}, column {header[i]!r}: {row[i]!r} is not a number. "
                    "Fix the cell or remove the row."
                ) from None
        rows.append(values)
    return np.asarray(rows, dtype=np.float64).reshape(len(rows), len(idx))


def _locate(lines: list[str], data_row: int, idx: list[int], header: list[str],
            bad: Callable[[float], bool]) -> tuple[int, str, str]:
    """The file line, column name and cell of the ``data_row``-th non-blank data row's first bad cell."""
    count = -1
    for line_no, line in enumerate(lines[1:], start=2):
        if not line.strip():
            continue
        count += 1
        if count == data_row:
            cells = next(csv.reader([line], skipinitialspace=True))
            for i in idx:
                if bad(float(cells[i])):
                    return line_no, header[i], cells[i]
    return data_row + 2, header[idx[0]], "?"  # pragma: no cover


def _is_number(cell: str) -> bool:
    try:
        float(cell)
    except ValueError:
        return False
    return True
