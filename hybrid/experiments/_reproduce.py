"""The seed paper's Table I: FNN, FNN-HIB and LSTM, forward and inverse, on one data set."""

from __future__ import annotations

import platform
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from physics.data.io import atomic_path, write_json, write_text
from physics.data import DataSplit
from hybrid.networks import make_network, network_label
from ._plots import plot_comparisons
from ._presets import BUDGETS, PAPER_NETWORKS, check_preset
from ._scoring import Score, label, score_model

__all__ = ["MODELS", "ReproduceResult", "reproduce"]

#: Table I's rows, the networks trained by default; any registered network may be given.
MODELS = PAPER_NETWORKS

#: The seed paper's Table I (real catheter), RMSE per test run: 0.15 Hz then 0.45 Hz, each 0/Mid/End BL.
PAPER_TABLE = {
    "forward": {"fnn": (2.824, 2.781, 2.858, 3.225, 3.061, 3.225), "fnn-hib": (0.812, 0.888, 1.232, 0.690, 0.689, 0.443),
                "lstm": (1.016, 1.140, 1.463, 0.713, 0.641, 0.415)},
    "inverse": {"fnn": (0.289, 0.263, 0.288, 0.304, 0.282, 0.310), "fnn-hib": (0.099, 0.090, 0.105, 0.090, 0.082, 0.099),
                "lstm": (0.094, 0.128, 0.098, 0.079, 0.045, 0.072)},
}


@dataclass
class ReproduceResult:
    """What :func:`reproduce` wrote and measured."""

    out: Path
    scores: list[Score]
    lstm_modes: list[dict[str, Any]]
    fit_seconds: dict[str, float] = field(default_factory=dict)
    seconds: float = 0.0


# ---------------------------------------------------------------------- job
def reproduce(split: DataSplit, out: str | Path, preset: str = "quick", seed: int = 0,
              directions=("forward", "inverse"), models=MODELS, overrides: dict[str, Any] | None = None,
              progress: bool | None = None, figures: bool = True, data_name: str = "",
              threads: int | None = 1) -> ReproduceResult:
    """Train every model in both directions, score it on the test set and write the results.

    Writes ``out/table.csv``, ``out/table.md``, ``out/lstm_modes.csv``, ``out/run.json``,
    ``out/figures/*.png`` and ``out/models/<direction>_<model>.pt``. ``threads`` sets torch's
    CPU threads for the whole job (1 by default: on a shared 2-core machine a second thread
    spin-waits and makes batched LSTM prediction 5-8 times slower).
    """
    from hybrid.learning._learned import _threads

    with _threads(threads):
        return _reproduce(split, Path(out), preset, seed, directions, models, overrides, progress, figures,
                          data_name)


def _reproduce(split, out, preset, seed, directions, models, overrides, progress, figures, data_name):
    from hybrid.learning._learned import LearnedModel

    check_preset(preset)
    for m in models:
        make_network(m)  # rejects unknown names, listing the valid ones
    start = time.perf_counter()
    result = ReproduceResult(out, [], [])
    fitted = {}
    for direction in directions:
        for name in models:
            training = BUDGETS[preset].table.for_network(name, seed=seed, progress=progress, **(overrides or {}))
            model = LearnedModel(make_network(name), direction, training=training)
            model.fit(split.train)
            model.save(out / "models" / f"{direction}_{name}.pt")
            result.fit_seconds[f"{direction}/{name}"] = round(model.history_.seconds, 2)
            result.scores += score_model(model, split.test, name)
            if len(model.network_.modes) > 1:  # the paper's LSTM: window and carried state
                for mode in model.network_.modes:
                    result.lstm_modes += [{**asdict(s), "mode": mode} for s in score_model(model, split.test, name, mode)]
            fitted[direction, name] = model
    write_tables(result.scores, out, split)
    _write_modes(result.lstm_modes, out)
    if figures:
        plot_comparisons(fitted, split.test, out / "figures")
    result.seconds = time.perf_counter() - start
    write_json(out / "run.json", {
        "data": data_name, "preset": preset, "seed": seed,
        "settings": {m: BUDGETS[preset].table.for_network(m).to_dict() for m in models},
        "overrides": overrides or {}, "train": list(split.train.names), "test": list(split.test.names),
        "fit_seconds": result.fit_seconds, "total_seconds": round(result.seconds, 1),
        "python": platform.python_version(),
    })
    return result


def write_tables(scores: list[Score], out: Path, split: DataSplit) -> None:
    rows = ["direction,model,test,rmse,nrmse"] + [
        f"{s.direction},{s.model},{s.test},{s.rmse:.6g},{s.nrmse:.6g}" for s in scores]
    write_text(out / "table.csv", "\n".join(rows) + "\n")
    write_text(out / "table.md", markdown_table(scores, split))


def _write_modes(rows: list[dict[str, Any]], out: Path) -> None:
    lines = ["direction,mode,test,rmse,nrmse"] + [
        f"{r['direction']},{r['mode']},{r['test']},{r['rmse']:.6g},{r['nrmse']:.6g}" for r in rows]
    with atomic_path(out / "lstm_modes.csv") as tmp:
        tmp.write_text("\n".join(lines) + "\n")


def markdown_table(scores: list[Score], split: DataSplit) -> str:
    """Table I layout: one block per direction, models as rows, RMSE then NRMSE per test run."""
    first = split.test[0]
    units = {"forward": first.output_unit, "inverse": first.input_unit}
    tests = [label(t) for t in split.test] + ["all"]
    lines = ["# Table I: FNN, FNN-HIB and LSTM, forward and inverse", ""]
    for direction in dict.fromkeys(s.direction for s in scores):
        unit = units[direction] or ("output units" if direction == "forward" else "input units")
        what = "input -> output" if direction == "forward" else "output -> input"
        lines += [f"## {direction.capitalize()} ({what}), RMSE ({unit}) / NRMSE (%)", "",
                  "| model | " + " | ".join(tests) + " |", "|---" * (len(tests) + 1) + "|"]
        for model in dict.fromkeys(s.model for s in scores if s.direction == direction):
            cells = {s.test: s for s in scores if s.direction == direction and s.model == model}
            lines.append(f"| {network_label(model)} | " + " | ".join(
                f"{cells[t].rmse:.4g} / {100 * cells[t].nrmse:.1f}%" for t in tests) + " |")
        lines.append("")
    lines += ["## The seed paper's Table I (real catheter), RMSE", "",
              "Test runs 0.15 Hz (0/Mid/End BL), then 0.45 Hz (0/Mid/End BL); forward in deg, inverse in mm.", "",
              "| direction | model | " + " | ".join(["0.15 0", "0.15 Mid", "0.15 End", "0.45 0", "0.45 Mid", "0.45 End"])
              + " |", "|---" * 8 + "|"]
    for direction, table in PAPER_TABLE.items():
        for model, values in table.items():
            lines.append(f"| {direction} | {network_label(model)} | " + " | ".join(f"{v:.3f}" for v in values) + " |")
    return "\n".join(lines) + "\n"
