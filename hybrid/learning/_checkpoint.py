"""Checkpoints of a :class:`LearnedModel`: one ``.pt`` file (weights + JSON-ready metadata)
plus a readable ``.json`` copy of the metadata beside it.

The two are a pair: written together (both or neither) and stamped with the same ``pair_id``, a
digest of the metadata and the weights, which loading checks, so a ``.pt`` is never read with
another model's ``.json``."""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
from typing import Any

import torch

from physics.data.io import atomic_paths, read_json
from ._settings import training_from_dict
from ._training import TrainingHistory
from physics.data import DataError, MinMaxScaler
from hybrid.networks import network_from_dict

__all__ = ["metadata", "from_metadata", "FORMAT", "VERSION", "write_blob", "read_blob", "pair_id", "check_pair"]

FORMAT = "hysteresis-hybrid/learned-model"
VERSION = 1


def metadata(model) -> dict[str, Any]:
    """A fitted LearnedModel's settings, scalers, history and provenance, JSON-ready."""
    params = model.get_params(deep=False)
    params["network"] = model.network_.to_dict()
    params["features"] = list(params["features"])
    if "outputs" in params and not tuple(params["outputs"]):  # a model of one output saves as it always has
        del params["outputs"]
    elif "outputs" in params:
        params["outputs"] = list(params["outputs"])
    params["training"] = params["training"].to_dict()
    # A JSON round trip turns numpy scalars into plain Python values, which weights_only loading needs.
    return json.loads(json.dumps({
        "format": FORMAT, "version": VERSION, "settings": params, "n_features": model.n_features_in_,
        "input_scaler": model.input_scaler_.to_dict(), "output_scaler": model.output_scaler_.to_dict(),
        "history": model.history_.to_dict(), "provenance": model.provenance_, "torch": str(torch.__version__),
    }, default=str))


def write_blob(path: Path, meta: dict, tensors: dict) -> None:
    """``meta`` and ``tensors`` in one torch file at ``path``, ``meta`` also in its ``.json``
    sidecar (the loaders dispatch on it); both stamped with one ``pair_id`` and written together."""
    path = Path(path)
    meta = {**meta, "pair_id": pair_id(meta, tensors)}
    with atomic_paths(path, path.with_suffix(".json")) as (pt, sidecar):
        torch.save({**meta, **tensors}, pt)
        sidecar.write_text(json.dumps(meta, indent=2) + "\n")


def pair_id(meta: dict, tensors: dict) -> str:
    """A digest of the metadata and every tensor (names, shapes, values): the same model, the same id."""
    h = hashlib.sha256(json.dumps({k: v for k, v in meta.items() if k != "pair_id"}, sort_keys=True,
                                  default=str).encode())

    def visit(obj, key=""):
        if isinstance(obj, torch.Tensor):
            t = obj.detach().cpu().contiguous()
            h.update(f"{key}:{t.dtype}:{tuple(t.shape)}".encode())
            h.update(t.numpy().tobytes() if t.dtype != torch.bfloat16 else t.float().numpy().tobytes())
        elif isinstance(obj, dict):
            for k in obj:
                visit(obj[k], f"{key}/{k}")
        else:
            h.update(f"{key}={obj!r}".encode())

    visit(tensors)
    return h.hexdigest()[:16]


def read_blob(path: str | os.PathLike[str], fmt: str, version: int, kind: str | None = None,
              saved_by: str = "") -> dict[str, Any]:
    """The dict :func:`write_blob` saved, checked to be of format ``fmt`` (and ``kind``) and
    ``version``, and to belong with the ``.json`` beside it; loaded safely (``weights_only=True``)."""
    path = Path(path)
    if path.is_dir():
        raise DataError(f"{path} is a folder; give the checkpoint file (.pt).")
    if not path.is_file():
        raise FileNotFoundError(f"checkpoint {path} does not exist.")
    try:
        blob = torch.load(path, map_location="cpu", weights_only=True)
    except Exception:  # noqa: BLE001 - any unpickling failure means "not our file"
        # torch's own reason advises weights_only=False, which would run the file's code: not shown
        raise DataError(f"{path} is not a readable checkpoint: not one this project wrote (corrupt, truncated or "
                        "another program's file); write it again with `hyst train` or `hyst fit`.") from None
    if not isinstance(blob, dict) or blob.get("format") != fmt or (kind is not None and blob.get("kind") != kind):
        what = f"{fmt} checkpoint" + (f" of kind {kind!r}" if kind is not None else "")
        raise DataError(f"{path} is not a {what}{f' (saved by {saved_by})' if saved_by else ''}.")
    if blob.get("version") != version:
        raise DataError(f"{path} has checkpoint version {blob.get('version')!r}; this code reads version {version}.")
    check_pair(path, blob)
    return blob


def check_pair(path: Path, blob: dict) -> None:
    """Refuse a checkpoint whose contents no longer match its ``pair_id`` (damaged), and a ``.json``
    sidecar that was not written with it (when one is there)."""
    sidecar = path.with_suffix(".json")
    info = read_json(sidecar, "checkpoint sidecar") if sidecar.is_file() else None
    if blob.get("pair_id") is not None and isinstance(info, dict):
        meta = {k: blob[k] for k in info if k in blob}
        if pair_id(meta, {k: v for k, v in blob.items() if k not in info}) != blob["pair_id"]:
            raise DataError(f"{path} is damaged: its contents no longer match the id it was saved with; save or "
                            "train the model again.")
    if info is None:
        return
    theirs = info.get("pair_id") if isinstance(info, dict) else None
    if theirs != blob.get("pair_id"):
        raise DataError(f"{sidecar} does not belong to {path} (pair id {theirs!r}, the checkpoint's "
                        f"{blob.get('pair_id')!r}): they were not written together. Save or train the model "
                        "again, or put back the .json written with this .pt.")


def from_metadata(cls, meta: dict, state_dict: dict):
    """The fitted ``cls`` (a LearnedModel) that :func:`metadata` described, with its weights."""
    settings = dict(meta["settings"])
    network = network_from_dict(settings.pop("network"))
    settings["features"] = tuple(settings["features"])
    if "outputs" in settings:
        settings["outputs"] = tuple(settings["outputs"])
    settings["training"] = training_from_dict(settings)  # saved flat before it was one object: read too
    model = cls(network, **settings)
    module = network.build(int(meta["n_features"]), max(len(settings.get("outputs", ())), 1))
    module.load_state_dict(state_dict)
    model.module_ = module.eval()
    model.n_features_in_ = int(meta["n_features"])
    model.input_scaler_ = MinMaxScaler.from_dict(meta["input_scaler"])
    model.output_scaler_ = MinMaxScaler.from_dict(meta["output_scaler"])
    model.history_ = TrainingHistory.from_dict(meta["history"])
    model.provenance_ = meta["provenance"]
    return model
