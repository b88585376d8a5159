"""``benchmarks/real_labs.py`` on the smallest real lab set in the shared data: the default path, with no
modelling option, against a linear ARX and a static line, and its 90 % band on the test runs."""

import importlib.util
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _load(name: str):
    spec = importlib.util.spec_from_file_location(name, ROOT / "benchmarks" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # its dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


def test_the_default_path_on_the_smallest_lab_set_beats_the_peers_and_covers_its_test_runs(root, tmp_path):
    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        _load("new_lab")
        real_labs = _load("real_labs")
    finally:
        sys.path.remove(str(ROOT / "benchmarks"))
    sets = real_labs.lab_sets(root)
    if not sets:
        pytest.skip(f"no lab sets under {root / 'labs'}")

    def samples(name):  # the training rows: the fastest set to fit
        return sum(len(p.read_text().splitlines()) for p in (root / "labs" / name / "train").glob("*.csv"))

    row = real_labs.run_set(min(sets, key=samples), root, tmp_path / "model")
    assert row["vs_arx"] <= real_labs.ARX_TARGET and row["vs_line"] <= real_labs.LINE_TARGET, row
    assert real_labs.COVERAGE[0] <= row["coverage"] <= real_labs.COVERAGE[1], row
    assert (tmp_path / "model" / "step.casadi").is_file() and row["seconds"] > 0
