"""A model folder's stages (``stages.json``): what each finished stage found, the key of its inputs and the files it
wrote, so that ``resume`` reuses a stage whose inputs are unchanged. One home for the folders of one output
(:mod:`._fit`) and of several (:mod:`._fit_outputs`)."""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path
from typing import Any

import numpy as np

from physics.data import DataError
from physics.data.io import write_json
from hybrid.export._load import MODEL_DIR_STAGES, file_sha256, read_stages


def _model_file(chosen: dict) -> str:
    """The folder's model file: the peer's, the hybrid's checkpoint, or the physics fit."""
    return chosen.get("model") or ("physics.json" if chosen["residual"] == "none" else "model.pt")


def _data_key(train, test, seed, preset) -> str:
    h = hashlib.sha256(json.dumps([seed, preset]).encode())
    for t in [*train, None, *test]:
        if t is not None:
            for a in (t.time, t.u, t.y):
                h.update(np.ascontiguousarray(a, dtype=np.float64).tobytes())
            for name, a in t.extra.items():  # the measured inputs: fit_model_dir keeps no other extra column
                h.update(name.encode() + np.ascontiguousarray(a, dtype=np.float64).tobytes())
        h.update(b"|")
    return h.hexdigest()


class _Stages:
    """``stages.json``: per finished stage, the key of its inputs, its result and the SHA-256 of the files it
    wrote. Written into the new folder ``out``; with ``resume``, the stages of the ``previous`` folder are
    read, and a stage is reused only with its files, copied from there and checked against their hashes."""

    def __init__(self, out: Path, resume: bool, data_key: str, previous: Path | None = None):
        self.out, self.previous = out, previous if previous is not None else out
        self.path, self.data_key, self.reused = out / MODEL_DIR_STAGES, data_key, []
        self.state: dict = {}
        old = self.previous / MODEL_DIR_STAGES
        if resume and old.is_file():
            try:
                self.state = read_stages(old)
            except ValueError as exc:
                raise DataError(f"{exc} (or run without --resume)" if "not valid JSON" in str(exc) else str(exc)) \
                    from None

    def key(self, *parts) -> str:
        return hashlib.sha256(json.dumps([self.data_key, *parts], sort_keys=True, default=str).encode()).hexdigest()

    def reuse(self, stage: str, key: str):
        entry = self.state.get(stage)
        if entry and entry.get("key") == key and self._bring(stage, entry):
            self.reused.append(stage)
            return entry["result"]
        return None

    def done(self, stage: str, key: str, result):
        files = {name: file_sha256(self.out / name) for name in _stage_files(stage, result, self.out)}
        self.state[stage] = {"key": key, "result": result, "files": files}
        self.save()
        return result

    def save(self) -> None:
        write_json(self.path, self.state)

    def _bring(self, stage: str, entry: dict) -> bool:
        """Copy the files of a finished stage from the previous folder; False when one is missing or differs."""
        if self.previous.resolve() == self.out.resolve():
            return True
        files = entry.get("files")
        if files is None:  # a stages.json from before the hashes: the files its result names, as they are
            files = dict.fromkeys(_stage_files(stage, entry["result"], self.previous))
        for name, digest in files.items():
            source = self.previous / name
            if not source.is_file() or (digest is not None and file_sha256(source) != digest):
                return False
        for name in files:
            (self.out / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(self.previous / name, self.out / name)
        return True


def _stage_files(stage: str, result: Any, folder: Path) -> list[str]:
    """The files (paths in the folder) a stage with ``result`` wrote there; ``physics.json`` is written
    from the identify stage's result on every run."""
    if not isinstance(result, dict):
        return []
    if stage == "residual":
        name = _model_file(result)
        names = [] if name == "physics.json" else [name, *([str(Path(name).with_suffix(".json"))]
                                                            if name.endswith(".pt") else [])]
    elif stage == "intervals":
        names = [result["intervals"]] if result.get("intervals") else []
    elif stage == "export":
        step = result.get("step") or "step.casadi"
        names = [step, step + ".json"]
        if result.get("c_code"):  # the C library (c/libstep.so): its folder's files
            c_dir = Path(result["c_code"]) if (folder / result["c_code"]).is_dir() else Path(result["c_code"]).parent
            if c_dir.parts:
                names += [p.relative_to(folder).as_posix() for p in sorted((folder / c_dir).rglob("*")) if p.is_file()]
    else:
        names = []
    return [n for n in names if (folder / n).is_file()]
