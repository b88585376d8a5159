"""The seed paper's Table I: FNN, FNN-HIB and LSTM, forward and inverse, on one data set."""

from __future__ import annotations

import json
import platform
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from physics.data._atomic import atomic_path, write_json, write_text
from physics.data import DataError, Dataset, DataSplit, load_csv, load_preset, nrmse, rmse
from hybrid.networks import make_network

__all__ = ["PRESETS", "MODELS", "Score", "ReproduceResult", "load_data", "score_model", "reproduce"]

MODELS = ("fnn", "fnn-hib", "lstm")
LABELS = {"fnn": "FNN", "fnn-hib": "FNN-HIB", "lstm": "LSTM"}

#: LearnedModel settings per preset and model. All keep the paper's networks, Adam lr 1e-3,
#: MSE and batch 16. "quick" trains on every 2nd (FNNs) / 4th (LSTM) window with early stopping
#: on a 10 % validation split, one torch thread (under 3 minutes for all six models on 2 cores);
#: "paper" is the paper's 500 epochs on every window; "tiny" is for tests only.
PRESETS: dict[str, dict[str, dict[str, Any]]] = {
    "quick": {
        "fnn": dict(epochs=40, stride=2, validation=0.1, patience=8, threads=1),
        "fnn-hib": dict(epochs=40, stride=2, validation=0.1, patience=8, threads=1),
        "lstm": dict(epochs=40, stride=4, validation=0.1, patience=10, threads=1),
    },
    "paper": {m: dict(epochs=500, stride=1, validation=0.0, patience=None, threads=1) for m in MODELS},
    "tiny": {m: dict(epochs=2, stride=20 if m == "lstm" else 5, validation=0.0, patience=None, threads=1)
             for m in MODELS},
}

#: The seed paper's Table I (real catheter), RMSE per test run: 0.15 Hz then 0.45 Hz, each 0/Mid/End BL.
PAPER_TABLE = {
    "forward": {"fnn": (2.824, 2.781, 2.858, 3.225, 3.061, 3.225), "fnn-hib": (0.812, 0.888, 1.232, 0.690, 0.689, 0.443),
                "lstm": (1.016, 1.140, 1.463, 0.713, 0.641, 0.415)},
    "inverse": {"fnn": (0.289, 0.263, 0.288, 0.304, 0.282, 0.310), "fnn-hib": (0.099, 0.090, 0.105, 0.090, 0.082, 0.099),
                "lstm": (0.094, 0.128, 0.098, 0.079, 0.045, 0.072)},
}


@dataclass(frozen=True)
class Score:
    """Error of one model on one test trajectory (``test="all"``: pooled over every test sample)."""

    direction: str
    model: str
    test: str
    rmse: float
    nrmse: float
    n: int


@dataclass
class ReproduceResult:
    """What :func:`reproduce` wrote and measured."""

    out: Path
    scores: list[Score]
    lstm_modes: list[dict[str, Any]]
    fit_seconds: dict[str, float] = field(default_factory=dict)
    seconds: float = 0.0


# --------------------------------------------------------------------- data
def load_data(data: str, seed: int = 0) -> DataSplit:
    """``"virtual"`` (the paper's protocol on the virtual catheter), ``"catheter_2023"``
    (train set 1, test set 2) or a folder with ``train/*.csv`` and ``test/*.csv``."""
    if data == "virtual":
        from physics.virtual import VirtualCatheter, paper_protocol

        return paper_protocol(VirtualCatheter(seed=seed))
    if data == "catheter_2023":
        return load_preset("catheter_2023")
    folder = Path(data)
    if not folder.is_dir():
        raise DataError(f"--data {data!r} is neither 'virtual', 'catheter_2023' nor a folder. "
                        "Give a folder written by `hyst simulate --paper-dataset --out DIR`.")
    return DataSplit(_load_folder(folder, "train"), _load_folder(folder, "test"))


def _load_folder(folder: Path, part: str) -> Dataset:
    files = sorted((folder / part).glob("*.csv"))
    if not files:
        raise DataError(f"{folder / part} holds no CSV files; expected {part}/*.csv with columns time,u,y.")
    manifest = folder / "manifest.json"
    info = {}
    units = {"u": "mm", "y": "deg"}
    if manifest.is_file():
        blob = json.loads(manifest.read_text())
        units.update(blob.get("units", {}))
        info = {Path(f["file"]).stem: f for f in blob.get("files", [])}
    trajs = []
    for f in files:
        meta = {k: v for k, v in info.get(f.stem, {}).items() if k in ("frequency_hz", "baseline")}
        t = load_csv(f, rate_hz=25.0, input_unit=units["u"], output_unit=units["y"], meta=meta)
        trajs.append(replace(t, source=f.stem))
    return Dataset(trajs)


def label(traj) -> str:
    """A short name for a trajectory: its source without folder or file extension."""
    name = Path(traj.source).name if traj.source else "?"
    stem, dot, ext = name.rpartition(".")
    return stem if dot and ext.lower() in ("csv", "txt", "mat") else name


# ------------------------------------------------------------------ scoring
def score_model(model, tests: Dataset, name: str, mode: str | None = None) -> list[Score]:
    """RMSE and NRMSE per test trajectory and pooled over all of them (``test="all"``)."""
    ys, yhats, out = [], [], []
    for traj in tests:
        y = (traj.swap() if model.direction == "inverse" else traj).y
        yhat = model.predict(traj, mode=mode)
        ys.append(y)
        yhats.append(yhat)
        out.append(Score(model.direction, name, label(traj), rmse(y, yhat), nrmse(y, yhat), len(y)))
    y, yhat = np.concatenate(ys), np.concatenate(yhats)
    out.append(Score(model.direction, name, "all", rmse(y, yhat), nrmse(y, yhat), len(y)))
    return out


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

    if preset not in PRESETS:
        raise DataError(f"unknown preset {preset!r}. Must be one of {[p for p in PRESETS if p != 'tiny']}.")
    for m in models:
        make_network(m)  # rejects unknown names, listing the valid ones
    start = time.perf_counter()
    result = ReproduceResult(out, [], [])
    fitted = {}
    for direction in directions:
        for name in models:
            settings = {**PRESETS[preset][name], **(overrides or {})}
            model = LearnedModel(make_network(name), direction, seed=seed, progress=progress, **settings)
            model.fit(split.train)
            model.save(out / "models" / f"{direction}_{name}.pt")
            result.fit_seconds[f"{direction}/{name}"] = round(model.history_.seconds, 2)
            result.scores += score_model(model, split.test, name)
            if name == "lstm":
                for mode in model.network_.modes:
                    result.lstm_modes += [{**asdict(s), "mode": mode} for s in score_model(model, split.test, name, mode)]
            fitted[direction, name] = model
    write_tables(result.scores, out, split)
    _write_modes(result.lstm_modes, out)
    if figures:
        from ._plots import plot_comparisons

        plot_comparisons(fitted, split.test, out / "figures")
    result.seconds = time.perf_counter() - start
    write_json(out / "run.json", {
        "data": data_name, "preset": preset, "seed": seed, "settings": {m: PRESETS[preset][m] for m in models},
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
        unit = units[direction] or "output units"
        what = "input -> output" if direction == "forward" else "output -> input"
        lines += [f"## {direction.capitalize()} ({what}), RMSE ({unit}) / NRMSE (%)", "",
                  "| model | " + " | ".join(tests) + " |", "|---" * (len(tests) + 1) + "|"]
        for model in dict.fromkeys(s.model for s in scores if s.direction == direction):
            cells = {s.test: s for s in scores if s.direction == direction and s.model == model}
            lines.append(f"| {LABELS.get(model, model)} | " + " | ".join(
                f"{cells[t].rmse:.3f} / {100 * cells[t].nrmse:.1f}%" for t in tests) + " |")
        lines.append("")
    lines += ["## The seed paper's Table I (real catheter), RMSE", "",
              "Test runs 0.15 Hz (0/Mid/End BL), then 0.45 Hz (0/Mid/End BL); forward in deg, inverse in mm.", "",
              "| direction | model | " + " | ".join(["0.15 0", "0.15 Mid", "0.15 End", "0.45 0", "0.45 Mid", "0.45 End"])
              + " |", "|---" * 8 + "|"]
    for direction, table in PAPER_TABLE.items():
        for model, values in table.items():
            lines.append(f"| {direction} | {LABELS[model]} | " + " | ".join(f"{v:.3f}" for v in values) + " |")
    return "\n".join(lines) + "\n"
