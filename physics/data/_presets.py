"""Named loaders for the measured data sets in the shared data folder."""

from __future__ import annotations

import os
import re
from collections.abc import Callable
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from scipy.io import loadmat

from ._checks import check_rate
from ._errors import DataError, DataNotFoundError
from ._fetch import ENV_VAR, SHARED, dataset_folder
from ._io import read_csv_columns
from ._trajectory import Dataset, DataSplit, Trajectory

__all__ = ["data_root", "load_preset", "PRESETS", "PROTOCOLS", "data_names", "niti_tip_angle"]


def data_root() -> Path:
    """Locate the shared data folder.

    ``$HYST_DATA_DIR`` if set, else ``<repo root>/../shared/data``, where the
    repo root is the parent of the ``hybrid/`` package.

    Raises
    ------
    DataNotFoundError
        The folder does not exist.
    """
    env = os.environ.get(ENV_VAR)
    if env:
        root = Path(env).expanduser()
        if not root.is_dir():
            raise DataNotFoundError(
                f"{ENV_VAR} is set to {env!r}, which is not a folder. Point it at the shared data "
                "folder (the one holding catheter_2023/) or unset it to use <repo>/../shared/data."
            )
        return root
    root = SHARED
    if not root.is_dir():
        raise DataNotFoundError(
            f"the shared data folder was not found at {root}. Set the {ENV_VAR} environment variable "
            "to the folder that holds catheter_2023/ and niti_frequency_trials/, or pass root=..."
        )
    return root


def _folder(root: str | os.PathLike[str] | None, name: str) -> Path:
    if root is None:  # $HYST_DATA_DIR, the shared folder beside a clone, or the user cache (downloaded)
        return dataset_folder(name)
    folder = Path(root) / name
    if not folder.is_dir():
        raise DataNotFoundError(f"preset folder {folder} does not exist. Check root= or {ENV_VAR}.")
    return folder


def _check_input(name: str, input: str | None, choices: dict[str, str]) -> str:  # noqa: A002
    chosen = next(iter(choices)) if input is None else input
    if chosen not in choices:
        raise DataError(f"preset {name!r} has no input {input!r}. Must be one of {list(choices)}.")
    return chosen


# --------------------------------------------------------------------- catheter
CATHETER_INPUTS = {"Tendon Disp.": "mm", "Motor Curr.": ""}
CATHETER_COLUMNS = ("Time", "Tendon Disp.", "Motor Curr.", "Pos x", "Pos y", "Pos z", "Angle x", "Angle y", "Angle z")


def _load_catheter(rate_hz: float | None, input: str | None, root) -> DataSplit:  # noqa: A002
    folder = _folder(root, "catheter_2023")
    chosen = _check_input("catheter_2023", input, CATHETER_INPUTS)
    train, test = [], []
    for s in (1, 2):
        for f in range(1, 6):
            path = folder / f"data_{s}_{f}.txt"
            cols = read_csv_columns(path, CATHETER_COLUMNS)
            others = [c for c in CATHETER_COLUMNS if c not in ("Time", chosen, "Angle x")]
            meta = {
                "set": s, "frequency_hz": f / 10, "baseline": "nonzero" if s == 1 else "zero",
                "file": path.name, "preset": "catheter_2023",
            }
            traj = _build(
                cols["Time"], cols[chosen], cols["Angle x"], rate_hz, path,
                input_name=chosen, output_name="Angle x", input_unit=CATHETER_INPUTS[chosen],
                output_unit="deg", extra={c: cols[c] for c in others}, meta=meta,
            )
            (train if s == 1 else test).append(traj)
    return DataSplit(Dataset(train), Dataset(test))


# ------------------------------------------------------------------------- NiTi
NITI_INPUTS = {"Tension": "N", "Stroke": "mm", "Stroke_Ref": "mm"}
#: Train on the authors' training frequencies plus the slow repeats; hold out 0.15 Hz and random.
NITI_TRAIN = ("f001_data_2.mat", "f002_data_2.mat", "f010_data.mat", "f020_data.mat", "f030_data.mat")
NITI_TEST = ("f015_data.mat", "f015_data_2.mat", "Random_data.mat")
# Data_x2_09252023.mat is left out: it is a byte-for-byte copy of f001_data_2.mat's arrays.


def niti_tip_angle(markers: NDArray[np.float64]) -> NDArray[np.float64]:
    """Tip bending angle in degrees from ``MarkerDataSynced`` (n x 3 x 12).

    The tip tangent is the unit vector from the marker of disk 11 to the
    marker of disk 12 (the last two). The angle is measured in the bending
    plane, from the first sample's tangent ``e1`` towards ``e2``, the unit
    component orthogonal to ``e1`` of the tangent farthest from ``e1``:
    ``atan2(d . e2, d . e1)``. It is 0 at the first sample, positive when
    the robot bends, and independent of the camera frame (the files differ
    in axis signs); noise around zero is not rectified.
    """
    m = np.asarray(markers, dtype=np.float64)
    if m.ndim != 3 or m.shape[1] != 3 or m.shape[2] < 2:
        raise DataError(f"MarkerDataSynced must have shape (n, 3, n_markers >= 2); got {m.shape}.")
    d = m[:, :, -1] - m[:, :, -2]
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    e1 = d[0]
    ortho = d - np.outer(d @ e1, e1)
    k = int(np.argmax(np.linalg.norm(ortho, axis=1)))
    norm = np.linalg.norm(ortho[k])
    if norm < 1e-9:
        raise DataError("the last two markers never change direction, so no bending angle can be computed.")
    e2 = ortho[k] / norm
    return np.degrees(np.arctan2(d @ e2, d @ e1))


def _load_niti(rate_hz: float | None, input: str | None, root) -> DataSplit:  # noqa: A002
    folder = _folder(root, "niti_frequency_trials")
    chosen = _check_input("niti_frequency_trials", input, NITI_INPUTS)
    out: dict[str, list[Trajectory]] = {"train": [], "test": []}
    for split, files in (("train", NITI_TRAIN), ("test", NITI_TEST)):
        for name in files:
            path = folder / name
            if not path.is_file():
                raise DataNotFoundError(f"NiTi data file {path} is missing. Check root= or {ENV_VAR}.")
            mat = loadmat(path)
            needed = ["Time", "MarkerDataSynced", *NITI_INPUTS]
            absent = [k for k in needed if k not in mat]
            if absent:
                raise DataError(f"{path} lacks the field(s) {absent}; fields present: {sorted(k for k in mat if not k.startswith('__'))}.")
            t = np.ravel(mat["Time"]).astype(np.float64)
            match = re.match(r"f(\d{3})_", name)
            meta = {
                "file": name, "preset": "niti_frequency_trials", "time_offset_s": float(t[0]),
                "frequency_hz": int(match.group(1)) / 100 if match else None,
                "excitation": "decaying sinusoid" if match else "random",
            }
            if not match:  # a random excitation is out of the training distribution (decaying sinusoids)
                meta["test_category"] = "ood_random"
            out[split].append(_build(
                t - t[0], np.ravel(mat[chosen]), niti_tip_angle(mat["MarkerDataSynced"]), rate_hz, path,
                input_name=chosen, output_name="tip_angle", input_unit=NITI_INPUTS[chosen], output_unit="deg",
                extra={k: np.ravel(mat[k]) for k in NITI_INPUTS if k != chosen}, meta=meta,
            ))
    return DataSplit(Dataset(out["train"]), Dataset(out["test"]))


def _build(time, u, y, rate_hz: float | None, path: Path, **kwargs) -> Trajectory:
    kwargs["source"] = path.name
    try:
        if rate_hz is None:
            return Trajectory(time, u, y, **kwargs)
        return Trajectory.from_raw(time, u, y, rate_hz=rate_hz, **kwargs)
    except DataError as exc:
        raise DataError(f"{path}: {exc}") from None


# ------------------------------------------------------------ Bouc-Wen benchmark
BOUCWEN_RATE_HZ = 750.0


def _load_boucwen(rate_hz: float | None, input: str | None, root) -> DataSplit:  # noqa: A002
    _check_input("boucwen_benchmark", input, {"u": "N"})
    if rate_hz is not None and rate_hz != BOUCWEN_RATE_HZ:
        raise DataError(f"boucwen_benchmark is sampled at {BOUCWEN_RATE_HZ:g} Hz, above the band of its "
                        f"multisine (5-150 Hz); resampling it to {rate_hz:g} Hz would alias it. Load it at its own rate "
                        "(rate_hz=None or 'default').")
    path = _folder(root, "boucwen_benchmark") / "bouc-wen.mat"
    mat = loadmat(path)
    parts = {"train": ("u", "y"), "multisine": ("uval_multisine", "yval_multisine"),
             "sinesweep": ("uval_sinesweep", "yval_sinesweep")}
    runs = {}
    for part, (ku, ky) in parts.items():
        u, y = np.ravel(mat[ku]).astype(np.float64), np.ravel(mat[ky]).astype(np.float64)
        runs[part] = _build(np.arange(u.size) / BOUCWEN_RATE_HZ, u, y, rate_hz, path, input_name="u",
                            output_name="y", input_unit="N", output_unit="m",
                            meta={"file": path.name, "preset": "boucwen_benchmark", "part": part})
    return DataSplit(Dataset([runs["train"]]), Dataset([runs["multisine"], runs["sinesweep"]]))


PRESETS: dict[str, Callable[..., DataSplit]] = {
    "catheter_2023": _load_catheter,
    "niti_frequency_trials": _load_niti,
    "boucwen_benchmark": _load_boucwen,
}


# -------------------------------------------------------------------- protocols
def _reverse(split: DataSplit) -> DataSplit:
    return DataSplit(split.test, split.train)


#: Frequencies (Hz) of the interpolation protocol's training runs; the others are its tests.
INTERP_TRAIN_HZ = (0.1, 0.3, 0.5)


def _interp(split: DataSplit) -> DataSplit:
    runs = [*split.train, *split.test]
    trained = [any(abs(t.meta["frequency_hz"] - f) < 1e-9 for f in INTERP_TRAIN_HZ) for t in runs]
    return DataSplit(Dataset(t for t, k in zip(runs, trained) if k), Dataset(t for t, k in zip(runs, trained) if not k))


#: Other splits of a preset's runs, named ``"<preset>:<protocol>"``: preset name and how to re-split.
PROTOCOLS: dict[str, tuple[str, Callable[[DataSplit], DataSplit]]] = {
    "catheter_2023:reverse": ("catheter_2023", _reverse),   # train set 2 (zero baseline), test set 1
    "catheter_2023:interp": ("catheter_2023", _interp),     # both sets: 0.1/0.3/0.5 Hz train, 0.2/0.4 Hz test
}


def data_names() -> list[str]:
    """Every name :func:`load_preset` accepts: the presets and their protocols."""
    return [*PRESETS, *PROTOCOLS]


#: Each data set's rate when none is asked for: the seed paper's 25 Hz for the catheter and the NiTi
#: robot; the Bouc-Wen benchmark's own 750 Hz (None: its raw samples), above its 5-150 Hz band.
DEFAULT_RATES: dict[str, float | None] = {"catheter_2023": 25.0, "niti_frequency_trials": 25.0,
                                          "boucwen_benchmark": None}


def load_preset(
    name: str,
    rate_hz: float | None | str = "default",
    input: str | None = None,  # noqa: A002
    root: str | os.PathLike[str] | None = None,
) -> DataSplit:
    """Load a measured data set as a train/test split.

    Parameters
    ----------
    name : {"catheter_2023", "catheter_2023:reverse", "catheter_2023:interp", "niti_frequency_trials", "boucwen_benchmark"}
        ``catheter_2023``: clinical tendon catheter, input ``"Tendon Disp."``
        (mm, default) or ``"Motor Curr."``, output ``"Angle x"`` (deg); set 1
        (non-zero baseline) is train, set 2 (zero baseline) is test.
        ``niti_frequency_trials``: NiTi robot, input ``"Tension"`` (N,
        default), ``"Stroke"`` or ``"Stroke_Ref"`` (mm), output the tip angle
        of :func:`niti_tip_angle` (deg); train f001_2, f002_2, f010, f020,
        f030, test f015, f015_2 and the random excitation (``meta["test_category"]``
        ``"ood_random"``). Time starts at 0. A protocol (:data:`PROTOCOLS`) re-splits a
        preset's runs: ``catheter_2023:reverse`` trains on set 2 and tests on set 1,
        ``catheter_2023:interp`` trains on both sets' 0.1, 0.3 and 0.5 Hz runs and tests
        on their 0.2 and 0.4 Hz runs.
        ``boucwen_benchmark``: force ``u`` (N) -> displacement ``y`` (m) at 750 Hz;
        train the 5-period multisine, test the multisine and the sine sweep.
        Files are found or downloaded as :func:`physics.data._fetch.dataset_folder` says.
    rate_hz : float, None or "default"
        Resampling rate; ``None`` keeps the raw samples; ``"default"`` is the data set's own
        (:data:`DEFAULT_RATES`: 25 Hz for the catheter and the NiTi robot, as in the seed paper;
        the Bouc-Wen benchmark's raw 750 Hz).
    input : str, optional
        Input column; ``None`` picks the default.
    root : path-like, optional
        The shared data folder; default :func:`data_root`.

    Returns
    -------
    DataSplit
        ``(train, test)``; ``meta`` holds ``frequency_hz``, ``file`` and more.
    """
    if name not in PRESETS and name not in PROTOCOLS:
        raise DataError(f"unknown preset {name!r}. Must be one of {data_names()}.")
    if isinstance(rate_hz, str):
        if rate_hz != "default":
            raise DataError(f"rate_hz must be a rate in Hz, None (the raw samples) or 'default'. Got {rate_hz!r}.")
        rate_hz = DEFAULT_RATES[PROTOCOLS[name][0] if name in PROTOCOLS else name]
    if rate_hz is not None:
        check_rate(rate_hz)
    if name in PROTOCOLS:
        base, resplit = PROTOCOLS[name]
        return resplit(PRESETS[base](rate_hz, input, root))
    return PRESETS[name](rate_hz, input, root)
