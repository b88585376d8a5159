"""How the physics a model uses is reached, in one place: :class:`PhysicsPolicy` and :func:`fit_physics`.

A policy names the physics (a spec, specs tried in order, ``"auto"``, or a fitted model used as
given) and what to fall back to: specs tried once every one it names failed to fit
(``fallback``), and specs tried instead when the selection of ``"auto"`` itself fails
(``if_selection_fails``). :func:`fit_physics` applies it and returns the fit with a
:class:`PhysicsReport` of what was tried and why, which the callers record and print.
``hyst fit`` (:data:`FALLBACK`), ``hyst compare`` (:data:`DEFAULT_SPECS`) and ``HybridModel.fit``
each state their policy with it.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from identification._errors import IdentificationError
from identification._identify import fitted_series
from ._select import Selection, select_physics

__all__ = ["PhysicsPolicy", "PhysicsReport", "PhysicsFitError", "fit_physics", "FALLBACK", "DEFAULT_SPECS", "AUTO"]

#: ``physics=AUTO``: the spec chosen by its error on whole training runs held out (``select_physics``).
AUTO = "auto"
#: Simpler specs a model folder (``hyst fit``) falls back to, in order, when its physics does not fit.
FALLBACK = ("backlash+linear", "linear")
#: The specs ``hyst compare`` tries in order by default, and where the selection of ``auto`` fails: the
#: first that fits is used, so a comparison never dies because one physics fit did.
DEFAULT_SPECS = ("backlash+boucwen+linear", "backlash+linear", "linear")


@dataclass(frozen=True)
class PhysicsPolicy:
    """Which physics to fit, and what to fall back to.

    Parameters
    ----------
    physics : str, sequence of str, Selection, physics.Series or FitResult
        ``"auto"`` (:func:`~identification.discovery.select_physics` ranks the specs on held-out
        runs; they are tried best first), a spec, specs tried in order (the first that fits is used),
        a Selection (its ranking), or a model used as given (a Series, a FitResult).
    fallback : tuple of str
        Specs tried, in order, after every spec above failed to fit.
    if_selection_fails : tuple of str, optional
        With ``"auto"``: the specs tried instead when the selection itself fails (too few runs to
        hold any out); None: its error is raised.
    select_options : mapping
        Keyword arguments of ``select_physics`` (``warmup``, ``n_jobs``, ``verbose``, ``peers``, ...).
    identify_options : mapping, optional
        Keyword arguments of ``identify`` for each spec's fit.
    """

    physics: Any = AUTO
    fallback: tuple[str, ...] = ()
    if_selection_fails: tuple[str, ...] | None = None
    select_options: Mapping[str, Any] = field(default_factory=dict)
    identify_options: Mapping[str, Any] | None = None

    def __post_init__(self) -> None:
        for name in ("fallback", "if_selection_fails"):
            value = getattr(self, name)
            if value is not None and (isinstance(value, str) or not all(isinstance(s, str) for s in value)):
                raise IdentificationError(f"The '{name}' of a PhysicsPolicy must be a tuple of specs, e.g. "
                                          f"('backlash+linear', 'linear'). Got {value!r} instead.")
            if value is not None:
                object.__setattr__(self, name, tuple(value))

    @property
    def auto(self) -> bool:
        return isinstance(self.physics, str) and self.physics.strip().lower() == AUTO


@dataclass
class PhysicsReport:
    """What :func:`fit_physics` did: the spec in use and how it was reached.

    ``how`` is ``"given"`` (a model used as it was), ``"first"`` (the first spec named fitted),
    ``"selection"`` (the selection's best spec fitted), ``"ranking"`` (a later spec of the
    selection's ranking or of the list fitted), ``"fallback"`` (a spec of ``fallback``, or of
    ``if_selection_fails`` after the selection failed; ``"none"`` in a :class:`PhysicsFitError`'s report).
    ``candidates`` are the specs it would try, in order; ``tried`` lists the specs tried in order,
    ``failed`` each failed spec's reason; ``selection`` is the selection of ``"auto"`` and
    ``selection_error`` why it failed.
    """

    spec: str
    how: str
    tried: list[str] = field(default_factory=list)
    failed: dict[str, str] = field(default_factory=dict)
    candidates: list[str] = field(default_factory=list)
    selection: Selection | None = field(default=None, repr=False)
    selection_error: str | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"spec": self.spec, "how": self.how, "tried": list(self.tried), "failed": dict(self.failed),
                "candidates": list(self.candidates), "selection_error": self.selection_error}


class PhysicsFitError(IdentificationError):
    """No spec of the policy fitted; ``report`` says what was tried and why each failed."""

    def __init__(self, message: str, report: PhysicsReport):
        super().__init__(message)
        self.report = report


def fit_physics(policy: PhysicsPolicy, runs, guesses: Mapping[str, Sequence[dict]] | None = None):
    """Apply ``policy`` to the training ``runs``: ``(series, fit, report)``.

    ``fit`` is the :class:`~identification.FitResult` (None for a Series used as given); ``guesses``
    (spec -> parameter sets) start each spec's fit besides its own grid, by default the selection's
    fits on its folds. Raises :class:`PhysicsFitError` (an ``IdentificationError``) with the report
    when no spec fits, listing every failure.
    """
    runs = list(runs)
    if not runs:
        raise IdentificationError("fit_physics needs training runs; got none.")
    physics, selection, error, how = policy.physics, None, None, None
    if policy.auto:
        try:
            selection = physics = select_physics(runs, **dict(policy.select_options))
        except IdentificationError as exc:
            if policy.if_selection_fails is None:
                raise
            error, physics, how = str(exc), list(policy.if_selection_fails), "fallback"
    if isinstance(physics, Selection):
        selection, guesses = physics, (physics.fold_parameters if guesses is None else guesses)
        physics = physics.ranked()
    if isinstance(physics, str) and not policy.fallback:  # one spec: its own error if it does not fit
        series, fit = fitted_series(physics, runs, runs[0].dt, _options(policy), guesses=guesses or {})
        return series, fit, PhysicsReport(series.spec, how or "first", [physics], {}, [physics], selection, error)
    if isinstance(physics, str):
        physics = [physics]
    if not (isinstance(physics, (list, tuple)) and all(isinstance(s, str) for s in physics)):
        series, fit = fitted_series(physics, runs, runs[0].dt, _options(policy))  # a model used as given
        return series, fit, PhysicsReport(getattr(series, "spec", ""), "given")
    named = list(dict.fromkeys(physics))
    candidates = list(dict.fromkeys([*named, *policy.fallback]))
    failed: dict[str, str] = {}
    try:
        series, fit = fitted_series(candidates, runs, runs[0].dt, _options(policy), failed=failed,
                                    guesses=guesses or {})
    except IdentificationError as exc:
        raise PhysicsFitError(str(exc), PhysicsReport("", "none", list(candidates), dict(failed), candidates,
                                                      selection, error)) from None
    spec = candidates[len(failed)]  # the specs are tried in order until one fits
    if how is None:
        how = _how(spec, named, selection is not None)
    return series, fit, PhysicsReport(spec, how, candidates[:len(failed) + 1], dict(failed), candidates,
                                      selection, error)


def _how(spec: str, named: list[str], selected: bool) -> str:
    if spec not in named:
        return "fallback"
    if spec != named[0]:
        return "ranking"
    return "selection" if selected else "first"


def _options(policy: PhysicsPolicy) -> dict | None:
    return None if policy.identify_options is None else dict(policy.identify_options)
