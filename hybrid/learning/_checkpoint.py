"""Checkpoints of a :class:`LearnedModel`: one ``.pt`` file (weights + JSON-ready metadata)
plus a readable ``.json`` copy of the metadata beside it, both written atomically."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import torch

from physics.data._atomic import atomic_path, write_json
from ._training import TrainingHistory
from physics.data import DataError, MinMaxScaler
from hybrid.networks import network_from_dict

__all__ = ["metadata", "from_metadata", "FORMAT", "VERSION", "write_blob", "read_blob"]

FORMAT = "hysteresis-hybrid/learned-model"
VERSION = 1


def metadata(model) -> dict[str, Any]:
    """A fitted LearnedModel's settings, scalers, history and provenance, JSON-ready."""
    params = model.get_params(deep=False)
    params["network"] = model.network_.to_dict()
    params["features"] = list(params["features"])
    # A JSON round trip turns numpy scalars into plain Python values, which weights_only loading needs.
    return json.loads(json.dumps({
        "format": FORMAT, "version": VERSION, "settings": params, "n_features": model.n_features_in_,
        "input_scaler": model.input_scaler_.to_dict(), "output_scaler": model.output_scaler_.to_dict(),
        "history": model.history_.to_dict(), "provenance": model.provenance_, "torch": str(torch.__version__),
    }, default=str))


def write_blob(path: Path, meta: dict, tensors: dict) -> None:
    """``meta`` and ``tensors`` in one torch file at ``path``, ``meta`` also in its ``.json``
    sidecar (the loaders dispatch on it); both written atomically."""
    with atomic_path(path) as tmp:
        torch.save({**meta, **tensors}, tmp)
    write_json(path.with_suffix(".json"), meta)


def read_blob(path: str | os.PathLike[str], fmt: str, version: int, kind: str | None = None,
              saved_by: str = "") -> dict[str, Any]:
    """The dict :func:`write_blob` saved, checked to be of format ``fmt`` (and ``kind``) and
    ``version``; loaded safely (``weights_only=True``)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"checkpoint {path} does not exist.")
    try:
        blob = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # noqa: BLE001 - any unpickling failure means "not our file"
        raise DataError(f"{path} is not a readable checkpoint ({type(exc).__name__}: {exc}).") from None
    if not isinstance(blob, dict) or blob.get("format") != fmt or (kind is not None and blob.get("kind") != kind):
        what = f"{fmt} checkpoint" + (f" of kind {kind!r}" if kind is not None else "")
        raise DataError(f"{path} is not a {what}{f' (saved by {saved_by})' if saved_by else ''}.")
    if blob.get("version") != version:
        raise DataError(f"{path} has checkpoint version {blob.get('version')!r}; this code reads version {version}.")
    return blob


def from_metadata(cls, meta: dict, state_dict: dict):
    """The fitted ``cls`` (a LearnedModel) that :func:`metadata` described, with its weights."""
    settings = dict(meta["settings"])
    network = network_from_dict(settings.pop("network"))
    settings["features"] = tuple(settings["features"])
    model = cls(network, **settings)
    module = network.build(int(meta["n_features"]), 1)
    module.load_state_dict(state_dict)
    model.module_ = module.eval()
    model.n_features_in_ = int(meta["n_features"])
    model.input_scaler_ = MinMaxScaler.from_dict(meta["input_scaler"])
    model.output_scaler_ = MinMaxScaler.from_dict(meta["output_scaler"])
    model.history_ = TrainingHistory.from_dict(meta["history"])
    model.provenance_ = meta["provenance"]
    return model
