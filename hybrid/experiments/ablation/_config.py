"""Ablation configs: a TOML file declaring the data, the grid of model settings and the metrics.

A config is parsed and checked once (:meth:`AblationConfig.from_toml`), then expanded into one
:class:`RunSpec` per grid point (:meth:`AblationConfig.runs`). Settings that do not apply to a
run's model (``buffer`` for an LSTM) are set to ``None``, so grids that mix models do not repeat
runs. A run's id is a hash of its settings and of the data description: the same run always
gets the same id, which is what lets a sweep resume.
"""

from __future__ import annotations

import dataclasses
import difflib
import hashlib
import itertools
import json
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hybrid.networks import NETWORKS
from .._datasets import load_data

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]

#: The folder of the configs shipped with the package (``hyst ablate tiny``).
CONFIGS = Path(__file__).resolve().parent / "configs"


def bundled_configs() -> list[str]:
    """Names of the ablation configs shipped with the package (``tiny``, ``buffer_length``, ...)."""
    return sorted(p.stem for p in CONFIGS.glob("*.toml"))


def config_path(config: str | os.PathLike[str]) -> Path:
    """The TOML file ``config`` names: a path to a file, or the name of a bundled config (with or
    without ``.toml``); an error naming the bundled ones otherwise."""
    path = Path(config)
    if path.exists():
        return path
    name = path.name.removesuffix(".toml")
    if path.parent == Path(".") and name in bundled_configs():
        return CONFIGS / f"{name}.toml"
    raise ConfigError(f"No ablation config '{config}': give a path to a .toml file or the name of a bundled "
                      f"config ({', '.join(bundled_configs())}).")

__all__ = ["AblationConfig", "ConfigError", "CONFIGS", "bundled_configs", "config_path", "DataConfig", "RunSpec", "SETTINGS", "METRICS", "DATA_SOURCES",
           "applies", "network_settings"]

#: An ablation trains any network of :data:`hybrid.networks.NETWORKS`, or this internal run type for
#: the tests: a linear least-squares map on the input history (numpy only, no torch).
DUMMY = "dummy"
#: What the dummy model takes besides the settings of every run.
_DUMMY_SETTINGS = ("buffer",)

#: What results.csv reports: test RMSE and NRMSE (per test trajectory and pooled) and training time.
METRICS = ("rmse", "nrmse", "fit_seconds")

DATA_SOURCES = ("virtual", "catheter_2023", "folder")
_DATA_KEYS = {
    "virtual": ("source", "effects", "input", "seed", "frequencies", "tests", "baselines"),
    "catheter_2023": ("source",),
    "folder": ("source", "path"),
}
_TOP_KEYS = ("name", "description", "requires", "data", "grid", "metrics")
#: Names from ``hybrid`` a config may declare it needs (``requires = ["HybridModel"]``); kept so
#: that configs written before the hybrids existed still load; every one is now provided.
REQUIRABLE = ("HybridModel",)


class ConfigError(ValueError):
    """A bad ablation config: names the file, the key and the allowed values."""


# ------------------------------------------------------------------ settings
def _is_int(low: int) -> Callable[[Any], bool]:
    return lambda v: isinstance(v, int) and not isinstance(v, bool) and v >= low


def _is_float(low: float, high: float, closed_low: bool) -> Callable[[Any], bool]:
    def check(v: Any) -> bool:
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            return False
        return (low <= v if closed_low else low < v) and v < high
    return check


def _is_fraction(v: Any) -> bool:
    if isinstance(v, bool):
        return False
    return (isinstance(v, int) and v >= 1) or (isinstance(v, float) and 0 < v <= 1)


def _is_physics(v: Any) -> bool:
    if not isinstance(v, str):
        return False
    if v.strip().lower() == "none":
        return True
    from physics import PhysicsError, Series

    try:
        Series.from_spec(v)
    except PhysicsError:
        return False
    return True


def _physics_allowed() -> str:
    from physics import BLOCKS

    return f"'none' or block names joined by '+' (e.g. 'backlash+boucwen+linear') from: {', '.join(sorted(BLOCKS))}"


@dataclass(frozen=True)
class _Setting:
    """A grid key. ``scope``: "run" (every run), "network" (every network: training and physics) or
    "spec" (a setting of the network spec, for the networks whose spec takes it)."""

    default: Any
    check: Callable[[Any], bool]
    allowed: str | Callable[[], str]
    scope: str
    as_float: bool = False

    def describe(self) -> str:
        return self.allowed() if callable(self.allowed) else self.allowed


def _choice(*values: str) -> Callable[[Any], bool]:
    return lambda v: v in values


def _is_model(v: Any) -> bool:
    return isinstance(v, str) and (v == DUMMY or v in NETWORKS)


#: Every grid key: default, check, allowed values, and the models it applies to. Order matters:
#: it is the column order of results.csv and the nesting order of the grid (seed varies fastest).
SETTINGS: dict[str, _Setting] = {
    "model": _Setting(None, _is_model, lambda: f"one of {list(NETWORKS)}", "run"),
    "direction": _Setting("forward", _choice("forward", "inverse"), "'forward' or 'inverse'", "run"),
    "physics": _Setting("none", _is_physics, _physics_allowed, "network"),
    "buffer": _Setting(50, _is_int(1), "an integer >= 1 (samples of input history, FNN-HIB)", "spec"),
    "seq_len": _Setting(50, _is_int(1), "an integer >= 1 (LSTM sequence length, samples)", "spec"),
    "hidden": _Setting(64, _is_int(1), "an integer >= 1 (width of each hidden layer)", "spec"),
    "layers": _Setting(2, _is_int(1), "an integer >= 1 (hidden layers)", "spec"),
    "mode": _Setting("window", _choice("window", "carried"), "'window' or 'carried' (LSTM prediction)", "spec"),
    "epochs": _Setting(40, _is_int(1), "an integer >= 1", "network"),
    "lr": _Setting(1e-3, _is_float(0.0, 1.0, False), "a number in (0, 1)", "network", as_float=True),
    "batch_size": _Setting(16, _is_int(1), "an integer >= 1", "network"),
    "stride": _Setting(1, _is_int(1), "an integer >= 1 (train on every stride-th window)", "network"),
    "validation": _Setting(0.0, _is_float(0.0, 1.0, True), "a number in [0, 1)", "network", as_float=True),
    "patience": _Setting(0, _is_int(0), "an integer >= 0 (0: no early stopping)", "network"),
    "data_fraction": _Setting(1.0, _is_fraction, "a fraction in (0, 1] (e.g. 0.5) or a number of training "
                              "trajectories >= 1 (e.g. 3; note 1 means one trajectory, 1.0 all of them)", "run"),
    "seed": _Setting(0, _is_int(0), "an integer >= 0 (weights, shuffling, choice of training trajectories)", "run"),
}


def _spec_settings(model: str) -> tuple[str, ...]:
    """The "spec" settings network ``model`` takes: the fields of its spec, plus ``layers`` where
    ``hidden`` is a tuple of layer widths (the FNNs: ``hidden = (hidden,) * layers``)."""
    fields = {f.name for f in dataclasses.fields(NETWORKS[model])}
    if _hidden_is_widths(model):
        fields.add("layers")
    return tuple(k for k, s in SETTINGS.items() if s.scope == "spec" and k in fields)


def _hidden_is_widths(model: str) -> bool:
    hidden = next((f for f in dataclasses.fields(NETWORKS[model]) if f.name == "hidden"), None)
    if hidden is None:
        return False
    default = hidden.default_factory() if hidden.default is dataclasses.MISSING else hidden.default  # type: ignore[misc]
    return isinstance(default, tuple)


def applies(key: str, model: str) -> bool:
    """Whether grid setting ``key`` means something for ``model`` (a run records ``None`` where not)."""
    scope = SETTINGS[key].scope
    if scope == "run":
        return True
    if model == DUMMY:
        return key in _DUMMY_SETTINGS
    return scope == "network" or key in _spec_settings(model)


def network_settings(settings: Mapping[str, Any]) -> dict[str, Any]:
    """The keyword arguments of the network spec of a run (``make_network(settings["model"], **...)``)."""
    model = settings["model"]
    out = {k: settings[k] for k in _spec_settings(model)}
    if _hidden_is_widths(model):
        out["hidden"] = (out["hidden"],) * out.pop("layers")
    return out


# ---------------------------------------------------------------------- data
@dataclass(frozen=True)
class DataConfig:
    """Where the trajectories come from (the ``[data]`` table).

    ``source = "virtual"``: the seed paper's protocol on :class:`hybrid.virtual.VirtualCatheter`
    (``effects``, ``input``, ``seed``, ``frequencies``, ``tests``, ``baselines``);
    ``"catheter_2023"``: the real catheter (train set 1, test set 2); ``"folder"``: ``path``
    holding ``train/*.csv`` and ``test/*.csv`` (as written by ``hyst simulate --paper-dataset``),
    relative to the current folder.
    """

    source: str = "virtual"
    effects: tuple[str, ...] = ("lag", "backlash", "hysteresis")
    input: str = "measured"
    seed: int = 0
    frequencies: tuple[float, ...] = (0.1, 0.2, 0.3, 0.4, 0.5)
    tests: tuple[float, ...] = (0.15, 0.45)
    baselines: tuple[str, ...] = ("zero", "mid", "end")
    path: str | None = None

    def to_dict(self) -> dict[str, Any]:
        """The keys that matter for this source (what a run id hashes and a run file records)."""
        keys = _DATA_KEYS[self.source]
        return {k: (list(v) if isinstance(v, tuple) else v) for k in keys for v in [getattr(self, k)]}

    def load(self):
        """The train/test :class:`~hybrid.data.DataSplit`."""
        if self.source == "virtual":
            return load_data("virtual", seed=self.seed, effects=self.effects, input=self.input,
                             frequencies=self.frequencies, tests=self.tests, baselines=self.baselines)
        return load_data("catheter_2023" if self.source == "catheter_2023" else str(self.path))


def _parse_data(table: Any, where: str) -> DataConfig:
    if not isinstance(table, Mapping):
        raise ConfigError(f"{where}: [data] must be a table, e.g. [data] source = \"virtual\".")
    source = table.get("source", "virtual")
    if source not in DATA_SOURCES:
        raise ConfigError(f"{where}: [data] source must be one of {list(DATA_SOURCES)}. Got {source!r} instead.")
    _check_keys(table, _DATA_KEYS[source], f"{where}: [data] (source = {source!r})")
    values: dict[str, Any] = {"source": source}
    if source == "folder":
        if not isinstance(table.get("path"), str) or not table["path"]:
            raise ConfigError(f"{where}: [data] source = 'folder' needs path = \"DIR\" (a folder with train/*.csv "
                              "and test/*.csv).")
        values["path"] = table["path"]
    if source == "virtual":
        values.update(_parse_virtual(table, where))
    return DataConfig(**values)


def _parse_virtual(table: Mapping[str, Any], where: str) -> dict[str, Any]:
    from physics.virtual import BASELINES, EFFECTS, INPUTS, parse_effects

    out: dict[str, Any] = {}
    if "effects" in table:
        try:
            names = parse_effects(table["effects"])
        except (ValueError, TypeError) as exc:
            raise ConfigError(f"{where}: [data] effects: {exc}") from None
        out["effects"] = tuple(e for e in EFFECTS if e in names)
    if "input" in table:
        if table["input"] not in INPUTS:
            raise ConfigError(f"{where}: [data] input must be one of {list(INPUTS)}. Got {table['input']!r} instead.")
        out["input"] = table["input"]
    if "seed" in table:
        if not _is_int(0)(table["seed"]):
            raise ConfigError(f"{where}: [data] seed must be an integer >= 0. Got {table['seed']!r} instead.")
        out["seed"] = table["seed"]
    for key in ("frequencies", "tests"):
        if key in table:
            v = table[key]
            if not (isinstance(v, list) and v and all(_is_float(0.0, float("inf"), False)(f) for f in v)):
                raise ConfigError(f"{where}: [data] {key} must be a non-empty list of frequencies > 0 (Hz). "
                                  f"Got {v!r} instead.")
            out[key] = tuple(float(f) for f in v)
    if "baselines" in table:
        v = table["baselines"]
        if not (isinstance(v, list) and v and all(b in BASELINES for b in v)):
            raise ConfigError(f"{where}: [data] baselines must be a non-empty list from {list(BASELINES)}. "
                              f"Got {v!r} instead.")
        out["baselines"] = tuple(v)
    return out


# ---------------------------------------------------------------------- runs
@dataclass(frozen=True, eq=False)
class RunSpec:
    """One grid point: every setting (``None`` where it does not apply) plus the data."""

    run_id: str
    settings: dict[str, Any]
    data: DataConfig

    @property
    def kind(self) -> str:
        """``"learned"``, ``"hybrid"`` (physics plus residual network) or ``"dummy"`` (tests)."""
        if self.settings["model"] == DUMMY:
            return "dummy"
        return "learned" if self.settings["physics"] == "none" else "hybrid"

    def __repr__(self) -> str:
        shown = ", ".join(f"{k}={v!r}" for k, v in self.settings.items() if v is not None)
        return f"RunSpec({self.run_id}: {shown})"


def run_id(settings: Mapping[str, Any], data: DataConfig) -> str:
    """``<model>-<12 hex>``: a hash of the settings and the data description (stable across machines)."""
    blob = json.dumps({"data": data.to_dict(), "settings": dict(settings)}, sort_keys=True)
    return f"{settings['model']}-{hashlib.sha256(blob.encode()).hexdigest()[:12]}"


def _settings_for(combo: Mapping[str, Any]) -> dict[str, Any]:
    out = {k: (v if applies(k, combo["model"]) else None) for k, v in combo.items()}
    if out["physics"] is not None:
        out["physics"] = "none" if out["physics"].strip().lower() == "none" else out["physics"].replace(" ", "")
    return out


# -------------------------------------------------------------------- config
@dataclass(frozen=True)
class AblationConfig:
    """A parsed ablation: data, grid and metrics.

    Parameters
    ----------
    data : DataConfig
    grid : dict of str to tuple
        Values of each setting named in the config (a single value is a 1-tuple); settings not
        named take their defaults (:data:`SETTINGS`).
    metrics : tuple of str
        Columns of results.csv, from :data:`METRICS`.
    name, description : str
    requires : tuple of str
        Names ``hybrid`` the config was written for (``"HybridModel"``); all are provided.

    Examples
    --------
    >>> cfg = AblationConfig.from_dict({"grid": {"model": "fnn-hib", "buffer": [10, 50], "seed": [0, 1]}})
    >>> len(cfg.runs()), cfg.varied
    (4, ('buffer', 'seed'))
    """

    data: DataConfig = field(default_factory=DataConfig)
    grid: dict[str, tuple[Any, ...]] = field(default_factory=dict)
    metrics: tuple[str, ...] = METRICS
    name: str = ""
    description: str = ""
    requires: tuple[str, ...] = ()

    @classmethod
    def from_toml(cls, path: str | os.PathLike[str]) -> AblationConfig:
        path = Path(path)
        if not path.is_file():
            raise ConfigError(f"ablation config {str(path)!r} does not exist.")
        try:
            table = tomllib.loads(path.read_text())
        except tomllib.TOMLDecodeError as exc:
            raise ConfigError(f"{path}: not valid TOML: {exc}") from None
        return cls.from_dict(table, where=str(path), default_name=path.stem)

    @classmethod
    def from_dict(cls, table: Mapping[str, Any], where: str = "ablation config",
                  default_name: str = "") -> AblationConfig:
        _check_keys(table, _TOP_KEYS, where)
        for key in ("name", "description"):
            if not isinstance(table.get(key, ""), str):
                raise ConfigError(f"{where}: {key} must be a string. Got {table[key]!r} instead.")
        if "grid" not in table:
            raise ConfigError(f"{where}: missing the [grid] table; it needs at least model = \"fnn-hib\" "
                              f"(one of {list(NETWORKS)}).")
        return cls(data=_parse_data(table.get("data", {}), where), grid=_parse_grid(table["grid"], where),
                   metrics=_parse_list(table, "metrics", METRICS, where, default=METRICS),
                   name=table.get("name", default_name), description=table.get("description", ""),
                   requires=_parse_list(table, "requires", REQUIRABLE, where, default=()))

    def runs(self) -> list[RunSpec]:
        """The grid as run specs, in grid order (``seed`` varies fastest), without repeats."""
        axes = [self.grid.get(k, (s.default,)) for k, s in SETTINGS.items()]
        specs: dict[str, RunSpec] = {}
        for combo in itertools.product(*axes):
            settings = _settings_for(dict(zip(SETTINGS, combo)))
            rid = run_id(settings, self.data)
            specs.setdefault(rid, RunSpec(rid, settings, self.data))
        return list(specs.values())

    @property
    def varied(self) -> tuple[str, ...]:
        """Settings that take more than one value across the runs."""
        runs = self.runs()
        return tuple(k for k in SETTINGS if len({json.dumps(r.settings[k]) for r in runs
                                                 if r.settings[k] is not None}) > 1)

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "description": self.description, "requires": list(self.requires),
                "data": self.data.to_dict(), "grid": {k: list(v) for k, v in self.grid.items()},
                "metrics": list(self.metrics)}


def _parse_grid(table: Any, where: str) -> dict[str, tuple[Any, ...]]:
    if not isinstance(table, Mapping):
        raise ConfigError(f"{where}: [grid] must be a table of settings, e.g. [grid] model = \"fnn-hib\".")
    _check_keys(table, tuple(SETTINGS), f"{where}: [grid]")
    if "model" not in table:
        raise ConfigError(f"{where}: [grid] needs model = one of {list(NETWORKS)} (or a list of them).")
    grid = {}
    for key, raw in table.items():
        setting = SETTINGS[key]
        values = raw if isinstance(raw, list) else [raw]
        if not values:
            raise ConfigError(f"{where}: [grid] {key} is an empty list; give at least one value "
                              f"({setting.describe()}).")
        for v in values:
            if not setting.check(v):
                raise ConfigError(f"{where}: [grid] {key} must be {setting.describe()} (or a list of them). "
                                  f"Got {v!r} instead.")
        values = [float(v) if setting.as_float else v for v in values]
        seen: set[str] = set()
        for v in values:  # by JSON text, so that data_fraction 1 (one trajectory) and 1.0 (all) differ
            if json.dumps(v) in seen:
                raise ConfigError(f"{where}: [grid] {key} lists {v!r} more than once.")
            seen.add(json.dumps(v))
        grid[key] = tuple(values)
    return grid


def _parse_list(table: Mapping[str, Any], key: str, allowed: tuple[str, ...], where: str,
                default: tuple[str, ...]) -> tuple[str, ...]:
    if key not in table or table[key] == [] and not default:
        return default  # an empty list is the default (to_dict writes it so)
    values = table[key] if isinstance(table[key], list) else [table[key]]
    bad = [v for v in values if v not in allowed]
    if bad or not values:
        raise ConfigError(f"{where}: {key} must be a non-empty list from {list(allowed)}. "
                          f"Got {bad[0] if bad else table[key]!r} instead.")
    return tuple(values)


def _check_keys(table: Mapping[str, Any], allowed: tuple[str, ...], where: str) -> None:
    for key in table:
        if key not in allowed:
            close = difflib.get_close_matches(str(key), allowed, n=1)
            hint = f" Did you mean {close[0]!r}?" if close else ""
            raise ConfigError(f"{where}: unknown key {key!r}.{hint} Allowed keys: {', '.join(allowed)}.")
