"""How the physics a model uses is reached, in one place: :class:`PhysicsPolicy` and :func:`fit_physics`.

A policy names the physics (a spec, specs tried in order, ``"auto"``, or a fitted model used as
given) and what to fall back to: specs tried once every one it names failed to fit
(``fallback``), and specs tried instead when the selection of ``"auto"`` itself fails
(``if_selection_fails``); what a spec must carry for the model built on it (``requires``), and how
many fitted specs a model that may still fail on one tries in turn (``max_tries``).
:func:`fit_physics` applies it and returns the fit with a :class:`PhysicsReport` of what was tried and
why, which the callers record and print; :func:`physics_fits` hands on each spec that fits in turn.
``hyst fit`` (:data:`FALLBACK`), ``hyst compare`` (:data:`DEFAULT_SPECS`, and its neural ODE's
``requires`` and ``max_tries``) and ``HybridModel.fit`` each state their policy with it.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

from physics import Series

from identification._errors import IdentificationError
from identification._identify import fitted_series
from identification._result import FitResult
from identification._solver_settings import SolverSettings
from ._pool import driver_threads
from ._select import Selection, select_physics

__all__ = ["PhysicsPolicy", "PhysicsReport", "PhysicsFitError", "fit_physics", "physics_fits", "FALLBACK",
           "DEFAULT_SPECS", "AUTO", "substitution"]

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
        Keyword arguments of ``select_physics`` (``warmup``, ``settings``: a ``SelectionSettings``,
        ``workers``: a ``Workers``, where its fold fits run, ``verbose``, ``peers``, ...).
    identify_options : mapping, optional
        Keyword arguments of ``identify`` for each spec's fit (``{"solver": SolverSettings(...)}``, ...).
    requires : callable, optional
        What a spec must carry for the model built on it: ``requires(series)`` says why ``series`` (the
        spec's model, unfitted, or a fitted model named in ``physics``) cannot carry it, or returns None
        when it can. A spec that cannot is skipped, not fitted (``PhysicsReport.skipped``). None: any spec.
    max_tries : int, optional
        Most fitted specs :func:`physics_fits` hands on, in turn, to a model that may still fail on one
        (a neural ODE unstable on a physics moves on to the next); None: every candidate.
    """

    physics: Any = AUTO
    fallback: tuple[str, ...] = ()
    if_selection_fails: tuple[str, ...] | None = None
    select_options: Mapping[str, Any] = field(default_factory=dict)
    identify_options: Mapping[str, Any] | None = None
    requires: Callable[[Series], str | None] | None = None
    max_tries: int | None = None

    def __post_init__(self) -> None:
        if self.max_tries is not None and (isinstance(self.max_tries, bool) or not isinstance(self.max_tries, int)
                                           or self.max_tries < 1):
            raise IdentificationError(f"The 'max_tries' of a PhysicsPolicy must be a whole number >= 1, or None. "
                                      f"Got {self.max_tries!r} instead.")
        if self.requires is not None and not callable(self.requires):
            raise IdentificationError(f"The 'requires' of a PhysicsPolicy must be a function of a physics.Series "
                                      f"(why it cannot carry the model, or None). Got {self.requires!r} instead.")
        for name in ("fallback", "if_selection_fails"):
            value = getattr(self, name)
            if value is not None and (isinstance(value, str) or not all(isinstance(s, str) for s in value)):
                raise IdentificationError(f"The '{name}' of a PhysicsPolicy must be a tuple of specs, e.g. "
                                          f"('backlash+linear', 'linear'). Got {value!r} instead.")
            if value is not None:
                object.__setattr__(self, name, tuple(value))

    def scored_after(self, warmup: int) -> "PhysicsPolicy":
        """This policy under the protocol every model is scored with: each run's first ``warmup`` samples
        set its state, the rest is scored, in the selection's folds and in the final fit alike. The one
        way ``hyst fit`` and ``hyst compare`` reach their physics; unchanged for ``warmup`` 0."""
        if not warmup:
            return self
        return replace(self, select_options={"warmup": int(warmup), **self.select_options},
                       identify_options={**(self.identify_options or {}), "warmup": int(warmup)})

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
    ``failed`` each failed spec's reason, ``skipped`` each spec the policy's ``requires`` refused and
    why; ``selection`` is the selection of ``"auto"`` and ``selection_error`` why it failed.
    """

    spec: str
    how: str
    tried: list[str] = field(default_factory=list)
    failed: dict[str, str] = field(default_factory=dict)
    candidates: list[str] = field(default_factory=list)
    selection: Selection | None = field(default=None, repr=False)
    selection_error: str | None = None
    skipped: dict[str, str] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {"spec": self.spec, "how": self.how, "tried": list(self.tried), "failed": dict(self.failed),
                "candidates": list(self.candidates), "selection_error": self.selection_error,
                "skipped": dict(self.skipped)}

    @property
    def substitution(self) -> str:
        """:func:`substitution` of this report: which spec was asked for and could not be fitted, why,
        and what was used instead ("" when the first spec tried is the one used)."""
        return substitution(self.to_dict())


def substitution(report: Mapping[str, Any]) -> str:
    """One line saying that the first spec tried could not be fitted, why (the first sentence of its
    error), and which spec was used instead: ``"'gpi+linear' could not be fitted (IPOPT did not converge
    ...); used 'backlash+linear' instead"``; "" when the first spec tried fitted. ``report`` is a
    :meth:`PhysicsReport.to_dict` (as a model folder keeps it): the CLI and the model card say the same."""
    failed, spec = dict(report.get("failed") or {}), report.get("spec", "")
    if not failed or not spec or spec in failed:
        return ""
    first, why = next(iter(failed.items()))
    return f"'{first}' could not be fitted ({_first_sentence(why)}); used '{spec}' instead"


def _first_sentence(text: str) -> str:
    line = " ".join(str(text).split())
    head, dot, _ = line.partition(". ")
    return head.rstrip(".") if dot else line.rstrip(".")


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
    if isinstance(physics, str) and not policy.fallback and policy.requires is None:  # one spec: its own error
        series, fit = fitted_series(physics, runs, runs[0].dt, _options(policy), guesses=guesses or {})
        return series, fit, PhysicsReport(series.spec, how or "first", [physics], {}, [physics], selection, error)
    if isinstance(physics, str):
        physics = [physics]
    if not (isinstance(physics, (list, tuple)) and all(isinstance(s, str) for s in physics)):
        series, fit = fitted_series(physics, runs, runs[0].dt, _options(policy))  # a model used as given
        return series, fit, PhysicsReport(getattr(series, "spec", ""), "given")
    named = list(dict.fromkeys(physics))
    candidates, skipped = _carried(policy, list(dict.fromkeys([*named, *policy.fallback])), runs[0].dt)
    failed: dict[str, str] = {}
    if not candidates:
        raise PhysicsFitError("No physics spec can carry the model:\n  " + "\n  ".join(
            f"'{k}': {v}" for k, v in skipped.items()), PhysicsReport("", "none", [], {}, [], selection, error, skipped))
    try:
        series, fit = fitted_series(candidates, runs, runs[0].dt, _options(policy), failed=failed,
                                    guesses=guesses or {})
    except IdentificationError as exc:
        raise PhysicsFitError(str(exc), PhysicsReport("", "none", list(candidates), dict(failed), candidates,
                                                      selection, error, skipped)) from None
    spec = candidates[len(failed)]  # the specs are tried in order until one fits
    if how is None:
        how = _how(spec, named, selection is not None)
    return series, fit, PhysicsReport(spec, how, candidates[:len(failed) + 1], dict(failed), candidates,
                                      selection, error, skipped)


def physics_fits(policy: PhysicsPolicy, runs, guesses: Mapping[str, Sequence[dict]] | None = None,
                 report: PhysicsReport | None = None) -> Iterator[tuple[Series, FitResult]]:
    """Each candidate of ``policy`` that it ``requires`` and that fits ``runs``, in order, as
    ``(series, fit)``: at most ``policy.max_tries`` of them, each fitted when reached.

    For a model that may still fail on a physics that fits (a neural ODE unstable on it): it builds
    itself on each in turn and stops at the first that holds. ``policy.physics`` is a spec or a sequence
    of specs and fitted models (a :class:`~identification.FitResult`, handed on as it is), then its
    ``fallback``; ``auto`` is for :func:`fit_physics`. ``report``, when given, is filled as the candidates
    are reached: ``tried`` (handed on), ``failed`` (spec -> why its fit failed), ``skipped`` (spec ->
    why ``requires`` refused it).
    """
    runs = list(runs)
    if not runs:
        raise IdentificationError("physics_fits needs training runs; got none.")
    report = PhysicsReport("", "none") if report is None else report
    items = [policy.physics] if isinstance(policy.physics, (str, FitResult)) else list(policy.physics)
    if policy.auto or not all(isinstance(i, (str, FitResult)) for i in items):
        raise IdentificationError(f"physics_fits takes specs and fitted models (FitResult) tried in order; got "
                                  f"{policy.physics!r}. Use fit_physics for 'auto' or a model used as given.")
    return _handed_on(policy, [*items, *policy.fallback], runs, guesses, report)  # checked now, fitted when reached


def _handed_on(policy: PhysicsPolicy, items: list, runs: list, guesses, report: PhysicsReport):
    handed = 0
    for item in items:
        if policy.max_tries is not None and handed >= policy.max_tries:
            return
        spec = item.spec if isinstance(item, FitResult) else item
        report.candidates.append(spec)
        why = policy.requires(item.model() if isinstance(item, FitResult) else Series.from_spec(spec, dt=runs[0].dt)) \
            if policy.requires is not None else None
        if why:
            report.skipped[spec] = why
            continue
        if isinstance(item, FitResult):
            series, fit = item.model(), item
        else:
            failed: dict[str, str] = {}
            try:
                series, fit = fitted_series([spec], runs, runs[0].dt, _options(policy), failed=failed,
                                            guesses=guesses or {})
            except IdentificationError:
                report.failed.update(failed)
                continue
        report.tried.append(spec)
        report.spec = spec
        handed += 1
        yield series, fit


def _carried(policy: PhysicsPolicy, specs: list[str], dt: float) -> tuple[list[str], dict[str, str]]:
    """``(specs the policy's requires lets through, {spec: why not} of the others)``."""
    if policy.requires is None:
        return specs, {}
    skipped = {}
    for spec in specs:
        why = policy.requires(Series.from_spec(spec, dt=dt))
        if why:
            skipped[spec] = why
    return [s for s in specs if s not in skipped], skipped


def _how(spec: str, named: list[str], selected: bool) -> str:
    if spec not in named:
        return "fallback"
    if spec != named[0]:
        return "ranking"
    return "selection" if selected else "first"


def _options(policy: PhysicsPolicy) -> dict | None:
    """``identify``'s options of the policy's fits: its own; without a solver of their own, their starts
    solved at once on as many threads as the selection's workers (the answer is the same:
    ``SolverSettings.threads``)."""
    options = None if policy.identify_options is None else dict(policy.identify_options)
    threads = driver_threads(policy.select_options.get("workers"))
    if threads > 1 and (options or {}).get("solver") is None:
        options = {**(options or {}), "solver": SolverSettings(threads=threads)}
    return options
