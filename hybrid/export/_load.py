"""``load``: any saved model, whatever wrote it.

A source is a checkpoint (``.pt`` with its ``.json`` sidecar: learned, hybrid or
neural-ODE hybrid; the sidecar's ``format`` and ``kind`` name the class), a physics
fit JSON (from ``hyst identify``), an exported ``.casadi`` step, a model folder
written by ``hyst fit`` (its ``card.json`` names the model), a folder holding
exactly one of those, or else a physics spec (``"lag+boucwen+linear"``).
"""

from __future__ import annotations

import importlib
import math
from pathlib import Path
from typing import Any, Callable

from physics import PhysicsError, Series
from physics.data._io import read_json

from ._model import ExportedModel, ExportError

__all__ = ["load", "model_rate_hz", "folder_intervals", "CHECKPOINTS", "JSON_MODELS", "MODEL_LOADERS"]

#: (format, kind) of a checkpoint's sidecar -> "module:Class" whose ``load(path)`` reads it; kind None
#: matches any. Classes are imported on first use, so loading a fit never imports torch.
CHECKPOINTS = {
    ("hysteresis-hybrid/learned-model", None): "hybrid.learning._learned:LearnedModel",
    ("hysteresis-hybrid/hybrid-model", "residual"): "hybrid.models._hybrid:HybridModel",
    ("hysteresis-hybrid/hybrid-model", "neural-ode"): "hybrid.models._neural_ode:NeuralODEHybrid",
}

#: ``format`` of a JSON model file -> "module:Class" whose ``load(path)`` reads it (a peer chosen as the model).
JSON_MODELS = {"hysteresis-hybrid/linear-arx/1": "hybrid.peers._arx:LinearARX"}


def _checkpoint(path: Path, dt: float | None, allow_external: bool = False):
    path, sidecar = path.with_suffix(".pt"), path.with_suffix(".json")
    if not path.is_file() or not sidecar.is_file():
        raise ExportError(f"No checkpoint at '{path}' (needs {path.name} and {sidecar.name}); write one with "
                          f"`hyst train --out {path}`.")
    info = read_json(sidecar, "checkpoint sidecar")
    key = (info.get("format"), info.get("kind")) if isinstance(info, dict) else (None, None)
    target = CHECKPOINTS.get(key) or CHECKPOINTS.get((key[0], None))
    if target is None:
        known = ", ".join(f"{f} ({k or 'any'})" for f, k in CHECKPOINTS)
        raise ExportError(f"'{sidecar}' has format {key[0]!r}, kind {key[1]!r}; known: {known}.")
    module, _, name = target.partition(":")
    return getattr(importlib.import_module(module), name).load(path)


def _fit_json(path: Path, info: dict, dt: float | None):
    """The fitted Series: its structure from the ``"series"`` entry (dt and every structural
    setting), else from the spec at the fit's ``"dt"``, else (old files) at the rate given; its
    parameters checked: every one present, a finite number, and the copies in the file agreeing."""
    try:
        series = info.get("series")
        if isinstance(series, dict):
            model = Series.from_dict({k: v for k, v in series.items() if k not in ("parameters", "params")})
        else:
            model = Series.from_spec(str(info["model"]), dt=_number(path, "dt", info.get("dt") or dt or 0.04))
    except ExportError:
        raise
    except (PhysicsError, ValueError, TypeError) as exc:
        raise ExportError(f"'{path}' does not describe a physics model: {exc}") from None
    sources = {"parameters": info["parameters"]}
    if isinstance(series, dict) and "parameters" in series:
        sources["series.parameters"] = series["parameters"]
    elif isinstance(series, dict) and "params" in series:
        values = series["params"]
        if not isinstance(values, list) or len(values) != model.n_p:
            raise ExportError(f"'{path}': series.params must list {model.n_p} numbers ({', '.join(model.param_names)}).")
        sources["series.params"] = dict(zip(model.param_names, values))
    checked = {where: _parameters(path, where, values, model) for where, values in sources.items()}
    first, values = next(iter(checked.items()))
    for where, other in checked.items():
        differ = [n for n in values if other[n] != values[n]]
        if differ:
            n = differ[0]
            raise ExportError(f"'{path}': {first} and {where} disagree on {n} ({values[n]!r} vs {other[n]!r}); "
                              f"edit both, or delete 'series' to use {first}.")
    return model.set_params(**values)


def _number(path: Path, name: str, value: Any) -> float:
    """``value`` as a finite float, or an error naming the entry and the file."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ExportError(f"'{path}': {name} is {value!r}, not a number; put the fitted value back "
                          "(or fit again with `hyst identify`).")
    if not math.isfinite(value):
        shown = "NaN" if math.isnan(value) else ("Infinity" if value > 0 else "-Infinity")  # as JSON writes it
        raise ExportError(f"'{path}': {name} is {shown}; a model needs finite parameters "
                          "(fit again with `hyst identify`).")
    return float(value)


def _parameters(path: Path, where: str, values: Any, model: Series) -> dict[str, float]:
    """``values`` checked against ``model``: a dict naming each of its parameters once, each a finite number."""
    if not isinstance(values, dict):
        raise ExportError(f"'{path}': {where} must map parameter names to numbers; got {type(values).__name__}.")
    names = model.param_names
    missing = [n for n in names if n not in values]
    if missing:
        raise ExportError(f"'{path}': {where} has no value for {missing[0]}; a fit of '{model.spec}' needs "
                          f"{', '.join(names)}.")
    unknown = [n for n in values if n not in names]
    if unknown:
        raise ExportError(f"'{path}': {where} names {unknown[0]!r}, which '{model.spec}' does not have "
                          f"(its parameters: {', '.join(names)}).")
    return {n: _number(path, f"parameter {n} ({where})", values[n]) for n in names}


def _json(path: Path, dt: float | None, allow_external: bool = False):
    info = read_json(path, "model file")
    fmt = str(info.get("format", "")) if isinstance(info, dict) else ""
    if isinstance(info, dict) and "model" in info and "parameters" in info:
        return _fit_json(path, info, dt)
    if any(fmt == f for f, _ in CHECKPOINTS):
        return _checkpoint(path, dt)
    if fmt in JSON_MODELS:
        module, _, name = JSON_MODELS[fmt].partition(":")
        return getattr(importlib.import_module(module), name).load(path)
    if fmt.startswith("hysteresis-hybrid/exported-model"):
        return ExportedModel.load(path.with_suffix(""), allow_external)  # step.casadi.json -> step.casadi
    raise ExportError(f"'{path}' is neither a physics fit (keys 'model', 'parameters', from `hyst identify`) "
                      "nor a checkpoint or exported-model sidecar.")


#: The manifest of a model folder written by ``hyst fit`` (``hybrid.experiments.fit_model_dir``).
MODEL_DIR_MANIFEST = "card.json"

#: File suffix -> loader ``f(path, dt, allow_external) -> model``.
MODEL_LOADERS: dict[str, Callable[[Path, float | None, bool], Any]] = {
    ".json": _json,
    ".pt": _checkpoint,
    ".casadi": lambda path, dt, allow_external: ExportedModel.load(path, allow_external),
}


def model_rate_hz(source: str | Path, model) -> float | None:
    """The rate (Hz) the model loaded from ``source`` runs at, None when it stores none.

    A model folder's ``rate_hz`` (its ``card.json``); else the model's own sample time (a physics
    fit, a hybrid's physics, an exported step); else the one rate of the data a learned model was
    trained on (its provenance). ``hyst predict``, ``hyst export`` and ``hyst mpc`` all ask here.
    """
    manifest = Path(source) / MODEL_DIR_MANIFEST
    if manifest.is_file():
        info = read_json(manifest, "model-folder manifest (`hyst fit`)")
        rate = info.get("rate_hz") if isinstance(info, dict) else None
        if isinstance(rate, (int, float)) and not isinstance(rate, bool) and math.isfinite(rate) and rate > 0:
            return float(rate)
    dt = getattr(getattr(model, "physics_", model), "dt", None)
    if dt:
        return 1.0 / dt
    learned = getattr(model, "residual_", model)
    rates = {float(p["meta"]["rate_hz"]) for p in getattr(learned, "provenance_", None) or []
             if isinstance(p, dict) and isinstance(p.get("meta"), dict) and p["meta"].get("rate_hz")}
    return rates.pop() if len(rates) == 1 else None


def folder_intervals(folder: str | Path):
    """``(intervals, why)``: the calibrated :class:`~hybrid.intervals.ConformalIntervals` of a model
    folder from ``hyst fit`` and None, or None and why it has none."""
    from hybrid.intervals import ConformalIntervals

    folder = Path(folder)
    if not (folder / MODEL_DIR_MANIFEST).is_file():
        return None, (f"'{folder}' is not a model folder written by `hyst fit` (which calibrates intervals on runs "
                      "held out of its fits)")
    info = read_json(folder / MODEL_DIR_MANIFEST, "model-folder manifest (`hyst fit`)")
    if not info.get("intervals"):
        stages = read_json(folder / "stages.json", "stages") if (folder / "stages.json").is_file() else {}
        return None, (stages.get("intervals") or {}).get("result", {}).get(
            "why", "it was fitted before intervals existed; fit it again")
    return ConformalIntervals.from_dict(read_json(folder / info["intervals"], "intervals")), None


def load(source: str | Path, rate_hz: float | None = None, allow_external: bool = False):
    """The model saved at ``source`` (see the module docstring for what a source may be).

    Parameters
    ----------
    source : str or Path
    rate_hz : float, optional
        Sample rate of a physics spec, and of an old fit JSON that does not store its
        own ``dt`` (default 25 Hz). A saved model's own rate always wins.
    allow_external : bool
        Read a ``.casadi`` model even if it calls an external library or is compiled on load:
        that runs native code, so only for files you trust (``--allow-external``).
    """
    if rate_hz is not None and not rate_hz > 0:
        raise ExportError(f"The rate must be > 0 Hz. Got {rate_hz} instead.")
    dt = None if rate_hz is None else 1.0 / rate_hz
    path = Path(source)
    if path.is_dir() and (path / MODEL_DIR_MANIFEST).is_file():  # a folder written by `hyst fit`
        info = read_json(path / MODEL_DIR_MANIFEST, "model-folder manifest (`hyst fit`)")
        if not isinstance(info, dict) or not isinstance(info.get("model"), str):
            raise ExportError(f"'{path / MODEL_DIR_MANIFEST}' names no model file; write the folder again "
                              "with `hyst fit`.")
        path = path / info["model"]
    elif path.is_dir():
        found = sorted(p for p in path.iterdir() if p.suffix in (".pt", ".casadi")
                       or (p.suffix == ".json" and not p.with_suffix(".pt").exists()
                           and not p.with_suffix(".casadi").exists()))
        if len(found) != 1:
            names = ", ".join(p.name for p in found) or "none"
            raise ExportError(f"The folder '{path}' must hold exactly one model file (.json fit, .pt, "
                              f".casadi); found: {names}. Name the file instead.")
        path = found[0]
    if path.is_file():
        loader = MODEL_LOADERS.get(path.suffix)
        if loader is None:
            raise ExportError(f"Unknown model file '{path.name}'. Must end in one of: {', '.join(MODEL_LOADERS)}.")
        return loader(path, dt, allow_external)
    if path.suffix == ".pt":
        return _checkpoint(path, dt)  # says what is missing and how to write it
    if any(ch in str(source) for ch in "/\\") or path.suffix in MODEL_LOADERS:
        raise ExportError(f"No model file at '{source}'.")
    try:
        return Series.from_spec(str(source), dt=dt or 0.04)
    except PhysicsError as exc:
        raise ExportError(f"'{source}' is not a model file nor a valid spec: {exc}") from None
