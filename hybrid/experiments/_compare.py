"""Physics, learned and hybrid models side by side, forward and inverse, in and out of distribution.

``compare`` trains every model on one data set and scores it on test categories
named in the ``test`` column as ``<category>:<trajectory>`` (``id:f0.15_mid``)
plus a pooled row per category (``id:all``):

``id``           the paper's tests (virtual: 0.15 and 0.45 Hz; catheter_2023: set 2)
``ood_freq``     (virtual) decaying sinusoids at 0.6-1.0 Hz
``ood_amp``      (virtual) amplitude 20 % beyond training (q_max 3.6 mm)
``ood_baseline`` (virtual) trained on the zero and mid baselines, tested on 'end'
``ood_steps``    (virtual) random-step commands
``data_1``, ``data_3``, ``data_all``  the id tests, trained on 1, 3 and all training runs
"""

from __future__ import annotations

import platform
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from physics.data._atomic import write_json, write_text
from ._reproduce import label
from physics.data import DataError, Dataset, nrmse, rmse

__all__ = ["PRESETS", "CompareData", "Row", "CompareResult", "compare", "compare_data"]

NETS = ("fnn", "fnn-hib", "lstm")
#: Per preset: settings of each network (learned and residual alike), the neural ODE, the model-based
#: inverse, and which directions the extra trainings (ood_baseline, data_1/3) run in.
PRESETS: dict[str, dict[str, Any]] = {
    "quick": {
        "networks": {"fnn": dict(epochs=30, stride=2, validation=0.1, patience=6),
                     "fnn-hib": dict(epochs=30, stride=2, validation=0.1, patience=6),
                     "lstm": dict(epochs=20, stride=6, validation=0.1, patience=5)},
        "ode": dict(epochs=3, segment_len=50, batch_size=16),
        "inverse": dict(window=20, commit=10),
        "extra_directions": ("forward",), "ode_extra": False,
    },
    "paper": {
        "networks": {m: dict(epochs=500, stride=1) for m in NETS},
        "ode": dict(epochs=100, segment_len=50, batch_size=16),
        "inverse": dict(window=50, commit=25),
        "extra_directions": ("forward", "inverse"), "ode_extra": True,
    },
    "tiny": {
        "networks": {m: dict(epochs=1, stride=10) for m in NETS},
        "ode": dict(epochs=1, segment_len=25, batch_size=64),
        "inverse": dict(window=10, commit=10),
        "extra_directions": ("forward",), "ode_extra": False,
    },
}


@dataclass(frozen=True)
class Row:
    """One score: ``kind`` is "physics", "learned" or "hybrid"; ``test`` is "<category>:<run>" or "<category>:all"."""

    direction: str
    model: str
    kind: str
    test: str
    rmse: float
    nrmse: float
    n: int


@dataclass
class CompareData:
    """Training runs, test runs per category, and the extra training sets."""

    train: Dataset
    tests: dict[str, Dataset]
    baseline: tuple[Dataset, Dataset] | None = None  # (train without 'end', 'end' tests)
    subsets: dict[str, Dataset] = field(default_factory=dict)
    noise_floor: float | None = None
    name: str = ""


@dataclass
class CompareResult:
    out: Path
    rows: list[Row]
    fit_seconds: dict[str, float]
    seconds: float


class _Physics:
    """The physics model alone as a predictor: ``Series.simulate`` forward, ``Series.inverse`` inverse."""

    def __init__(self, series, direction):
        self.series, self.direction = series, direction

    def predict(self, traj):
        return self.series.simulate(traj.u) if self.direction == "forward" else self.series.inverse(traj.y)


# --------------------------------------------------------------------- data
def compare_data(data: str, seed: int = 0, preset: str = "quick") -> CompareData:
    """The data of a comparison: ``"virtual"`` (all categories), ``"catheter_2023"`` or a folder (id and data)."""
    if data != "virtual":
        from ._reproduce import load_data

        split = load_data(data, seed=seed)
        return CompareData(split.train, {"id": split.test}, None, _subsets(split.train), None, data)
    from physics.virtual import DecayingSinusoid, RandomSteps, VirtualCatheter, paper_protocol

    cath = VirtualCatheter(seed=seed)
    tiny = preset == "tiny"
    split = paper_protocol(cath, frequencies=(0.4, 0.5) if tiny else (0.1, 0.2, 0.3, 0.4, 0.5),
                           tests=(0.45,) if tiny else (0.15, 0.45))
    freqs, amps = ((0.8,), (0.45,)) if tiny else ((0.6, 0.8, 1.0), (0.15, 0.45))
    steps = (0,) if tiny else (0, 1)
    tests = {
        "id": split.test,
        "ood_freq": Dataset(cath.run(DecayingSinusoid(f, "mid"), name=f"f{f:.2f}_mid") for f in freqs),
        "ood_amp": Dataset(cath.run(DecayingSinusoid(f, "mid", q_max_mm=3.6), name=f"f{f:.2f}_mid_q3.6")
                           for f in amps),
        "ood_steps": Dataset(cath.run(RandomSteps(duration_s=20.0 if tiny else 60.0, seed=s), name=f"seed{s}")
                             for s in steps),
    }
    keep = [t for t in split.train if t.meta.get("baseline") != "end"]
    ends = [t for t in split.test if t.meta.get("baseline") == "end"]
    return CompareData(split.train, tests, (Dataset(keep), Dataset(ends)), _subsets(split.train), cath.noise_floor,
                       "virtual")


def _subsets(train: Dataset) -> dict[str, Dataset]:
    """1 run (the middle one: 0.3 Hz mid on the virtual protocol) and 3 runs spread over the list."""
    n = len(train)
    out = {"data_1": Dataset([train[n // 2]])}
    if n > 3:
        out["data_3"] = Dataset([train[int(i)] for i in np.linspace(0, n - 1, 3).round().astype(int)])
    return out


def test_name(traj) -> str:
    name = label(traj)
    return name[5:] if name.startswith("test_") else name


# ------------------------------------------------------------------ scoring
def score(model, direction: str, name: str, kind: str, category: str, tests: Dataset) -> list[Row]:
    ys, yhats, rows = [], [], []
    for traj in tests:
        y = traj.y if direction == "forward" else traj.u
        yhat = np.asarray(model.predict(traj), dtype=float)
        ys.append(y)
        yhats.append(yhat)
        rows.append(Row(direction, name, kind, f"{category}:{test_name(traj)}", rmse(y, yhat), nrmse(y, yhat), len(y)))
    y, yhat = np.concatenate(ys), np.concatenate(yhats)
    rows.append(Row(direction, name, kind, f"{category}:all", rmse(y, yhat), nrmse(y, yhat), len(y)))
    return rows


# ---------------------------------------------------------------------- job
def _models(train: Dataset, direction: str, preset: dict, seed: int, progress, ode: bool, inverse: bool,
            timings: dict, tag: str) -> dict[str, tuple[str, Any]]:
    """Fit every model of one direction on ``train``: name -> (kind, fitted model)."""
    from identification import identify

    from hybrid.models._hybrid import HybridModel
    from hybrid.control._inverse import ModelInverse
    from hybrid.learning._learned import LearnedModel
    from hybrid.models._neural_ode import NeuralODEHybrid
    from hybrid.networks import make_network

    def timed(key, fn):
        t0 = time.perf_counter()
        out = fn()
        timings[f"{tag}/{direction}/{key}"] = round(time.perf_counter() - t0, 2)
        return out

    fit = timed("physics", lambda: identify("backlash+boucwen+linear", list(train)))
    models: dict[str, tuple[str, Any]] = {"physics": ("physics", _Physics(fit.model(), direction))}
    common = dict(seed=seed, progress=progress, threads=1)
    for m in NETS:
        s = {**preset["networks"][m], **common}
        models[m] = ("learned", timed(m, lambda: LearnedModel(make_network(m), direction, **s).fit(train)))
    for m in NETS:
        s = {**preset["networks"][m], **common}
        models[f"{m}+physics"] = ("hybrid", timed(f"{m}+physics", lambda: HybridModel(fit, m, direction, **s).fit(train)))
    if direction == "forward" and ode:
        models["neural-ode"] = ("hybrid", timed("neural-ode", lambda: NeuralODEHybrid(
            fit, **preset["ode"], **common).fit(train)))
    if direction == "inverse" and inverse:
        forward = HybridModel(fit, "fnn-hib", "forward", **{**preset["networks"]["fnn-hib"], **common})
        u = np.concatenate([t.u for t in train])
        bounds = (float(u.min()) - 1.0, float(u.max()) + 1.0)
        models["model-inverse:fnn-hib+physics"] = ("hybrid", timed("model-inverse", lambda: ModelInverse(
            forward, u_bounds=bounds, **preset["inverse"]).fit(train)))
    return models


def compare(data: CompareData, out: str | Path, preset: str = "quick", seed: int = 0, progress: bool | None = None,
            figures: bool = True, directions=("forward", "inverse")) -> CompareResult:
    """Train and score everything; write ``out/compare.csv``, ``out/compare.md``, ``out/run.json``, figures."""
    from hybrid.learning._learned import _threads

    if preset not in PRESETS:
        raise DataError(f"unknown preset {preset!r}. Must be one of ['quick', 'paper'].")
    cfg, out = PRESETS[preset], Path(out)
    start, rows, timings, fitted = time.perf_counter(), [], {}, {}
    with _threads(1):
        for direction in directions:
            models = _models(data.train, direction, cfg, seed, progress, True, True, timings, "all")
            fitted[direction] = models
            for name, (kind, model) in models.items():
                for category, tests in data.tests.items():
                    rows += score(model, direction, name, kind, category, tests)
            # data_all: the id scores of the models trained on every run (the same numbers, renamed)
            rows += [Row(r.direction, r.model, r.kind, "data_all:" + r.test[3:], r.rmse, r.nrmse, r.n)
                     for r in rows if r.direction == direction and r.test.startswith("id:")]
            if direction not in cfg["extra_directions"]:
                continue
            extra = dict(data.subsets)
            if data.baseline is not None:
                extra["ood_baseline"] = data.baseline[0]
            for category, train in extra.items():
                models = _models(train, direction, cfg, seed, progress, cfg["ode_extra"], False, timings, category)
                tests = data.baseline[1] if category == "ood_baseline" else data.tests["id"]
                for name, (kind, model) in models.items():
                    rows += score(model, direction, name, kind, category, tests)
    result = CompareResult(out, rows, timings, 0.0)
    write_tables(rows, out, data)
    if figures:
        from ._compare_plots import plot_all

        plot_all(fitted, data, rows, out / "figures")
    result.seconds = time.perf_counter() - start
    write_json(out / "run.json", {"data": data.name, "preset": preset, "seed": seed, "settings": _jsonable(cfg),
                                  "train": list(data.train.names),
                                  "tests": {k: list(v.names) for k, v in data.tests.items()},
                                  "fit_seconds": timings, "total_seconds": round(result.seconds, 1),
                                  "noise_floor": data.noise_floor, "python": platform.python_version()})
    return result


def _jsonable(cfg):
    return {k: (list(v) if isinstance(v, tuple) else v) for k, v in cfg.items()}


# ------------------------------------------------------------------ tables
def write_tables(rows: list[Row], out: Path, data: CompareData) -> None:
    lines = ["direction,model,kind,test,rmse,nrmse"] + [
        f"{r.direction},{r.model},{r.kind},{r.test},{r.rmse:.6g},{r.nrmse:.6g}" for r in rows]
    write_text(out / "compare.csv", "\n".join(lines) + "\n")
    write_text(out / "compare.md", markdown(rows, data))


def pooled(rows: list[Row], direction: str) -> dict[tuple[str, str], Row]:
    return {(r.model, r.test.split(":")[0]): r for r in rows if r.direction == direction and r.test.endswith(":all")}


def markdown(rows: list[Row], data: CompareData) -> str:
    first = data.train[0]
    units = {"forward": first.output_unit or "output units", "inverse": first.input_unit or "input units"}
    lines = [f"# Physics, learned and hybrid models on {data.name or 'data'}", "",
             "Pooled RMSE per test category (per-run rows in compare.csv). id: the paper's tests; "
             "ood_*: out of distribution; data_k: trained on k runs.", ""]
    if data.noise_floor is not None:
        lines += [f"Noise floor of the virtual catheter: {data.noise_floor:.3g} deg (forward).", ""]
    for direction in dict.fromkeys(r.direction for r in rows):
        table = pooled(rows, direction)
        cats = list(dict.fromkeys(c for _, c in table))
        models = list(dict.fromkeys(m for m, _ in table))
        kinds = {r.model: r.kind for r in rows}
        lines += [f"## {direction.capitalize()}, RMSE ({units[direction]})", "",
                  "| model | kind | " + " | ".join(cats) + " |", "|---" * (len(cats) + 2) + "|"]
        for m in models:
            cells = [f"{table[m, c].rmse:.3f}" if (m, c) in table else "-" for c in cats]
            lines.append(f"| {m} | {kinds[m]} | " + " | ".join(cells) + " |")
        lines += ["", *summary(table, cats, kinds, data.noise_floor if direction == "forward" else None), ""]
    return "\n".join(lines) + "\n"


def summary(table, cats, kinds, noise_floor) -> list[str]:
    """Best hybrid against the best pure network (and the noise floor), per category."""
    out = []
    for c in cats:
        best = {k: min(((r.rmse, m) for (m, cc), r in table.items() if cc == c and kinds[m] == k), default=None)
                for k in ("learned", "hybrid", "physics")}
        if best["hybrid"] is None or best["learned"] is None:
            continue
        (h, hm), (p, pm) = best["hybrid"], best["learned"]
        text = f"- {c}: best hybrid {hm} {h:.3f} vs best pure network {pm} {p:.3f} (ratio {h / p:.2f})"
        if noise_floor:
            text += f"; {h / noise_floor:.2f}x the noise floor"
        out.append(text)
    return out
