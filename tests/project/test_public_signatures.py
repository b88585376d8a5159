"""No constructor or function of the public API takes more than 12 parameters (issue 44): settings
travel as objects (``TrainingSettings``, ``MPCSettings``, ``SolverSettings``, ...).

Walked like scikit-learn's ``all_estimators``: every name in the ``__all__`` of every public module
of the three packages, and the public methods of every public class. The records a fit *returns*
are not built by users and are listed in :data:`RECORDS` with their reason."""

from __future__ import annotations

import importlib
import inspect
import pkgutil

import pytest

MAX_PARAMETERS = 12
#: Results and declarations, not settings: a fit returns them (their fields are what it found), or a
#: block declares them as class attributes that ``BlockTraits.of`` gathers.
RECORDS = {
    "identification.FitResult": "what identify returns",
    "identification.discovery.DiscoveryReport": "what discover returns",
    "identification.discovery.Step": "one step of a DiscoveryReport",
    "identification.discovery.Selection": "what select_physics returns",
    "physics.BlockTraits": "a block's declared class attributes, gathered by BlockTraits.of",
}


def _public_callables():
    seen = {}
    for top in ("physics", "identification", "hybrid"):
        package = importlib.import_module(top)
        names = [top] + [m.name for m in pkgutil.walk_packages(package.__path__, top + ".")
                         if not any(part.startswith("_") for part in m.name.split(".")[1:])]
        for module_name in names:
            try:
                module = importlib.import_module(module_name)
            except ImportError as exc:  # an optional extra (torch, pysindy, dask) is absent
                pytest.skip(f"{module_name} needs an optional extra that is absent: {exc}")
            for name in getattr(module, "__all__", ()):
                obj = getattr(module, name, None)
                if inspect.isclass(obj):
                    key = f"{obj.__module__}.{obj.__qualname__}"
                    seen.setdefault(key, (f"{module_name}.{name}", obj.__init__, obj))
                    for attr, value in vars(obj).items():
                        if not attr.startswith("_") and inspect.isfunction(value):
                            seen.setdefault(f"{key}.{attr}", (f"{module_name}.{name}.{attr}", value, None))
                elif inspect.isfunction(obj):
                    seen.setdefault(f"{obj.__module__}.{obj.__qualname__}", (f"{module_name}.{name}", obj, None))
    return sorted(seen.values(), key=lambda pair: pair[0])


def _resolve(path: str):
    module, _, name = path.rpartition(".")
    return getattr(importlib.import_module(module), name)


def _count(fn) -> int:
    try:
        parameters = inspect.signature(fn).parameters.values()
    except (TypeError, ValueError):  # a builtin without a signature
        return 0
    return sum(p.name not in ("self", "cls") and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD) for p in parameters)


def test_no_public_constructor_or_function_takes_more_than_12_parameters():
    callables = _public_callables()
    assert len(callables) > 200  # the walk reached the API
    records = {_resolve(path) for path in RECORDS}
    over = {name: n for name, fn, cls in callables if (n := _count(fn)) > MAX_PARAMETERS and cls not in records}
    assert not over, f"more than {MAX_PARAMETERS} parameters (group settings into an object): {over}"


def test_the_records_left_out_are_still_records():
    """Each exempted name is a dataclass a fit returns or a block declares, not a settings taker."""
    import dataclasses

    for path in RECORDS:
        assert dataclasses.is_dataclass(_resolve(path)), path
