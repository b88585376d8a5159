"""The ablation's summary: results.csv (one row per run) and one figure per varied setting."""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from physics.data.io import atomic_path, write_text
from ._config import SETTINGS, RunSpec

__all__ = ["read_record", "table_rows", "write_results_csv", "plot_summary"]

#: Settings plotted on a numeric axis; the others (physics, model, direction, mode) are categories.
NUMERIC = ("buffer", "seq_len", "hidden", "layers", "data_fraction", "epochs", "lr", "batch_size", "stride",
           "validation", "patience")
_LOG_X = ("lr",)
_LABELS = {"buffer": "FNN-HIB buffer length (samples)", "seq_len": "LSTM sequence length (samples)",
           "hidden": "hidden size (units per layer)", "data_fraction": "training trajectories",
           "physics": "physics model (none: purely learned)"}


def read_record(path: Path) -> dict[str, Any] | None:
    """A run file's record, or None when it is missing or unreadable."""
    try:
        return json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return None


def table_rows(specs: Sequence[RunSpec], out: Path, metrics: Sequence[str]) -> list[dict[str, Any]]:
    """One row per run, in grid order, read from the run files: settings then metrics.

    ``status`` is ``"ok"``, ``"failed"`` (``error`` holds the message) or ``"missing"`` (not run,
    e.g. an interrupted sweep).
    """
    runs = Path(out) / "runs"
    rows = []
    for spec in specs:
        record = read_record(runs / f"{spec.run_id}.json")
        if record is None or record.get("status") != "ok":
            record = read_record(runs / f"{spec.run_id}.error.json") or {"status": "missing"}
        row: dict[str, Any] = {"run_id": spec.run_id, "status": record["status"], "kind": spec.kind,
                               **spec.settings, "n_train": record.get("n_train"), "unit": record.get("unit")}
        m = record.get("metrics", {})
        for name in ("rmse", "nrmse"):
            if name in metrics:
                row[name] = m.get(name)
                row.update({f"{name}_{t['test']}": t[name] for t in m.get("per_test", [])})
        if "fit_seconds" in metrics:
            row["fit_seconds"] = m.get("fit_seconds")
        error = record.get("error")
        row["error"] = f"{error['type']}: {error['message']}" if error else None
        rows.append(row)
    return rows


def write_results_csv(rows: Sequence[dict[str, Any]], path: Path) -> Path:
    """Tidy CSV, one row per run; setting columns that apply to no run are left out."""
    columns: list[str] = []
    for row in rows:
        columns += [k for k in row if k not in columns]
    columns = [c for c in columns if c not in SETTINGS or any(r.get(c) is not None for r in rows)]
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(columns)
    for row in rows:
        writer.writerow(["" if row.get(c) is None else _cell(row[c]) for c in columns])
    return write_text(path, buf.getvalue())


def _cell(value: Any) -> str:
    return repr(value) if isinstance(value, float) else str(value)


# ------------------------------------------------------------------- figures
def plot_summary(rows: Sequence[dict[str, Any]], folder: Path, metrics: Sequence[str]) -> list[Path]:
    """``<metric>_vs_<setting>.png`` for every setting (but the seed) the finished runs vary.

    Each figure has one series per combination of the other varied settings (e.g. pure and
    hybrid), with every seed as a point and mean +- standard deviation over seeds.
    """
    ok = [r for r in rows if r["status"] == "ok"]
    metric = next((m for m in ("rmse", "nrmse") if m in metrics), None)
    if not ok or metric is None:
        return []
    varied = [k for k in SETTINGS if k != "seed" and len({_text(r[k]) for r in ok if r[k] is not None}) > 1]
    return [_plot_axis(ok, axis, [k for k in varied if k != axis], metric, Path(folder) / f"{metric}_vs_{axis}.png")
            for axis in varied]


def _plot_axis(rows, axis: str, others: list[str], metric: str, path: Path) -> Path:
    from matplotlib.figure import Figure

    rows = [r for r in rows if r[axis] is not None]
    numeric = axis in NUMERIC
    x_of = (lambda r: r["n_train"]) if axis == "data_fraction" else (lambda r: r[axis])
    categories = list(dict.fromkeys(r[axis] for r in rows))  # categorical settings are strings
    groups: dict[str, list[dict[str, Any]]] = {}
    for r in rows:
        groups.setdefault(_series_label(r, others), []).append(r)
    fig = Figure(figsize=(6.4, 4.2), layout="constrained")
    ax = fig.subplots()
    width = 0.6 / max(len(groups), 1)
    for i, (label, members) in enumerate(groups.items()):
        by_x: dict[Any, list[float]] = {}
        for r in members:
            key = x_of(r) if numeric else categories.index(r[axis]) + (i - (len(groups) - 1) / 2) * width
            by_x.setdefault(key, []).append(float(r[metric]))
        xs = sorted(by_x)
        means = [float(np.mean(by_x[x])) for x in xs]
        stds = [float(np.std(by_x[x])) for x in xs]
        line = ax.errorbar(xs, means, yerr=stds, marker="o", capsize=3, lw=1.2 if numeric else 0,
                           elinewidth=1.2, label=label or None)
        color = line[0].get_color()
        for x in xs:
            ax.plot([x] * len(by_x[x]), by_x[x], "x", color=color, alpha=0.6, ms=5)
    if numeric and axis in _LOG_X:
        ax.set_xscale("log")
    if not numeric:
        ax.set_xticks(range(len(categories)), [str(c) for c in categories])
    ax.set_xlabel(_LABELS.get(axis, axis))
    units = {r["unit"] for r in rows}
    unit = units.pop() if len(units) == 1 else None
    unit = f", {unit}" if unit and metric == "rmse" else ""
    ax.set_ylabel(f"test {metric.upper()} (pooled{unit}); mean $\\pm$ std over seeds")
    ax.set_title(f"{metric.upper()} against {axis} ({len(rows)} runs)")
    ax.grid(alpha=0.3)
    if any(groups):
        if len(groups) > 4:  # beside the axes, where it hides no points
            fig.set_figwidth(9.6)
            ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
        else:
            ax.legend(fontsize=8)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=120)
    return path


def _series_label(row: dict[str, Any], others: list[str]) -> str:
    parts = []
    for k in others:
        v = row[k]
        if v is None:
            continue
        parts.append(("pure" if v == "none" else f"hybrid ({v})") if k == "physics" else f"{k}={v}")
    return ", ".join(parts)


def _text(value: Any) -> str:
    return json.dumps(value)
