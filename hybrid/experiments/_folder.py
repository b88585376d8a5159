"""What every model folder shares: its result record, its stages' log, its exported step and its files."""

from __future__ import annotations

import contextlib
import sys
import time
from collections.abc import Callable, Sequence
from concurrent.futures import Future, wait
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hybrid.export._load import MODEL_DIR_MANIFEST, file_sha256
from physics.data import Trajectory

__all__ = ["FittedModelDir", "FORMAT", "MANIFEST", "STAGES"]

#: The folder's manifest: what ``hybrid.export.load(folder)`` opens.
MANIFEST = MODEL_DIR_MANIFEST
FORMAT = "hysteresis-hybrid/model-dir/1"
STAGES = ("physics", "identify", "residual", "intervals", "export", "card")

@dataclass
class FittedModelDir:
    """What :func:`fit_model_dir` wrote: the folder, the chosen physics and residual, per-run RMSEs."""

    path: Path
    spec: str
    residual: str
    model: Any
    rows: list[dict]
    seconds: dict[str, float]
    failures: list[str] = field(default_factory=list)
    #: Which physics was asked for and could not be fitted, why, and what was used instead (one line,
    #: :func:`identification.discovery.substitution`); "" when the physics asked for is the one used.
    substitution: str = field(default="", init=False)
    #: The measured input columns the model does not read: with them, no network beat the physics alone
    #: (or the peer) held out, so the folder reads and exports the command alone.
    dropped: list[str] = field(default_factory=list, init=False)
    reused: list[str] = field(default_factory=list)
    #: The warm-up window every row was scored after (samples).
    warmup: int = 0
    #: The conformal intervals (``intervals.json``) or None, and how they were calibrated (or why not).
    intervals: Any = None
    calibration: dict = field(default_factory=dict)
    #: ``(trajectory, model output, physics output)`` of each row, for the card's figures.
    predictions: list[tuple[Trajectory, np.ndarray, np.ndarray]] = field(default_factory=list, repr=False)
    #: The output columns of a model of several (``Columns(output=(...))``; its rows one per run and output, its
    #: intervals one per output); () for a model of the runs' ``y``.
    outputs: tuple[str, ...] = field(default=(), init=False)
    #: A model of several outputs: the specs tried on the runs held out of their fits (each one's error, or why
    #: it has none) and the one kept, ``{"specs": {...}, "kept": spec}``; {} for a model of one output.
    tried: dict = field(default_factory=dict, init=False)


def _export(model, series, out: Path, warmup: int, intervals=None) -> tuple[dict, Future]:
    """The exported step saved in ``out``, and its C library compiling meanwhile: ``(entry, future)``, the
    future's result the library's path in the folder (None without a C compiler). The C compiler runs
    while the card is written (:func:`~identification._trace.in_background`: a traced task while tracing)."""
    from hybrid.export import export_model
    from hybrid.export._codegen import has_compiler
    from identification._trace import in_background

    exported = export_model(model, warmup=warmup or None, **({"symbolic": "MX"} if model is not series else {}))
    exported.dt = exported.dt or series.dt
    if intervals is not None:  # the interval of each step beside it (C symbol half_width)
        exported.half_width = intervals.function(dt=exported.dt)
        exported.meta["interval_level"] = intervals.level
    exported.save(out / "step.casadi")

    def compile_c() -> str | None:
        if not has_compiler():
            return None
        return str(Path(exported.codegen(out / "c")).resolve().relative_to(out.resolve()))

    entry = {"step": "step.casadi", "n_x": exported.n_x, "kind": exported.kind}
    return entry, in_background("compile C", compile_c)


@contextlib.contextmanager
def _while_compiling(exported):
    """The work inside runs while the C library of ``exported`` (:func:`_export`) compiles; an error, a
    Ctrl-C or a SIGTERM inside stops the compiler and waits for its thread (its scratch folder gone)
    before it goes on up."""
    try:
        yield
    except BaseException:
        if exported is not None:
            from physics.data.io import stop_compilers
            from physics.data._compiler import POLL_S

            compiling = exported[1]
            while not compiling.done():  # the compiler may not have started yet: stop it once it has
                try:
                    stop_compilers()
                    wait([compiling], timeout=POLL_S)
                except KeyboardInterrupt:  # a second press: it is being stopped already
                    continue
        raise


def _folder_files(folder: Path) -> dict[str, str]:
    """Every file of the new folder but the card (path in the folder -> SHA-256): the card's ``files``."""
    return {p.relative_to(folder).as_posix(): file_sha256(p) for p in sorted(folder.rglob("*"))
            if p.is_file() and p.name != MANIFEST}


class _Log:
    def __init__(self, progress: bool, stages: Sequence[str] = STAGES):
        self.progress, self.stages = progress, tuple(stages)

    def run(self, stage: str, work: Callable, result: FittedModelDir):
        if self.progress:
            print(f"[{self.stages.index(stage) + 1}/{len(self.stages)}] {stage} ...", file=sys.stderr, flush=True)
        from identification._trace import stage as traced

        t0 = time.perf_counter()
        with traced(stage):
            out = work()
        result.seconds[stage] = round(time.perf_counter() - t0, 2)
        if self.progress:
            print(f"      {stage} done in {result.seconds[stage]:.1f} s", file=sys.stderr, flush=True)
        return out
