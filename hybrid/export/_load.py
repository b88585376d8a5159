"""``load``: any saved model, whatever wrote it.

A source is a checkpoint (``.pt`` with its ``.json`` sidecar: learned, hybrid or
neural-ODE hybrid; the sidecar's ``format`` and ``kind`` name the class), a physics
fit JSON (from ``hyst identify``), an exported ``.casadi`` step, a model folder
written by ``hyst fit`` (its ``card.json`` names the model), a folder holding
exactly one of those, or else a physics spec (``"lag+boucwen+linear"``).
"""

from __future__ import annotations

import hashlib
import importlib
import math
from pathlib import Path
from typing import Any, Callable

from physics import PhysicsError, Series
from physics.data.io import read_json

from ._model import ExportedModel, ExportError

__all__ = ["load", "model_rate_hz", "folder_intervals", "read_card", "read_stages", "check_folder_files",
           "model_folder_of", "file_sha256", "CHECKPOINTS", "JSON_MODELS", "MODEL_LOADERS", "register_checkpoint",
           "register_json_model"]

#: (format, kind) of a checkpoint's sidecar -> public "package.Class" whose ``load(path)`` reads it; kind
#: None matches any. Each model kind's export module registers its own (:func:`register_checkpoint`);
#: the class is imported on first use, so loading a fit never imports torch.
CHECKPOINTS: dict[tuple[str, str | None], str] = {}

#: ``format`` of a JSON model file -> public "package.Class" whose ``load(path)`` reads it (a peer chosen
#: as the model; :func:`register_json_model`).
JSON_MODELS: dict[str, str] = {}


def register_checkpoint(format: str, kind: str | None, cls: str) -> None:
    """``load`` reads a checkpoint whose sidecar has this ``format`` and ``kind`` (None: any) with
    ``cls.load(path)``; ``cls`` is the class's public name, ``"package.Class"``, imported on first use."""
    CHECKPOINTS[(format, kind)] = _class_name(cls)


def register_json_model(format: str, cls: str) -> None:
    """``load`` reads a JSON model file of this ``format`` with ``cls.load(path)`` (``"package.Class"``)."""
    JSON_MODELS[format] = _class_name(cls)


def _class_name(cls: str) -> str:
    if not isinstance(cls, str) or "." not in cls.strip("."):
        raise ExportError(f"register a loader by its class's public name 'package.Class'. Got {cls!r} instead.")
    return cls


def _class(name: str):
    module, _, attr = name.rpartition(".")
    return getattr(importlib.import_module(module), attr)


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
    return _class(target).load(path)


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
        return _class(JSON_MODELS[fmt]).load(path)
    if fmt.startswith("hysteresis-hybrid/exported-model"):
        return ExportedModel.load(path.with_suffix(""), allow_external)  # step.casadi.json -> step.casadi
    raise ExportError(f"'{path}' is neither a physics fit (keys 'model', 'parameters', from `hyst identify`) "
                      "nor a checkpoint or exported-model sidecar.")


#: The manifest of a model folder written by ``hyst fit`` (``hybrid.experiments.fit_model_dir``).
MODEL_DIR_MANIFEST = "card.json"
#: The record of a model folder's finished stages (``hyst fit --resume`` reuses them).
MODEL_DIR_STAGES = "stages.json"

_NAME = {"type": "string", "minLength": 1}
#: ``card.json``: what names the model, its rate and its files; every field a reader uses is typed here.
CARD_SCHEMA = {
    "type": "object",
    "required": ["model"],
    "properties": {
        "format": {"type": "string", "pattern": "^hysteresis-hybrid/model-dir/"},
        "model": _NAME, "step": _NAME, "spec": {"type": "string"}, "residual": {"type": "string"},
        "peer": {"type": ["string", "null"]},
        "warmup": {"type": "integer", "minimum": 0},
        "intervals": {"anyOf": [_NAME, {"type": "null"}]},
        "rate_hz": {"anyOf": [{"type": "number", "exclusiveMinimum": 0}, {"type": "null"}]},
        "columns": {"type": "object", "additionalProperties": {"type": "string"}},
        "rows": {"type": "array", "items": {"type": "object"}},
        "failures": {"type": "array", "items": {"type": "string"}},
        "seconds": {"type": "object", "additionalProperties": {"type": "number"}},
        # every file of the model (path in the folder -> SHA-256), written last by `hyst fit`
        "files": {"type": "object", "additionalProperties": {"type": "string", "pattern": "^[0-9a-f]{64}$"}},
    },
}
_ENTRY = {"type": "object", "required": ["key", "result"],
          "properties": {"key": {"type": "string"},
                         "files": {"type": "object", "additionalProperties": {"type": "string"}}}}
#: ``stages.json``: per finished stage, the key of its inputs, its result and the files it wrote.
STAGES_SCHEMA = {
    "type": "object",
    "additionalProperties": _ENTRY,
    "properties": {
        "physics": {**_ENTRY, "properties": {**_ENTRY["properties"], "result": {
            "type": "object", "required": ["spec", "ranked"],
            "properties": {"spec": {"type": "string"}, "ranked": {"type": "array", "items": {"type": "string"}}}}}},
        "identify": {**_ENTRY, "properties": {**_ENTRY["properties"], "result": {
            "type": "object", "required": ["series"], "properties": {"series": {"type": "object"},
                                                                     "failures": {"type": "array"}}}}},
        "residual": {**_ENTRY, "properties": {**_ENTRY["properties"], "result": {
            "type": "object", "required": ["residual"],
            "properties": {"residual": {"type": "string"}, "model": {"type": ["string", "null"]}}}}},
        "intervals": {**_ENTRY, "properties": {**_ENTRY["properties"], "result": {
            "type": "object", "required": ["intervals"],
            "properties": {"intervals": {"type": ["string", "null"]}, "why": {"type": "string"}}}}},
        "export": {**_ENTRY, "properties": {**_ENTRY["properties"], "result": {
            "type": "object", "properties": {"step": {"type": "string"}, "c_code": {"type": ["string", "null"]}}}}},
    },
}


def _validated(path: Path, info: Any, schema: dict, fix: str) -> Any:
    """``info`` (read from ``path``) if it has the shape of ``schema``, else an ExportError in one line
    naming the file and the field."""
    from jsonschema import Draft202012Validator
    from jsonschema.exceptions import best_match

    error = best_match(Draft202012Validator(schema).iter_errors(info))
    if error is None:
        return info
    field = "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in error.absolute_path).lstrip(".")
    value = error.instance
    shown = repr(value) if len(repr(value)) <= 60 else f"a {type(value).__name__}"
    what = _requirement(error.validator, error.validator_value)
    message = (f"{field or 'the file'} is {shown}; it {what}" if what else
               f"{field or 'the file'}: {error.message if len(error.message) <= 120 else error.message[:117] + '...'}")
    raise ExportError(f"'{path}': {message}; {fix}")


def _requirement(validator: str, value: Any) -> str:
    """What a schema keyword asks for, in words ("must be a number > 0 or null"); "" for the others."""
    if validator == "type":
        return f"must be {_types(value)}"
    if validator == "anyOf":
        return "must be " + " or ".join(_describe(s) for s in value)
    if validator == "minLength":
        return "must not be empty"
    if validator == "exclusiveMinimum":
        return f"must be > {value}"
    if validator == "minimum":
        return f"must be >= {value}"
    if validator == "pattern":
        return f"must match {value!r}"
    return ""


def _types(kind) -> str:
    names = {"number": "a number", "integer": "an integer", "string": "a string", "object": "an object ({...})",
             "array": "a list", "null": "null", "boolean": "true or false"}
    return " or ".join(names.get(k, k) for k in ([kind] if isinstance(kind, str) else kind))


def _describe(schema: dict) -> str:
    if schema.get("minLength"):
        return "a non-empty string"
    text = _types(schema.get("type", "any"))
    return text + (f" > {schema['exclusiveMinimum']}" if "exclusiveMinimum" in schema else "")


def read_card(folder: str | Path) -> dict:
    """A model folder's ``card.json``, checked against :data:`CARD_SCHEMA` (rate finite too)."""
    path = Path(folder) / MODEL_DIR_MANIFEST
    info = _validated(path, read_json(path, "model-folder manifest (`hyst fit`)"), CARD_SCHEMA,
                      "write the folder again with `hyst fit`.")
    rate = info.get("rate_hz")
    if isinstance(rate, float) and not math.isfinite(rate):
        raise ExportError(f"'{path}': rate_hz is {rate}; it must be a finite number > 0 or null; write the folder "
                          "again with `hyst fit`.")
    return info


def read_stages(path: str | Path) -> dict:
    """A model folder's ``stages.json``, checked against :data:`STAGES_SCHEMA`."""
    path = Path(path)
    return _validated(path, read_json(path, "stages of `hyst fit`"), STAGES_SCHEMA,
                      "delete it, or fit again without --resume.")


def file_sha256(path: str | Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def check_folder_files(folder: str | Path, info: dict, names=None) -> None:
    """Refuse a model folder whose files (``names``, default all) differ from those its ``card.json``
    lists: changed, cut short or missing since ``hyst fit`` wrote them. A card without ``files`` (older
    folders) lists none."""
    folder = Path(folder)
    listed = info.get("files") or {}
    for name in listed if names is None else [n for n in names if n in listed]:
        path = folder / name
        inside = Path(name).parts and ".." not in Path(name).parts and not Path(name).is_absolute()
        if not inside:
            raise ExportError(f"'{folder / MODEL_DIR_MANIFEST}': files names {name!r}, outside the folder; write "
                              "the folder again with `hyst fit`.")
        if not path.is_file():
            raise ExportError(f"'{path}' is missing from the model folder (its card.json lists it); fit again "
                              "with `hyst fit`, or restore the file.")
        if file_sha256(path) != listed[name]:
            raise ExportError(f"'{path}' is not the file `hyst fit` wrote (changed or cut short: its SHA-256 differs "
                              "from card.json's); fit again, or restore the file.")


def _check_folder_file(path: Path) -> None:
    """A model file loaded from a model folder by name: it and its sidecar as ``hyst fit`` wrote them."""
    info = read_card(path.parent)
    names = [path.name, path.with_suffix(".json").name, path.name + ".json"]
    check_folder_files(path.parent, info, [n for n in names if n != MODEL_DIR_MANIFEST])


def model_folder_of(path: str | Path) -> Path | None:
    """The model folder (holding ``card.json``) that ``path`` is, or lies in, else None."""
    path = Path(path).absolute()
    for folder in (path, *path.parents[:2]):  # the folder, a file in it, a file in its c/
        if (folder / MODEL_DIR_MANIFEST).is_file():
            return folder
    return None


def _folder_model_file(folder: Path, name: str) -> Path:
    """The model file ``name`` that a model folder's ``card.json`` names, or an error naming that file."""
    path = folder / name
    if not path.is_file():
        raise ExportError(f"'{path}' is missing: it is the model file '{folder / MODEL_DIR_MANIFEST}' names; "
                          "restore it, or fit the folder again with `hyst fit`.")
    return path


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
    if (Path(source) / MODEL_DIR_MANIFEST).is_file():
        rate = read_card(source).get("rate_hz")
        if rate is not None:
            return float(rate)
    dt = getattr(getattr(model, "physics_", model), "dt", None)
    if dt:
        return 1.0 / dt
    learned = getattr(model, "residual_", model)
    rates = {float(p["meta"]["rate_hz"]) for p in getattr(learned, "provenance_", None) or []
             if isinstance(p, dict) and isinstance(p.get("meta"), dict) and p["meta"].get("rate_hz")}
    return rates.pop() if len(rates) == 1 else None


def folder_intervals(folder: str | Path, output: str | None = None):
    """``(intervals, why)``: the calibrated :class:`~hybrid.intervals.ConformalIntervals` of a model
    folder from ``hyst fit`` and None, or None and why it has none. A folder of several outputs has one per
    output: ``output`` names it."""
    from hybrid.intervals import ConformalIntervals

    folder = Path(folder)
    if not (folder / MODEL_DIR_MANIFEST).is_file():
        return None, (f"'{folder}' is not a model folder written by `hyst fit` (which calibrates intervals on runs "
                      "held out of its fits)")
    info = read_card(folder)
    if not info.get("intervals"):
        stages = read_stages(folder / MODEL_DIR_STAGES) if (folder / MODEL_DIR_STAGES).is_file() else {}
        return None, (stages.get("intervals") or {}).get("result", {}).get(
            "why", "it was fitted before intervals existed; fit it again")
    check_folder_files(folder, info, [info["intervals"]])
    stored = read_json(folder / info["intervals"], "intervals")
    if info.get("outputs"):
        from hybrid.intervals import per_output_from_dict

        if output is None:
            return None, (f"its intervals are per output ({', '.join(info['outputs'])}): name one with "
                          "--track OUTPUT")
        return per_output_from_dict(stored)[output], None
    return ConformalIntervals.from_dict(stored), None


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
        info = read_card(path)
        check_folder_files(path, info)  # the folder is one unit: every file as `hyst fit` wrote it
        path = _folder_model_file(path, info["model"])
    elif path.is_dir():
        found = sorted(p for p in path.iterdir() if p.suffix in (".pt", ".casadi")
                       or (p.suffix == ".json" and not p.with_suffix(".pt").exists()
                           and not p.with_suffix(".casadi").exists()))
        if len(found) != 1:
            names = ", ".join(p.name for p in found) or "none"
            raise ExportError(f"The folder '{path}' must hold exactly one model file (.json fit, .pt, "
                              f".casadi); found: {names}. Name the file instead.")
        path = found[0]
    elif path.is_file() and (path.parent / MODEL_DIR_MANIFEST).is_file():  # one file of a model folder
        _check_folder_file(path)
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
