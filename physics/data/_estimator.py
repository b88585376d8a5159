"""scikit-learn's estimator contract, kept without importing scikit-learn.

An estimator lists its settings as explicit ``__init__`` keywords and stores each
unchanged under its own name; :meth:`BaseEstimator.get_params` reads them back from
the signature, so there is no second list to keep in step. That is what
``sklearn.base.clone`` and the model-selection tools (``GridSearchCV``,
``cross_val_score``) rely on.

Settings that belong together (how to train a network, how to fine-tune) travel as one frozen
:class:`Settings` dataclass held under one ``__init__`` keyword: ``get_params(deep=True)`` shows
its fields as ``training__epochs``, and ``set_params(training__lr=...)`` swaps in a changed copy
(validated whole), so one settings object can be shared by many estimators safely.
"""

from __future__ import annotations

import dataclasses
import inspect
from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np

from ._errors import DataError

__all__ = ["BaseEstimator", "Settings"]


class Settings:
    """Base of the frozen settings dataclasses an estimator takes as one parameter.

    A subclass is a ``@dataclass(frozen=True)`` that checks its fields in ``__post_init__``, so a
    settings object is valid from construction on and never changes: a budget table can hand the
    same one to many estimators. scikit-learn sees its fields through :meth:`get_params`
    (``sklearn.base.clone`` rebuilds it from them); :meth:`BaseEstimator.set_params` changes them
    with :meth:`replace`, which returns a new, checked object.
    """

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        """The fields, by name (``deep`` is accepted for scikit-learn: settings hold no estimators)."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}  # type: ignore[arg-type]

    def replace(self, **changes: Any):
        """A copy with ``changes`` (checked like a new object); unknown names are refused."""
        names = [f.name for f in dataclasses.fields(self)]  # type: ignore[arg-type]
        unknown = [k for k in changes if k not in names]
        if unknown:
            raise DataError(f"{type(self).__name__} has no setting {unknown[0]!r}. Must be one of: {', '.join(names)}.")
        return dataclasses.replace(self, **changes)  # type: ignore[type-var]

    def to_dict(self) -> dict[str, Any]:
        """The fields, JSON-ready (what :meth:`from_dict` reads back)."""
        return self.get_params()

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]):
        """The settings :meth:`to_dict` wrote (unknown keys refused, missing ones at their defaults)."""
        if not isinstance(d, Mapping):
            raise DataError(f"{cls.__name__} settings must be a mapping of names to values; got {type(d).__name__}.")
        return cls().replace(**d)


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
            value = getattr(self, name)
            if isinstance(value, Settings):  # frozen: a changed copy, checked with all its changes at once
                setattr(self, name, value.replace(**sub))
            elif hasattr(value, "set_params"):
                value.set_params(**sub)
            else:
                raise DataError(f"The {name!r} setting of {type(self).__name__} is {value!r}, which has no settings "
                                f"to change ({', '.join(f'{name}__{k}' for k in sub)}); set {name} itself.")
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
