"""Load any saved model (learned, hybrid, neural-ODE hybrid) from its ``.pt`` checkpoint.

Each kind writes a ``.json`` sidecar beside its ``.pt`` naming its ``format`` (and
``kind``); the loader dispatches on it, so callers need not know what was saved.
"""

from __future__ import annotations

import json
from pathlib import Path

from physics.data import DataError

#: (format, kind) -> (module, class); kind None matches any.
_LOADERS = {
    ("hysteresis-hybrid/learned-model", None): ("hybrid.learning._learned", "LearnedModel"),
    ("hysteresis-hybrid/hybrid-model", "residual"): ("hybrid.models._hybrid", "HybridModel"),
    ("hysteresis-hybrid/hybrid-model", "neural-ode"): ("hybrid.models._neural_ode", "NeuralODEHybrid"),
}


def load_checkpoint_any(path):
    """The model saved at ``path`` (a ``.pt`` file with its ``.json`` sidecar)."""
    import importlib

    path = Path(path)
    sidecar = path.with_suffix(".json")
    if not path.is_file() or not sidecar.is_file():
        raise DataError(f"No checkpoint at '{path}' (needs {path.with_suffix('.pt').name} and "
                        f"{sidecar.name}); write one with `hyst train --out {path.with_suffix('.pt')}`.")
    try:
        info = json.loads(sidecar.read_text())
    except json.JSONDecodeError as exc:
        raise DataError(f"'{sidecar}' is not valid JSON ({exc}).") from None
    key = (info.get("format"), info.get("kind"))
    target = _LOADERS.get(key) or _LOADERS.get((key[0], None))
    if target is None:
        known = ", ".join(f"{f} ({k or 'any'})" for f, k in _LOADERS)
        raise DataError(f"'{sidecar}' has format {key[0]!r}, kind {key[1]!r}; known: {known}.")
    module = importlib.import_module(target[0])
    return getattr(module, target[1]).load(path.with_suffix(".pt"))
