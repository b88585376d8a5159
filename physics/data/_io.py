"""Reading trajectories from CSV files."""

from __future__ import annotations

import csv
import io
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NoReturn

import numpy as np
from numpy.typing import NDArray

from ._errors import DataError, DataNotFoundError
from ._trajectory import Trajectory

__all__ = ["load_csv", "read_csv_columns"]


def load_csv(
    path: str | os.PathLike[str],
    time: str = "time",
    input: str = "u",  # noqa: A002 - mirrors the column role
    output: str = "y",
    rate_hz: float | None = None,
    extra: Sequence[str] | None = None,
    *,
    input_unit: str = "",
    output_unit: str = "",
    meta: dict[str, Any] | None = None,
) -> Trajectory:
    """Load one trajectory from a CSV file with a header line.

    Parameters
    ----------
    path : path-like
        Comma-separated file; the first line names the columns (any names).
    time, input, output : str
        Names of the time (s), input and output columns.
    rate_hz : float or None
        ``None`` keeps the samples as they are (time must then be strictly
        increasing); a number resamples with :func:`resample`, which also
        accepts repeated stamps and irregular steps.
    extra : sequence of str, optional
        Further columns to keep in :attr:`Trajectory.extra`.
    input_unit, output_unit : str
        Units recorded on the trajectory.
    meta : dict, optional
        Metadata; ``rate_hz`` is added when resampling.

    Returns
    -------
    Trajectory
        ``input_name``/``output_name`` are the column names, ``source`` the path.

    Raises
    ------
    DataError
        Missing or empty file, unknown column (the available ones are listed),
        non-numeric cell or NaN (line and column named), or time not strictly
        increasing when ``rate_hz`` is None.
    """
    path = Path(path)
    wanted = [time, input, output] + list(extra or [])
    cols = read_csv_columns(path, wanted)
    meta = dict(meta or {})
    kwargs: dict[str, Any] = dict(
        input_name=input, output_name=output, input_unit=input_unit, output_unit=output_unit,
        source=str(path), extra={name: cols[name] for name in (extra or [])}, meta=meta,
    )
    try:
        if rate_hz is None:
            return Trajectory(cols[time], cols[input], cols[output], **kwargs)
        return Trajectory.from_raw(cols[time], cols[input], cols[output], rate_hz=rate_hz, **kwargs)
    except DataError as exc:
        hint = "" if rate_hz is not None else " (or pass rate_hz=... to resample raw samples)"
        raise DataError(f"{path}: {exc}{hint}") from None


def read_csv_columns(path: str | os.PathLike[str], names: Sequence[str]) -> dict[str, NDArray[np.float64]]:
    """Read the named columns of a CSV file as float64 arrays (shared with the presets, not public)."""
    path = Path(path)
    if not path.is_file():
        raise DataNotFoundError(f"CSV file {path} does not exist. Check the path.")
    text = path.read_text(encoding="utf-8-sig")
    lines = text.splitlines()
    if not any(line.strip() for line in lines):
        raise DataError(f"{path} is empty. Expected a header line (e.g. 'time,u,y') and data rows.")
    header = [h.strip() for h in next(csv.reader([lines[0]]))]
    missing = [n for n in names if n not in header]
    if missing:
        raise DataError(
            f"{path} has no column {missing[0]!r}. Available columns: {header}. "
            "Pass the right names via time=, input=, output= or extra=."
        )
    dupes = sorted({h for h in header if header.count(h) > 1 and h in names})
    if dupes:
        raise DataError(f"{path} has the column {dupes[0]!r} more than once; make the header names unique.")
    if not any(line.strip() for line in lines[1:]):
        raise DataError(f"{path} has a header but no data rows.")
    idx = [header.index(n) for n in names]
    table = _parse_table(path, text, lines, len(header))
    nan_rows = np.flatnonzero(np.isnan(table[:, idx]).any(axis=1))
    if nan_rows.size:
        line_no, col = _locate_nan(lines, int(nan_rows[0]), idx, header)
        raise DataError(
            f"{path}, line {line_no}, column {col!r}: NaN value. Fill or drop the row before loading."
        )
    return {n: np.ascontiguousarray(table[:, i]) for n, i in zip(names, idx)}


def _parse_table(path: Path, text: str, lines: list[str], n_cols: int) -> NDArray[np.float64]:
    try:
        table = np.loadtxt(io.StringIO(text), delimiter=",", skiprows=1, ndmin=2, comments=None, dtype=np.float64)
    except ValueError:
        table = None
    if table is not None and table.shape[1] == n_cols:
        return table
    _raise_bad_cell(path, lines, n_cols)


def _raise_bad_cell(path: Path, lines: list[str], n_cols: int) -> NoReturn:
    """Slow pass that names the first bad line and cell (only run when the fast parse failed)."""
    header = [h.strip() for h in next(csv.reader([lines[0]]))]
    for line_no, row in enumerate(csv.reader(lines[1:]), start=2):
        if not row or not "".join(row).strip():
            continue
        if len(row) != n_cols:
            raise DataError(
                f"{path}, line {line_no}: {len(row)} cells but the header has {n_cols} columns. "
                "Every row needs one value per header column."
            )
        for name, cell in zip(header, row):
            try:
                float(cell)
            except ValueError:
                raise DataError(
                    f"{path}, line {line_no}, column {name!r}: {cell!r} is not a number. "
                    "Fix the cell or remove the row."
                ) from None
    raise DataError(f"{path}: could not parse the file as comma-separated numbers.")


def _locate_nan(lines: list[str], data_row: int, idx: list[int], header: list[str]) -> tuple[int, str]:
    """Map the ``data_row``-th non-blank data row to its file line and first NaN column."""
    count = -1
    for line_no, line in enumerate(lines[1:], start=2):
        if not line.strip():
            continue
        count += 1
        if count == data_row:
            cells = next(csv.reader([line]))
            for i in idx:
                if np.isnan(float(cells[i])):
                    return line_no, header[i]
    return data_row + 2, header[idx[0]]  # pragma: no cover
