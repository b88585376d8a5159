"""Models named on the command line: a physics spec, a fit JSON, a learned checkpoint, or a folder."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Callable

from ._model import ExportedModel, ExportError

__all__ = ["load_model", "MODEL_LOADERS"]

_CHECKPOINT_FORMATS = ("hysteresis-hybrid/learned-model", "hysteresis-hybrid/hybrid-model")


def _fit_json(path: Path, info: dict, dt: float):
    """The fitted Series: from its ``"series"`` entry (dt and every structural setting), else
    from the spec at the fit's ``"dt"``, else (old files) at the rate given."""
    from physics import PhysicsError, Series

    try:
        if isinstance(info.get("series"), dict):
            return Series.from_dict(info["series"])
        model = Series.from_spec(str(info["model"]), dt=float(info.get("dt") or dt))
        model.set_params(**{k: float(v) for k, v in info["parameters"].items()})
    except PhysicsError as exc:
        raise ExportError(f"'{path}' does not describe a physics model: {exc}") from None
    return model


def _learned(path: Path, dt: float):
    from ._load import load_checkpoint_any

    return load_checkpoint_any(path)


def _json(path: Path, dt: float):
    try:
        info = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise ExportError(f"'{path}' is not valid JSON ({exc}).") from None
    if isinstance(info, dict) and "model" in info and "parameters" in info:
        return _fit_json(path, info, dt)
    if isinstance(info, dict) and str(info.get("format", "")) in _CHECKPOINT_FORMATS:
        return _learned(path.with_suffix(".pt"), dt)
    if isinstance(info, dict) and str(info.get("format", "")).startswith("hysteresis-hybrid/exported-model"):
        return ExportedModel.load(path.with_suffix(""))  # step.casadi.json -> step.casadi
    raise ExportError(f"'{path}' is neither a physics fit (keys 'model', 'parameters', from `hyst identify`) "
                      "nor a learned-model or exported-model sidecar.")


#: File suffix -> loader ``f(path, dt) -> model``. Hybrid checkpoints plug in here.
MODEL_LOADERS: dict[str, Callable[[Path, float], Any]] = {
    ".json": _json,
    ".pt": _learned,
    ".casadi": lambda path, dt: ExportedModel.load(path),
}


def load_model(source: str, rate_hz: float = 25.0):
    """The model named by ``source``: a fit JSON, a ``.pt`` checkpoint, an exported ``.casadi``,
    a folder holding exactly one of those, or else a physics spec (``"lag+boucwen+linear"``)."""
    if not rate_hz > 0:
        raise ExportError(f"The rate must be > 0 Hz. Got {rate_hz} instead.")
    dt = 1.0 / rate_hz
    path = Path(source)
    if path.is_dir():
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
        return loader(path, dt)
    if any(ch in source for ch in "/\\") or Path(source).suffix in MODEL_LOADERS:
        raise ExportError(f"No model file at '{source}'.")
    from physics import PhysicsError, Series

    try:
        return Series.from_spec(source, dt=dt)
    except PhysicsError as exc:
        raise ExportError(f"'{source}' is not a model file nor a valid spec: {exc}") from None
