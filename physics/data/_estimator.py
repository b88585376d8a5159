"""scikit-learn's estimator contract, kept without importing scikit-learn.

An estimator lists its settings as explicit ``__init__`` keywords and stores each
unchanged under its own name; :meth:`BaseEstimator.get_params` reads them back from
the signature, so there is no second list to keep in step. That is what
``sklearn.base.clone`` and the model-selection tools (``GridSearchCV``,
``cross_val_score``) rely on.
"""

from __future__ import annotations

import inspect
from collections.abc import Iterable
from typing import Any

import numpy as np

from ._errors import DataError

__all__ = ["BaseEstimator"]


class BaseEstimator:
    """``get_params(deep)``, ``set_params(**params)`` and ``score`` (R², higher is better).

    ``score(data)`` compares ``predict(trajectory)`` with :meth:`_target` of the
    trajectory (its output; its input when the estimator's ``direction`` is
    ``"inverse"``), pooled over the trajectories, like ``RegressorMixin.score``.
    """

    @classmethod
    def _param_names(cls) -> list[str]:
        names = []
        for p in list(inspect.signature(cls.__init__).parameters.values())[1:]:
            if p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD):
                raise TypeError(f"{cls.__name__}.__init__ must name its settings (no *args or **kwargs) so that "
                                "get_params can read them from its signature.")
            names.append(p.name)
        return sorted(names)

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        """Settings as given to ``__init__``; ``deep`` adds ``name__setting`` of estimator-valued settings."""
        out: dict[str, Any] = {}
        for name in self._param_names():
            value = getattr(self, name)
            if deep and hasattr(value, "get_params") and not isinstance(value, type):
                out.update((f"{name}__{k}", v) for k, v in value.get_params().items())
            out[name] = value
        return out

    def set_params(self, **params: Any):
        """Change settings (``name=value`` or ``name__setting=value`` of a nested estimator); returns ``self``."""
        valid = self._param_names()
        nested: dict[str, dict[str, Any]] = {}
        for key, value in params.items():
            name, sep, sub = key.partition("__")
            if name not in valid:
                raise DataError(f"{type(self).__name__} has no setting {name!r}. Must be one of: "
                                f"{', '.join(valid)}.")
            if sep:
                nested.setdefault(name, {})[sub] = value
            else:
                setattr(self, name, value)
        for name, sub in nested.items():
            getattr(self, name).set_params(**sub)
        return self

    def __sklearn_tags__(self):
        """What scikit-learn's model-selection tools ask of an estimator (>= 1.6); sklearn is
        imported only when sklearn itself calls this."""
        from sklearn.utils import InputTags, RegressorTags, Tags, TargetTags

        return Tags(estimator_type="regressor", target_tags=TargetTags(required=False),
                    input_tags=InputTags(), regressor_tags=RegressorTags())

    def _target(self, trajectory):
        """What ``predict(trajectory)`` estimates."""
        return trajectory.u if getattr(self, "direction", "forward") == "inverse" else trajectory.y

    def score(self, data) -> float:
        """Coefficient of determination R² of the pooled predictions on trajectories (1 is perfect)."""
        trajs = [data] if hasattr(data, "u") else list(data) if isinstance(data, Iterable) else None
        if not trajs or not all(hasattr(t, "u") and hasattr(t, "y") for t in trajs):
            raise DataError(f"score needs a trajectory or a list of them (with .u and .y); got {type(data).__name__}.")
        y = np.concatenate([np.asarray(self._target(t), dtype=float) for t in trajs])
        yhat = np.concatenate([np.asarray(self.predict(t), dtype=float) for t in trajs])
        error, total = np.sum((y - yhat) ** 2), np.sum((y - y.mean()) ** 2)
        if total == 0:  # a constant target: perfect or not, as sklearn's r2_score
            return 1.0 if error == 0 else 0.0
        return float(1.0 - error / total)
