"""Checkpoints of hybrid models: one ``.pt`` (weights + JSON-ready metadata) and a ``.json`` copy of the metadata.

The residual network's part is the learned-model checkpoint's own metadata
(``hybrid.learning._checkpoint``); the physics is stored as block names, structural
settings and parameter values, so a load rebuilds the same CasADi graph.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import torch

from hybrid.learning._checkpoint import _metadata as learned_metadata
from hybrid.learning._checkpoint import read_blob as _read_blob
from hybrid.learning._checkpoint import write_blob
from ._torch_physics import series_from_dict, series_to_dict
from hybrid.learning._training import TrainingHistory
from physics.data import MinMaxScaler
from hybrid.networks import network_from_dict

__all__ = ["save_hybrid", "load_hybrid", "FORMAT", "read_blob", "residual_from_blob"]

FORMAT = "hysteresis-hybrid/hybrid-model"
VERSION = 1


def _json_ready(d: dict) -> dict:
    return json.loads(json.dumps(d, default=str))


def save_hybrid(model, path: str | os.PathLike[str]) -> Path:
    """Save a fitted :class:`HybridModel`; :func:`load_hybrid` gives back identical predictions."""
    model._check_fitted()
    path = Path(path)
    settings = {k: getattr(model, k) for k in model._SETTINGS}
    meta = _json_ready({
        "format": FORMAT, "version": VERSION, "kind": "residual", "settings": settings,
        "features": list(model.features), "feature_names": list(model.feature_names_),
        "state_names": list(model.state_names_), "physics": series_to_dict(model.physics_),
        "physics_fit": model.physics_fit_.to_dict() if model.physics_fit_ is not None else None,
        "fine_tune_loss": list(model.fine_tune_loss_), "residual": learned_metadata(model.residual_),
        "torch": str(torch.__version__),
    })
    write_blob(path, meta, {"residual_weights": model.residual_.module_.state_dict()})
    return path


def read_blob(path: str | os.PathLike[str], kind: str) -> dict[str, Any]:
    """A hybrid checkpoint of ``kind`` (``"residual"`` or ``"neural-ode"``)."""
    return _read_blob(path, FORMAT, VERSION, kind)


def residual_from_blob(meta: dict, state_dict: dict):
    """The fitted :class:`LearnedModel` described by learned-checkpoint metadata plus its weights."""
    from hybrid.learning._learned import LearnedModel

    settings = dict(meta["settings"])
    network = network_from_dict(settings.pop("network"))
    settings["features"] = tuple(settings["features"])
    model = LearnedModel(network, **settings)
    module = network.build(int(meta["n_features"]), 1)
    module.load_state_dict(state_dict)
    model.module_ = module.eval()
    model.n_features_in_ = int(meta["n_features"])
    model.input_scaler_ = MinMaxScaler.from_dict(meta["input_scaler"])
    model.output_scaler_ = MinMaxScaler.from_dict(meta["output_scaler"])
    model.history_ = TrainingHistory.from_dict(meta["history"])
    model.provenance_ = meta["provenance"]
    return model


def load_hybrid(path: str | os.PathLike[str]):
    """Load a model written by :func:`save_hybrid` (safe: ``weights_only=True``)."""
    from ._hybrid import HybridModel

    blob = read_blob(path, "residual")
    residual = residual_from_blob(blob["residual"], blob["residual_weights"])
    physics = series_from_dict(blob["physics"])
    settings = dict(blob["settings"])
    model = HybridModel(physics, residual.network_, features=tuple(blob["features"]), **settings)
    model.physics_, model.physics_fit_, model._fns = physics, None, None
    model.state_names_ = tuple(blob["state_names"])
    model.feature_names_ = tuple(blob["feature_names"])
    model.fine_tune_loss_ = list(blob["fine_tune_loss"])
    model.residual_ = residual
    return model
