"""Ablation configs: parsing, the errors for bad keys and values, grid expansion, single runs."""

from __future__ import annotations


import numpy as np
import pytest

from hybrid.experiments.ablation import (AblationConfig, ConfigError, DataConfig, bundled_configs, config_path,
                                         execute_run, select_training)
from physics.data import DataError

SMALL_DATA = {"frequencies": [0.4, 0.5], "tests": [0.45], "baselines": ["mid", "end"]}


def config(grid, data=SMALL_DATA, **top):
    return AblationConfig.from_dict({"data": dict(data), "grid": grid, **top})


# ------------------------------------------------------------------ parsing
@pytest.mark.parametrize("name, n_runs, varied", [
    ("tiny", 4, ("buffer", "seed")),
    ("buffer_length", 30, ("direction", "buffer", "seed")),
    ("lstm_sequence", 30, ("direction", "seq_len", "seed")),
    ("hybrid_vs_pure", 60, ("model", "physics", "data_fraction", "seed")),
])
def test_shipped_configs_parse(name, n_runs, varied):
    cfg = AblationConfig.from_toml(config_path(name))
    assert cfg.name == name
    assert len(cfg.runs()) == n_runs
    assert cfg.varied == varied


def test_hybrid_config_is_marked():
    cfg = AblationConfig.from_toml(config_path("hybrid_vs_pure"))
    assert cfg.requires == ("HybridModel",)
    assert {r.kind for r in cfg.runs()} == {"learned", "hybrid"}


def test_toml_values_reach_the_config(tmp_path):
    path = tmp_path / "a.toml"
    path.write_text('metrics = ["rmse"]\n[data]\nsource = "virtual"\neffects = ["hysteresis", "lag"]\nseed = 3\n'
                    'frequencies = [0.5]\n[grid]\nmodel = "lstm"\nseq_len = [10, 20]\nlr = 0.01\n')
    cfg = AblationConfig.from_toml(path)
    assert cfg.name == "a" and cfg.metrics == ("rmse",)
    assert cfg.data.effects == ("actuator_lag", "hysteresis") and cfg.data.seed == 3 and cfg.data.frequencies == (0.5,)
    assert cfg.grid == {"model": ("lstm",), "seq_len": (10, 20), "lr": (0.01,)}


@pytest.mark.parametrize("table, match", [
    ({"grid": {"model": "fnn", "bufer": 3}},
     r"\[grid\]: unknown key 'bufer'. Did you mean 'buffer'\? Allowed keys: model"),
    ({"grid": {"model": "fnn"}, "grids": {}}, r"unknown key 'grids'. Did you mean 'grid'\?"),
    ({"grid": {"model": "fnn"}, "data": {"source": "virtual", "path": "x"}},
     r"\[data\] \(source = 'virtual'\): unknown key 'path'. Allowed keys: source, effects"),
    ({"grid": {"model": "gru"}}, r"\[grid\] model must be one of \['fnn', 'fnn-hib', 'lstm'\].*Got 'gru'"),
    ({"grid": {"model": "fnn-hib", "buffer": [10, 0]}}, r"\[grid\] buffer must be an integer >= 1.*Got 0 instead"),
    ({"grid": {"model": "fnn-hib", "buffer": 2.5}}, r"buffer must be an integer >= 1.*Got 2.5"),
    ({"grid": {"model": "fnn", "epochs": True}}, r"epochs must be an integer >= 1.*Got True"),
    ({"grid": {"model": "fnn", "lr": 2}}, r"lr must be a number in \(0, 1\).*Got 2 instead"),
    ({"grid": {"model": "fnn", "physics": "lag+foo"}},
     r"physics must be 'none' or block names joined by '\+'.*boucwen"),
    ({"grid": {"model": "fnn", "data_fraction": 1.5}}, r"data_fraction must be a fraction in \(0, 1\].*Got 1.5"),
    ({"grid": {"model": "fnn", "seed": []}}, r"\[grid\] seed is an empty list"),
    ({"grid": {"model": "fnn", "seed": [0, 1, 0]}}, r"\[grid\] seed lists 0 more than once"),
    ({"grid": {"buffer": 5}}, r"\[grid\] needs model = one of"),
    ({"data": {}}, r"missing the \[grid\] table"),
    ({"grid": {"model": "fnn"}, "data": {"source": "s3"}}, r"\[data\] source must be one of \['virtual', "
                                                           r"'catheter_2023', 'folder'\]. Got 's3'"),
    ({"grid": {"model": "fnn"}, "data": {"source": "folder"}}, r"source = 'folder' needs path"),
    ({"grid": {"model": "fnn"}, "data": {"effects": ["lag", "wobble"]}}, r"\[data\] effects: Unknown effect"),
    ({"grid": {"model": "fnn"}, "data": {"baselines": ["top"]}}, r"baselines must be a non-empty list from"),
    ({"grid": {"model": "fnn"}, "metrics": ["rmse", "mae"]}, r"metrics must be a non-empty list from "
                                                             r"\['rmse', 'nrmse', 'fit_seconds'\]. Got 'mae'"),
    ({"grid": {"model": "fnn"}, "requires": ["Magic"]}, r"requires must be a non-empty list from \['HybridModel'\]"),
])
def test_bad_config_names_key_and_allowed_values(table, match):
    with pytest.raises(ConfigError, match=match):
        AblationConfig.from_dict(table, where="cfg.toml")


def test_bad_toml_and_missing_file(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[grid]\nmodel = \n")
    with pytest.raises(ConfigError, match=r"bad.toml: not valid TOML"):
        AblationConfig.from_toml(bad)
    with pytest.raises(ConfigError, match=r"does not exist"):
        AblationConfig.from_toml(tmp_path / "nope.toml")


def test_top_level_key_after_a_table_is_reported_in_that_table(tmp_path):
    # TOML puts a key written after [grid] inside [grid]: the error says where it landed.
    path = tmp_path / "late.toml"
    path.write_text('[grid]\nmodel = "fnn"\nmetrics = ["rmse"]\n')
    with pytest.raises(ConfigError, match=r"\[grid\]: unknown key 'metrics'"):
        AblationConfig.from_toml(path)


# ---------------------------------------------------------------- expansion
def test_grid_is_the_product_with_seed_fastest():
    runs = config({"model": "fnn-hib", "buffer": [10, 20], "hidden": [8, 16], "seed": [0, 1, 2]}).runs()
    assert len(runs) == 12
    assert [(r.settings["buffer"], r.settings["hidden"], r.settings["seed"]) for r in runs[:4]] == \
        [(10, 8, 0), (10, 8, 1), (10, 8, 2), (10, 16, 0)]
    assert len({r.run_id for r in runs}) == 12


def test_settings_that_do_not_apply_are_dropped_without_repeating_runs():
    runs = config({"model": ["fnn-hib", "lstm"], "buffer": [10, 20], "seq_len": [5, 7]}).runs()
    hib = [r for r in runs if r.settings["model"] == "fnn-hib"]
    lstm = [r for r in runs if r.settings["model"] == "lstm"]
    assert len(hib) == 2 and len(lstm) == 2
    assert all(r.settings["seq_len"] is None and r.settings["mode"] is None for r in hib)
    assert all(r.settings["buffer"] is None for r in lstm)
    assert {r.kind for r in runs} == {"learned"}


def test_defaults_fill_unnamed_settings():
    (run,) = config({"model": "lstm"}).runs()
    s = run.settings
    assert (s["direction"], s["physics"], s["seq_len"], s["hidden"], s["epochs"], s["lr"], s["data_fraction"],
            s["seed"]) == ("forward", "none", 50, 64, 40, 1e-3, 1.0, 0)


def test_run_id_is_stable_and_depends_on_settings_and_data():
    grid = {"model": "fnn-hib", "buffer": [10, 20]}
    a, b = config(grid).runs(), config(grid).runs()
    assert [r.run_id for r in a] == [r.run_id for r in b]
    assert a[0].run_id.startswith("fnn-hib-") and len(a[0].run_id) == len("fnn-hib-") + 12
    other_data = config(grid, data={**SMALL_DATA, "seed": 1}).runs()
    assert not {r.run_id for r in a} & {r.run_id for r in other_data}
    # 1 (one trajectory) and 1.0 (all of them) are different runs; lr 0.001 and 1e-3 the same run
    fractions = config({"model": "fnn", "data_fraction": [1, 1.0]}).runs()
    assert len({r.run_id for r in fractions}) == 2
    (milli,), (exp,) = config({"model": "fnn", "lr": 0.001}).runs(), config({"model": "fnn", "lr": 1e-3}).runs()
    assert milli.run_id == exp.run_id


def test_physics_runs_are_hybrid_and_normalised():
    runs = config({"model": "fnn-hib", "physics": ["None", "backlash + boucwen + linear"]}).runs()
    assert [r.settings["physics"] for r in runs] == ["none", "backlash+boucwen+linear"]
    assert [r.kind for r in runs] == ["learned", "hybrid"]


# --------------------------------------------------------------- data, runs
def test_select_training_nests_subsets_for_one_seed():
    train = DataConfig(**{k: tuple(v) for k, v in SMALL_DATA.items()}).load().train
    assert len(select_training(train, 1.0, 0)) == 4
    two = select_training(train, 0.5, seed=3).names
    one = select_training(train, 1, seed=3).names
    assert len(two) == 2 and set(one) <= set(two)
    with pytest.raises(DataError, match=r"data_fraction = 5 asks for 5 training trajectories but the data has 4"):
        select_training(train, 5, 0)


@pytest.mark.parametrize("direction", ["forward", "inverse"])
def test_execute_run_dummy_scores_each_test_and_pooled(direction):
    (spec,) = config({"model": "dummy", "buffer": 5, "direction": direction, "data_fraction": 3}).runs()
    record = execute_run(spec)
    assert record["run_id"] == spec.run_id and record["status"] == "ok" and record["kind"] == "dummy"
    assert record["n_train"] == 3 and len(record["train"]) == 3
    assert record["unit"] == ("mm" if direction == "inverse" else "deg")
    tests = record["metrics"]["per_test"]
    assert [t["test"] for t in tests] == ["test_f0.45_mid", "test_f0.45_end"]
    pooled = np.sqrt(sum(t["rmse"] ** 2 * t["n"] for t in tests) / sum(t["n"] for t in tests))
    assert record["metrics"]["rmse"] == pytest.approx(pooled)
    assert 0 < record["metrics"]["nrmse"] < 0.2  # a linear map on 5 inputs already follows the loop
    assert set(record["timings"]) == {"data_s", "fit_s", "predict_s", "total_s"}


def test_execute_run_fails_clearly_for_a_buffer_longer_than_the_data():
    (spec,) = config({"model": "dummy", "buffer": 100_000}).runs()
    with pytest.raises(DataError, match=r"has 438 samples but buffer = 100000"):
        execute_run(spec)


def test_config_round_trips_through_to_dict():
    from hybrid.experiments.ablation import AblationConfig
    cfg = AblationConfig.from_toml(config_path("tiny"))
    again = AblationConfig.from_dict(cfg.to_dict())
    assert [r.run_id for r in again.runs()] == [r.run_id for r in cfg.runs()]


def test_bundled_configs_are_found_by_name_and_an_unknown_name_lists_them(tmp_path):
    assert {"tiny", "buffer_length", "lstm_sequence", "hybrid_vs_pure"} <= set(bundled_configs())
    assert config_path("tiny") == config_path("tiny.toml") and config_path("tiny").is_file()
    own = tmp_path / "tiny.toml"  # a file of the user's wins over the bundled name
    own.write_text("x = 1")
    assert config_path(own) == own
    with pytest.raises(ConfigError, match="bundled config.*tiny"):
        config_path("tinny")
