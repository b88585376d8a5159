"""compare --interval at a level the held-out runs cannot calibrate: compare.md says so, per model (the
reasons were only in run.json's 'skipped', and the intervals were simply missing)."""

import numpy as np

from hybrid.experiments._compare_table import Row, write_tables
from hybrid.experiments._datasets import CompareData
from physics.data import Trajectory


def test_intervals_not_calibrated_are_listed_in_compare_md(tmp_path):
    rows = [Row("forward", "physics", "physics", "id:run", 1.5, 0.1, 10)]
    run = Trajectory(np.arange(20) * 0.04, np.linspace(0, 1, 20), np.linspace(0, 2, 20), source="run")
    data = CompareData(train=[run], tests={"id": [run]}, name="mine")
    reason = "A 99.9% interval needs at least 999 groups of held-out samples; the 2 held-out runs give 78"
    write_tables(rows, tmp_path, data, [], skipped={"intervals/physics": reason})
    text = (tmp_path / "compare.md").read_text()
    assert "## Intervals not calibrated" in text and f"- physics: {reason}" in text
    assert not (tmp_path / "intervals.csv").exists()
    write_tables(rows, tmp_path, data, [])
    assert "not calibrated" not in (tmp_path / "compare.md").read_text()
