"""Checkpoints of hybrid models: one ``.pt`` (weights + JSON-ready metadata) and a ``.json`` copy of the metadata.

The residual network's part is the learned-model checkpoint's own metadata
(``hybrid.learning._checkpoint``); the physics is stored by ``Series.to_dict`` (block
names, structural settings, parameter values, dt), so a load rebuilds the same CasADi graph.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import torch

from hybrid.learning._checkpoint import from_metadata, metadata, read_blob as _read_blob, write_blob
from hybrid.learning._learned import LearnedModel
from hybrid.learning._settings import training_from_dict
from physics import Series

from ._hybrid_tune import FineTuneSettings

__all__ = ["save_hybrid", "load_hybrid", "write_hybrid_blob", "read_hybrid_blob", "FORMAT", "VERSION"]

FORMAT = "hysteresis-hybrid/hybrid-model"
VERSION = 1
#: Settings that are stored elsewhere in the checkpoint (the physics and network themselves).
_STORED_APART = ("physics", "residual", "features", "identify_options")
#: How checkpoints written before the fine-tune settings were one object named its fields.
_FLAT_FINE_TUNE = {"fine_tune_epochs": "epochs", "physics_lr": "physics_lr", "residual_penalty": "residual_penalty",
                   "segment_len": "segment_len"}


def write_hybrid_blob(path: str | os.PathLike[str], kind: str, meta: dict[str, Any], tensors: dict) -> Path:
    """A hybrid checkpoint of ``kind`` (``"residual"`` or ``"neural-ode"``) at ``path``."""
    meta = json.loads(json.dumps({"format": FORMAT, "version": VERSION, "kind": kind, **meta,
                                  "torch": str(torch.__version__)}, default=str))
    write_blob(Path(path), meta, tensors)
    return Path(path)


def read_hybrid_blob(path: str | os.PathLike[str], kind: str) -> dict[str, Any]:
    """A hybrid checkpoint of ``kind`` (``"residual"`` or ``"neural-ode"``)."""
    return _read_blob(path, FORMAT, VERSION, kind)


def save_hybrid(model, path: str | os.PathLike[str]) -> Path:
    """Save a fitted :class:`HybridModel`; :func:`load_hybrid` gives back identical predictions."""
    model._check_fitted()
    settings = {k: v for k, v in model.get_params(deep=False).items() if k not in _STORED_APART}
    settings["training"] = model.training.to_dict()
    settings["fine_tune"] = None if model.fine_tune is None else model.fine_tune.to_dict()
    if tuple(settings.get("outputs", ())):
        settings["outputs"] = list(settings["outputs"])
    else:  # a model of one output saves as it always has
        settings.pop("outputs", None)
    meta = {"settings": settings, "features": list(model.features), "feature_names": list(model.feature_names_),
            "state_names": list(model.state_names_), "physics": model.physics_.to_dict(),
            "physics_fit": model.physics_fit_.to_dict() if hasattr(model.physics_fit_, "to_dict") else None,
            "physics_selection": (model.physics_selection_.to_dict()
                                  if getattr(model, "physics_selection_", None) is not None else None),
            "fine_tune_loss": list(model.fine_tune_loss_), "residual": metadata(model.residual_),
            "input_bounds": None if model.input_bounds_ is None else list(model.input_bounds_),
            "inverse_quasi_static": bool(model.inverse_quasi_static_)}
    tensors = {"residual_weights": model.residual_.module_.state_dict()}
    domain = getattr(model, "domain_", None)
    if domain is not None:  # the residual's training rows: the weight of the residual off them
        meta["domain"] = domain.to_dict()
        tensors["domain_rows"] = torch.as_tensor(domain.rows_, dtype=torch.float64)
    return write_hybrid_blob(path, "residual", meta, tensors)


def load_hybrid(cls, path: str | os.PathLike[str]):
    """The ``cls`` (a HybridModel) written by :func:`save_hybrid` (safe: ``weights_only=True``)."""
    blob = read_hybrid_blob(path, "residual")
    residual = from_metadata(LearnedModel, blob["residual"], blob["residual_weights"])
    physics = Series.from_dict(blob["physics"])
    model = cls(physics, residual.network_, features=tuple(blob["features"]), **_settings(blob["settings"]))
    model.physics_, model.physics_fit_, model._fns = physics, None, None
    model.physics_selection_ = blob.get("physics_selection")  # the selection's report (a dict), if any
    model.state_names_ = tuple(blob["state_names"])
    model.feature_names_ = tuple(blob["feature_names"])
    model.fine_tune_loss_ = list(blob["fine_tune_loss"])
    bounds = blob.get("input_bounds")  # absent from checkpoints written before the bounded inverse
    model.input_bounds_ = None if bounds is None else tuple(float(b) for b in bounds)
    model.inverse_quasi_static_ = bool(blob.get("inverse_quasi_static", False))
    model.residual_ = residual
    model.domain_ = None
    if blob.get("domain") is not None:
        from ._domain import ResidualDomain

        model.domain_ = ResidualDomain.from_dict(blob["domain"], blob["domain_rows"].numpy())
    return model


def _settings(saved: dict[str, Any]) -> dict[str, Any]:
    """The ``__init__`` keywords of a saved hybrid's settings: its training and fine-tune settings as
    objects, read from their own entries or (checkpoints written before) from the flat names."""
    settings = dict(saved)
    settings["training"] = training_from_dict(settings)
    if "outputs" in settings:
        settings["outputs"] = tuple(settings["outputs"])
    flat = {new: settings.pop(old) for old, new in _FLAT_FINE_TUNE.items() if old in settings}
    tune = settings.get("fine_tune")
    if isinstance(tune, bool):  # the flat form: a switch plus the four settings beside it
        settings["fine_tune"] = FineTuneSettings.from_dict(flat) if tune else None
    elif tune is not None:
        settings["fine_tune"] = FineTuneSettings.from_dict(tune)
    return settings
