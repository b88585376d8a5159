"""The data of the experiments: a data name, folder or preset turned into train and test trajectories.

Table I, the comparison, the ablations and the ``hyst`` commands that run them load
their data here and nowhere else:

``"virtual"``        the seed paper's protocol on the virtual catheter (its settings adjustable)
``"catheter_2023"``  the real catheter: train set 1, test set 2 (``:reverse`` set 2 -> set 1,
                     ``:interp`` both sets, 0.1/0.3/0.5 Hz train, 0.2/0.4 Hz test)
``"niti_frequency_trials"``  the NiTi robot, tension -> tip angle (random excitation: ``ood_random``)
a folder             ``train/*.csv`` and ``test/*.csv`` (as ``hyst simulate --paper-dataset`` writes)

:func:`compare_data` adds the comparison's out-of-distribution test categories.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from physics.data import DataError, Dataset, DataSplit, data_names, load_csv, load_preset, raw_rate
from physics.data.io import read_csv_columns, read_json

__all__ = ["CompareData", "compare_data", "load_data"]

#: Settings of the virtual data that go to ``VirtualCatheter``; the others go to ``paper_protocol``.
_CATHETER_SETTINGS = ("effects", "input")


def load_data(data: str | os.PathLike[str], seed: int = 0, **virtual: Any) -> DataSplit:
    """The train/test split named by ``data``.

    Parameters
    ----------
    data : str or path
        ``"virtual"`` (the paper's protocol on the virtual catheter), a measured data set or
        protocol (:func:`physics.data.data_names`: ``"catheter_2023"`` train set 1, test set 2;
        ``"catheter_2023:reverse"``; ``"catheter_2023:interp"``; ``"niti_frequency_trials"``)
        or a folder with ``train/*.csv`` and ``test/*.csv`` (columns ``time,u,y``), resampled at its
        ``manifest.json``'s ``rate_hz`` where it gives one, else at the rate its files were
        recorded at (:func:`physics.data.raw_rate`, pooled over train and test).
    seed : int
        Seed of the virtual catheter's noise.
    **virtual
        For ``"virtual"`` only: ``effects`` and ``input`` of the catheter, ``frequencies``,
        ``tests`` and ``baselines`` of the protocol.
    """
    if data == "virtual":
        return _virtual(seed, virtual)[1]
    if virtual:
        raise DataError(f"{sorted(virtual)} set the virtual data; {str(data)!r} is measured data. "
                        "Drop them or use data 'virtual'.")
    if str(data) in data_names():
        return load_preset(str(data))
    folder = Path(data)
    if not folder.is_dir():
        raise DataError(f"--data {str(data)!r} is neither 'virtual', a measured data set ({', '.join(data_names())}) "
                        "nor a folder. Give one of those names, or a folder written by "
                        "`hyst simulate --paper-dataset --out DIR`.")
    files = {part: _csv_files(folder, part) for part in ("train", "test")}
    blob = read_json(folder / "manifest.json", "manifest") if (folder / "manifest.json").is_file() else {}
    rate = blob.get("rate_hz") or blob.get("parameters", {}).get("rate_hz")
    if rate is None:
        rate = raw_rate([read_csv_columns(f, ["time"])["time"] for f in files["train"] + files["test"]])
    return DataSplit(*(_load_folder(files[part], blob, float(rate)) for part in ("train", "test")))


def _virtual(seed: int, settings: dict[str, Any]):
    """The virtual catheter and the paper's protocol run on it."""
    from physics.virtual import VirtualCatheter, paper_protocol

    settings = dict(settings)
    catheter = VirtualCatheter(**{k: settings.pop(k) for k in _CATHETER_SETTINGS if k in settings}, seed=seed)
    return catheter, paper_protocol(catheter, **settings)


def _csv_files(folder: Path, part: str) -> list[Path]:
    files = sorted((folder / part).glob("*.csv"))
    if not files:
        raise DataError(f"{folder / part} holds no CSV files; expected {part}/*.csv with columns time,u,y.")
    return files


def _load_folder(files: list[Path], manifest: dict, rate_hz: float) -> Dataset:
    units = {"u": "", "y": "", **manifest.get("units", {})}  # a folder without a manifest names no units
    info = {Path(f["file"]).stem: f for f in manifest.get("files", [])}
    trajs = []
    for f in files:
        meta = {k: v for k, v in info.get(f.stem, {}).items() if k in ("frequency_hz", "baseline")}
        t = load_csv(f, rate_hz=rate_hz, input_unit=units["u"], output_unit=units["y"], meta=meta)
        trajs.append(replace(t, source=f.stem))
    return Dataset(trajs)


# --------------------------------------------------------------- comparison
@dataclass
class CompareData:
    """Training runs, test runs per category, and the extra training sets of :func:`hybrid.compare`."""

    train: Dataset
    tests: dict[str, Dataset]
    baseline: tuple[Dataset, Dataset] | None = None  # (train without 'end', 'end' tests)
    subsets: dict[str, Dataset] = field(default_factory=dict)
    noise_floor: float | None = None
    name: str = ""


def compare_data(data: str, seed: int = 0, preset: str = "quick") -> CompareData:
    """The data of a comparison: ``"virtual"`` (all categories), a measured data set or a folder.

    Measured test runs go to the category in their ``meta["test_category"]`` (``"id"`` when
    absent; the NiTi robot's random excitation is ``"ood_random"``). The "tiny" preset
    (tests only) runs fewer and shorter virtual trajectories.
    """
    if data != "virtual":
        split = load_data(data, seed=seed)
        tests: dict[str, list] = {"id": []}
        for t in split.test:
            tests.setdefault(t.meta.get("test_category", "id"), []).append(t)
        return CompareData(split.train, {k: Dataset(v) for k, v in tests.items() if v}, None,
                           _subsets(split.train), None, str(data))
    from physics.virtual import DecayingSinusoid, RandomSteps

    tiny = preset == "tiny"
    cath, split = _virtual(seed, dict(frequencies=(0.4, 0.5) if tiny else (0.1, 0.2, 0.3, 0.4, 0.5),
                                      tests=(0.45,) if tiny else (0.15, 0.45)))
    freqs, amps = ((0.8,), (0.45,)) if tiny else ((0.6, 0.8, 1.0), (0.15, 0.45))
    steps = (0,) if tiny else (0, 1)
    tests = {
        "id": split.test,
        "ood_freq": Dataset(cath.run(DecayingSinusoid(f, "mid"), name=f"f{f:.2f}_mid") for f in freqs),
        "ood_amp": Dataset(cath.run(DecayingSinusoid(f, "mid", q_max_mm=3.6), name=f"f{f:.2f}_mid_q3.6")
                           for f in amps),
        "ood_steps": Dataset(cath.run(RandomSteps(duration_s=20.0 if tiny else 60.0, seed=s), name=f"seed{s}")
                             for s in steps),
    }
    keep = [t for t in split.train if t.meta.get("baseline") != "end"]
    ends = [t for t in split.test if t.meta.get("baseline") == "end"]
    return CompareData(split.train, tests, (Dataset(keep), Dataset(ends)), _subsets(split.train), cath.noise_floor,
                       "virtual")


def _subsets(train: Dataset) -> dict[str, Dataset]:
    """1 run (the middle one: 0.3 Hz mid on the virtual protocol) and 3 runs spread over the list;
    a subset as large as the training set itself is left out (its scores are data_all's)."""
    n = len(train)
    out = {"data_1": Dataset([train[n // 2]])} if n > 1 else {}
    if n > 3:
        out["data_3"] = Dataset([train[int(i)] for i in np.linspace(0, n - 1, 3).round().astype(int)])
    return out
