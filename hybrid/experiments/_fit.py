"""From measured runs to a model a controller can use, in one call: ``fit_model_dir``.

The model folder is one unit: it is written in a staging folder beside ``out`` and swapped in whole
when its ``card.json`` (every file's SHA-256) is written, so an interrupted fit leaves the previous
folder as it was. Each stage is recorded in ``stages.json`` with a key of its inputs and the digests
of its files, so ``resume=True`` reuses the finished ones:

1. ``physics``: the physics spec, given or chosen for extrapolation (``physics="auto"``:
   :func:`identification.discovery.select_physics` grows it a block at a time, keeping a block
   only where it beats the spec held on folds of runs left out of the fit, and a linear ARX scored
   on the same folds, which becomes the model where it beats every spec);
2. ``identify``: its parameters (IPOPT, each run's state from its warm-up window as the card scores
   it) with standard errors -> ``physics.json``; a spec that does not fit falls back to simpler
   ones, and the failures are recorded;
3. ``residual``: the residual network (``fnn``, ``fnn-hib``, ``lstm``, ``none`` or ``auto``: each
   candidate trained without one run in three, or on each of fewer than three runs before its last
   branch, and the best on those kept, physics alone included) -> ``model.pt`` (a peer: ``peer.json``);
4. ``intervals``: conformal intervals from the held-out runs or branches -> ``intervals.json``;
5. ``export``: the model as one CasADi step -> ``step.casadi`` (and C code where gcc is);
6. ``card``: ``report.md`` and its figures (:mod:`._card`), then ``card.json``.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from physics import Series
from physics.data import DataError, Trajectory, check_warmup_length, rmse, warmup_split
from physics.data.io import atomic_folder, write_json

from hybrid.export._load import MODEL_DIR_STAGES
# Residual choices (live): ``auto``, ``none`` and the registered networks; ``auto`` compares those that
# declare ``auto_residual`` (AUTO_CANDIDATES) with the physics alone.
from hybrid.networks import ALONE, AUTO_RESIDUALS as AUTO_CANDIDATES, RESIDUALS
from identification.discovery import FALLBACK, PhysicsPolicy  # the policy's simpler specs, in order
from hybrid.intervals import condition_folds, run_conditions

from ._card import short_name, substitution_line, write_card
from ._folder import FORMAT, MANIFEST, STAGES, FittedModelDir, _export, _folder_files, _Log, _while_compiling  # noqa: F401 (STAGES: benchmarks)
from ._split import PIECE_SAMPLES, RESIDUAL_RUNS, residual_split
from ._columns import Columns
from ._compare import WARMUP, _Physics
from ._presets import check_preset, folder_network, folder_training
from ._scoring import score_model
from ._stages import _data_key, _model_file, _Stages

__all__ = ["fit_model_dir", "FittedModelDir", "Columns", "RESIDUALS", "MANIFEST", "residual_split"]

#: Selection options that say where its fits run, not what it chooses: not part of the stage's key.
WHERE = ("workers", "n_jobs", "scheduler", "progress", "verbose")


def fit_model_dir(train: Sequence[Trajectory], out: str | Path, *, test: Sequence[Trajectory] = (),
                  physics: str | PhysicsPolicy = "auto", residual: str = "auto", preset: str = "quick",
                  seed: int = 0, warmup: int = WARMUP, columns: Columns | None = None, group: str | None = None,
                  resume: bool = False, progress: bool = True) -> FittedModelDir:
    """Fit physics and a residual network to ``train`` and write a model folder with its card.

    Parameters
    ----------
    train, test : sequences of Trajectory
        Training runs (one sample rate) and runs held out of every fit (reported apart).
    out : path
        The model folder (created).
    physics : str or PhysicsPolicy
        A spec (``"lag+backlash+linear"``) or ``"auto"`` (chosen by leaving whole runs out), falling back
        to :data:`~identification.discovery.FALLBACK` when it does not fit; or a
        :class:`~identification.PhysicsPolicy` naming a spec, specs tried in order or ``"auto"``, its
        ``fallback``, and the selection's ``select_options`` (``{"workers": Workers(n_jobs=4)}``: where its
        fold fits run and the residual's candidates train, and its ``device``: where the networks train;
        ``blocks``, ``settings``, ...).
    residual : {"auto", "none"} or a registered network's name (:data:`hybrid.networks.RESIDUALS`)
        With measured inputs (``columns.measured``), ``"none"`` (physics only) is refused: no physics block
        takes a second input, so the columns would be read and silently dropped. ``"auto"`` keeps them only where a
        network that reads them beats the physics alone (which ignores them) held out; where none does, the folder
        reads and exports the command alone and says so (``FittedModelDir.dropped``, the card, ``hyst fit``).
    preset : {"quick", "paper"}
        Training budget of the networks (``hyst compare``'s presets).
    resume : bool
        Reuse the stages already in ``out`` whose inputs are unchanged.
    warmup : int
        The protocol of the card and of the residual's choice: each run's first ``warmup`` measured
        samples set the model's state, the rest is scored (``score_model``); the export gets an
        ``init`` over windows of that many samples (0: from rest, no ``init``).
    columns : Columns, optional
        The CSV columns the runs were read from (kept in the folder's manifest so ``hyst predict`` reads
        new files with them unasked), and the measured inputs (``Columns.measured``: ``Trajectory.extra``
        columns, e.g. a motor current) the residual network reads beside the command and the physics'
        output; every run, train and test, must carry them, and the exported step's input is then
        ``[u, *measured]``. The runs' other extra columns (a simulator's states) are not read.
        With several output columns (``Columns(output=("Angle x", "Pos x", "Pos y"))``, the runs' ``y`` by its
        name and ``Trajectory.extra`` columns), e.g. the tip's angle and position: one chain of blocks, one
        state, a map per output (:mod:`._fit_outputs`), and a residual network of every output where one is asked
        for or, with ``auto``, beats the physics alone held out; intervals per output with their joint coverage, a
        linear ARX of all outputs on the card. Measured inputs are read by that network as with one output (kept only
        where it beats the physics alone held out); ``group`` leaves each condition out of a refit of the physics
        for its intervals; ``resume`` reuses the physics, the joint fit and the residual network.
    group : str, optional
        The runs' conditions for the intervals' folds (:func:`hybrid.intervals.run_conditions`): a meta
        key or a regular expression on the file names.
    """
    train, test = list(train), list(test)
    columns = Columns() if columns is None else columns
    if not isinstance(columns, Columns):
        raise DataError(f"columns must be a hybrid.experiments.Columns, e.g. Columns('time', 'u', 'y'). "
                        f"Got {type(columns).__name__} instead.")
    if columns.outputs:
        from ._fit_outputs import fit_outputs_dir

        policy = _policy(physics)
        measured = _check(train, test, residual, columns.measured)
        conditions = run_conditions(train, group)  # a bad group fails here, before any work
        check_preset(preset)
        workers = policy.select_options.get("workers")
        return fit_outputs_dir(train, out, columns.outputs, test=test, residual=residual, warmup=warmup,
                               physics=policy.physics, columns=columns.manifest(), workers=workers, measured=measured,
                               conditions=conditions, resume=resume, progress=progress, networks=(preset, seed, "cpu" if workers is None else workers.device))
    policy = _policy(physics)
    measured_inputs = _check(train, test, residual, columns.measured)
    train, test = _inputs_only(train, measured_inputs), _inputs_only(test, measured_inputs)
    warmup = check_warmup_length(warmup)
    conditions = run_conditions(train, group)  # a bad group fails here, before any work
    short = [t for t in [*train, *test] if t.n <= warmup]
    if short:
        raise DataError(f"A warm-up of {warmup} samples leaves nothing to score in run {short[0].source!r} "
                        f"({short[0].n} samples); give a shorter --warmup.")
    check_preset(preset)
    workers = policy.select_options.get("workers")
    device = "cpu" if workers is None else workers.device  # where the networks train (the folder's are on the CPU)
    out = Path(out)
    log = _Log(progress)
    result = FittedModelDir(out, "", "", None, [], {}, warmup=warmup)
    # the folder is one unit: written beside ``out`` and swapped in whole when the card is written, so an
    # interrupted fit leaves the previous folder as it was (atomic_folder); ``work`` is the new folder
    with atomic_folder(out, carry=_not_model_file) as work:
        stages = _Stages(work, resume, _data_key(train, test, seed, preset), previous=out)
        _fit_stages(train, test, policy, residual, (preset, seed, device), warmup, columns.manifest(), work,
                    stages, log, result, conditions)
    result.reused = stages.reused
    return result


def _fit_stages(train, test, policy, residual, networks: tuple, warmup, columns, out: Path,
                stages: "_Stages", log: "_Log", result: FittedModelDir, conditions=(None, "")) -> None:
    """The stages of :func:`fit_model_dir`, writing into ``out`` (the new folder), ``card.json`` last;
    ``networks`` the ``(preset, seed, device)`` the networks train with."""
    options = dict(policy.select_options)
    # a folder fitted before the physics policy keyed the spec string itself: the same key for the same inputs
    named = policy.physics if isinstance(policy.physics, str) else list(policy.physics)
    key = stages.key("physics", named, {k: v for k, v in options.items() if k not in WHERE}, warmup)
    spec_info = stages.reuse("physics", key) or stages.done("physics", key, log.run(
        "physics", lambda: _choose_physics(train, policy, {"verbose": log.progress, "progress": log.progress,
                                                           "warmup": warmup, **options}), result))
    result.spec = spec_info["spec"]

    key = stages.key("identify", key, warmup, *([] if policy.fallback == FALLBACK else [list(policy.fallback)]),
                     *([] if not policy.identify_options else [dict(policy.identify_options)]))
    fit = stages.reuse("identify", key) or stages.done("identify", key, log.run(
        "identify", lambda: _identify(train, spec_info, warmup, policy), result))
    result.failures = list(fit.get("failures", []))
    result.substitution = substitution_line(fit, spec_info)
    series = Series.from_dict(fit["series"])
    result.spec = series.spec
    write_json(out / "physics.json", fit)

    # a GPU's numbers differ from the CPU's by rounding: a fit resumed on another device trains again
    key = stages.key("residual", key, residual, *([] if networks[2] == "cpu" else [networks[2]]))
    chosen = stages.reuse("residual", key)
    if chosen is None or (_model_file(chosen) != "physics.json" and not (out / _model_file(chosen)).is_file()):
        # a peer that beat the physics is the model, unless a network was asked for (it is trained on the physics)
        peer = (spec_info.get("selection") or {}).get("peer") if residual in ("auto", "none") else None
        chosen = stages.done("residual", key, log.run(
            "residual", lambda: _peer_model(train, peer, out) if peer else
            _residual(train, series, residual, networks, out, warmup, policy.select_options.get("workers")), result))
    result.residual = chosen["residual"]
    result.model = series if _model_file(chosen) == "physics.json" else _load(out / _model_file(chosen))
    if _model_file(chosen) != "model.pt" and train[0].extra:  # the measured inputs did not help held out
        result.dropped = list(train[0].extra)
        if columns and "input" in columns:  # predict reads the command alone, as the model does
            columns = {**columns, "input": columns["input"].split(",")[0]}

    key = stages.key("intervals", key, chosen["residual"], warmup, conditions[0], CALIBRATION_FORMAT)
    calibration = stages.reuse("intervals", key)
    if calibration is None or (calibration["intervals"] and not (out / "intervals.json").is_file()):
        calibration = stages.done("intervals", key, log.run(
            "intervals", lambda: _calibrate(train, series, spec_info, chosen, warmup, out, conditions), result))
    result.intervals = _intervals(out) if calibration["intervals"] else None
    result.calibration = calibration

    key = stages.key("export", key, warmup)
    exported = None
    if stages.reuse("export", key) is None or not (out / "step.casadi").is_file():
        exported = log.run("export", lambda: _export(result.model, series, out, warmup, result.intervals), result)

    with _while_compiling(exported):
        result.rows, result.predictions = _rows(result.model, series, train, test, warmup, result.intervals)
        stages.save()
        log.run("card", lambda: write_card(out, result, fit, spec_info, chosen), result)
        if exported is not None:  # the C library, compiled meanwhile (an interrupt while waiting stops it too)
            t0 = time.perf_counter()
            info, compiling = exported
            stages.done("export", key, {**info, "c_code": compiling.result()})
            result.seconds["export"] = round(result.seconds["export"] + time.perf_counter() - t0, 2)
    write_json(out / MANIFEST, {"format": FORMAT, "model": _model_file(chosen), "step": "step.casadi",
                                "spec": result.spec, "residual": result.residual, "peer": chosen.get("peer"),
                                "warmup": warmup,
                                "intervals": calibration["intervals"],
                                "rate_hz": round(1.0 / series.dt, 9) if series.dt else None,
                                **({"columns": dict(columns)} if columns else {}), "rows": result.rows,
                                "failures": result.failures,
                                "seconds": result.seconds, "files": _folder_files(out)})  # last


# ---------------------------------------------------------------------------- stages
def _policy(physics) -> PhysicsPolicy:
    """The folder's physics policy: a spec or ``auto`` falls back to :data:`FALLBACK`; a policy names
    ``auto``, a spec or specs tried in order (a model given as fitted has no place in a folder's stages)."""
    policy = physics if isinstance(physics, PhysicsPolicy) else PhysicsPolicy(physics, fallback=FALLBACK)
    named = [policy.physics] if isinstance(policy.physics, str) else policy.physics
    if not (isinstance(named, (list, tuple)) and named and all(isinstance(s, str) for s in named)):
        raise DataError(f"physics must be 'auto', a spec such as 'lag+backlash+linear', or a PhysicsPolicy naming "
                        f"them; got {policy.physics!r}.")
    for spec in named if not policy.auto else []:
        Series.from_spec(spec)  # a misspelt spec fails here, before any work
    return policy


def _choose_physics(train, policy: PhysicsPolicy, options: dict) -> dict:
    if not policy.auto:
        ranked = [policy.physics] if isinstance(policy.physics, str) else list(policy.physics)
        return {"spec": ranked[0], "how": "given", "ranked": ranked}
    from identification.discovery import select_physics

    selection = select_physics(train, **{"peers": _selection_peers(), **options})
    return {"spec": selection.spec, "how": "selection", "ranked": selection.ranked(),
            "selection": selection.to_dict(), "summary": selection.table(),
            "guesses": selection.fold_parameters}


def _identify(train, spec_info: dict, warmup: int, policy: PhysicsPolicy) -> dict:
    """The first spec of the ranked candidates (then the policy's ``fallback``) that fits all training runs,
    each run's state set by its first ``warmup`` samples as the card scores it (``identify(..., warmup=)``).
    The policy's report (what was tried, why each failed, how the spec was reached) is kept for the card;
    a ranking that came from the selection (the ``physics`` stage) reports its first spec as ``selection``."""
    from dataclasses import replace

    from identification import IdentificationError, fit_physics

    ranked = replace(policy.scored_after(warmup), physics=list(spec_info["ranked"]))
    try:
        _, fit, report = fit_physics(ranked, train, guesses=spec_info.get("guesses", {}))
    except IdentificationError as exc:
        raise DataError(str(exc)) from None
    if spec_info["how"] == "selection" and report.how == "first":
        report = replace(report, how="selection")
    return {**fit.to_dict(), "failures": [f"'{k}': {v}" for k, v in report.failed.items()],
            "physics_report": report.to_dict()}


def _hybrid(series, name: str, networks: tuple):
    """A residual candidate on ``series``: its ``fit(runs)`` returns the fitted HybridModel whose network
    reads the command, the physics' output and every measured input the runs carry (their
    ``Trajectory.extra``, cut to ``measured_inputs`` by :func:`fit_model_dir`), so its exported step takes
    ``[u, *measured_inputs]``. The features are the runs' columns, known only when it is fitted."""
    from types import SimpleNamespace

    from hybrid.models import HybridModel
    from hybrid.models._hybrid import BUILTIN_FEATURES

    training = folder_training(name, networks)

    def fit(runs):
        runs = list(runs)
        return HybridModel(physics=series, residual=folder_network(name), features=(*BUILTIN_FEATURES, *runs[0].extra),
                           training=training).fit(runs)

    return SimpleNamespace(fit=fit)


def _candidate(series, name: str, networks: tuple):
    """A residual stage's candidate: the hybrid on ``series`` (:func:`_hybrid`), or with :data:`ALONE`
    the network alone (a ``LearnedModel`` reading the command and every measured input)."""
    if not name.endswith(ALONE):
        return _hybrid(series, name, networks)
    from types import SimpleNamespace

    from hybrid.learning import LearnedModel

    network = name[: -len(ALONE)]
    training = folder_training(network, networks)

    def fit(runs):
        runs = list(runs)
        return LearnedModel(folder_network(network), "forward", features=tuple(runs[0].extra), training=training).fit(runs)

    return SimpleNamespace(fit=fit)


def _selection_peers() -> dict:
    """The peers the physics selection scores on its own folds: the one with the lowest held-out error,
    where that is lower than the chosen spec's, becomes the model (:func:`_peer_model`)."""
    from functools import partial

    from hybrid.peers import LinearARX

    # the simplest honest models: a linear ARX, and a static line y = a u + b (an ARX with no dynamics)
    return {"linear ARX": LinearARX, "static line": partial(LinearARX, na=0, nb=1, nk=0)}


def _peer_model(train, peer: str, out: Path) -> dict:
    """The peer that beat the physics held out, fitted on every training run and saved as the model
    (exported and used like any other; no residual is trained on it)."""
    model = _selection_peers()[peer]().fit(train)
    model.save(out / PEER_FILE)
    return {"residual": "none", "peer": peer, "model": PEER_FILE, "validation_rmse": {}, "held_out_runs": [],
            "held_out_predictions": [],
            "how": f"the peer {peer} beat every physics spec on the selection's held-out folds"}


#: The file of a peer chosen as the model.
PEER_FILE = "peer.json"

def _residual(train, series, residual: str, networks: tuple, out: Path, warmup: int, workers=None) -> dict:
    """The residual (chosen on runs or pieces held out of its candidates' fits when ``auto``,
    :func:`residual_split`) and, for the intervals, the held-out model's predictions on them (a
    given residual is fitted once more without them for this). The candidates train at once on
    ``workers`` (the selection's :class:`~identification.discovery.Workers`), each a function of plain
    data: the same numbers in any process (a network registered by the user's own code trains here,
    one after another: a new worker process does not know it)."""
    from identification.discovery import make_pool

    scores: dict[str, float] = {}
    names = tuple(AUTO_CANDIDATES) if residual == "auto" else () if residual == "none" else (residual,)
    if residual == "auto":  # a network whose history is longer than a run cannot be fitted on it: no candidate
        shortest = min(t.n for t in train)
        names = tuple(n for n in names if folder_network(n).history <= shortest)
        if not names and train[0].extra:
            raise DataError(f"--residual auto: the shortest training run has {shortest} samples, fewer than the "
                            f"history every network reads ({', '.join(f'{n} {folder_network(n).history}' for n in AUTO_CANDIDATES)}"
                            "); give longer runs, or --residual fnn.")
    min_piece = max([PIECE_SAMPLES, *(folder_network(n).history for n in names)])  # a network trains on pieces this long
    fit_on, held, how = residual_split(train, warmup, min_piece)
    check = held or train
    candidates = ((*names, *(n + ALONE for n in names)) if residual == "auto"  # the networks alone: where the
                  else () if residual == "none" else (residual,))               # physics misleads the residual
    predictions: dict[str, list] = {}
    if candidates:
        # a network registered by the user's own code (not this package's) is unknown in a new worker process
        ours = all(type(folder_network(n.removesuffix(ALONE))).__module__.startswith("hybrid.") for n in candidates)
        pool = make_pool(workers if ours else None)
        futures = {name: pool.submit(_held_out_fit, series.to_dict(), name, networks, fit_on, check, warmup)
                   for name in candidates}
        try:
            for name, future in futures.items():  # in order, whatever order they finish in
                scores[name], predictions[name] = future.result()
        except BaseException:
            pool.abort(list(futures.values()))
            raise
        finally:
            pool.close()
    if residual == "auto":  # with measured inputs, "none" ignores them: kept only where reading them helps
        scores = {"none": _pooled(_Physics(series, "forward", check), check, warmup), **scores}
        residual = min(scores, key=scores.get)
    else:
        scores = {}
    if residual != "none":
        _candidate(series, residual, networks).fit(train).save(out / "model.pt")
    return {"residual": residual, "validation_rmse": scores, "how": how, "min_piece": min_piece,
            "held_out_runs": [t.source for t in held],
            "held_out_predictions": predictions[residual] if held and residual != "none" else []}


def _held_out_fit(series: dict, name: str, networks: tuple, fit_on: list, check: list, warmup: int):
    """A residual candidate fitted on ``fit_on``: its pooled RMSE on ``check`` (as :func:`_pooled` scores
    it) and its predictions of each of those runs after its warm-up window (a worker's task: plain data
    in, plain numbers out)."""
    from hybrid.intervals import predict_with
    from hybrid.learning._learned import _threads

    with _threads(1):
        model = _candidate(Series.from_dict(series), name, networks).fit(fit_on)
        measured, predictions = [], []
        for t in check:
            window, rest = warmup_split(t, warmup)
            measured.append(rest.y)
            predictions.append(predict_with(model, rest, window))
        return rmse(np.concatenate(measured), np.concatenate(predictions)), [p.tolist() for p in predictions]


#: Bumped when the intervals stage computes something new from the same inputs (a resumed fit redoes it).
CALIBRATION_FORMAT = 4  # 4: each held-out run's distance beyond its model's runs (reaches)


def _calibrate(train, series, spec_info: dict, chosen: dict, warmup: int, out: Path, conditions=(None, "")) -> dict:
    """Conformal intervals (``intervals.json``) from predictions of runs held out of a fit: the
    physics selection's folds for a physics-only model (refitted when the spec was given, or leaving
    one whole condition out where the runs carry conditions), the peer refitted the same way, the
    residual stage's held-out model for a hybrid. Too few held-out runs: no intervals, and why."""
    from hybrid.intervals import ConformalIntervals, HeldOut

    labels, how = conditions
    if chosen.get("peer"):
        held = _peer_held_out(train, chosen["peer"], warmup, labels)
        source = f"the peer {chosen['peer']} refitted without each fold"
    elif chosen["residual"] == "none":
        held = _physics_held_out(train, series, spec_info, warmup, labels)
        source = "the physics refitted without each fold"
    else:
        trained_on, check, split_how = residual_split(train, warmup, chosen.get("min_piece"))
        pieces = len(train) < RESIDUAL_RUNS
        held = [HeldOut(warmup_split(t, warmup)[1], np.asarray(p, dtype=float), trained_on, piece=pieces)
                for t, p in zip(check, chosen.get("held_out_predictions", []))]
        source, labels = f"the hybrid's held-out fit ({split_how})", None
        if conditions[0] is not None:
            source += "; the conditions were not left out whole (the network would be retrained per condition)"
    try:
        intervals = ConformalIntervals().fit(train, held)
        q = intervals.quantile()
    except DataError as exc:
        return {"intervals": None, "why": str(exc)}
    write_json(out / "intervals.json", intervals.to_dict())
    report = intervals.report()
    return {"intervals": "intervals.json", "level": intervals.level, "held_out_runs": intervals.runs_,
            "half_width": q, "source": source, "conditions": how if labels is not None else "none (each run its own)",
            "report": report.to_dict()}


def _holdout(train, warmup: int, labels=None):
    """The folds a model refitted for the intervals is held out on, as the selection's: whole runs (a whole
    condition where ``labels`` names them), or one run's later branches (None: too short to hold out)."""
    from identification import IdentificationError
    from identification.discovery import Holdout, holdout

    if labels is not None and len(train) > 1:
        folds = condition_folds(labels)
        return Holdout(list(train), [[i for i in range(len(train)) if i not in f] for f in folds], folds,
                       "leave-one-condition-out")
    try:
        return holdout(train, warmup)
    except IdentificationError:
        return None


def _peer_held_out(train, peer: str, warmup: int, labels=None) -> list:
    """The peer refitted on each fold's runs (one run: the run before each held-out branch; a whole
    condition left out where ``labels`` names them) predicts the runs it holds out, as the selection did."""
    from dataclasses import replace

    from hybrid.intervals import held_out_predictions

    folds = _holdout(train, warmup, labels)
    if folds is None:
        return []
    models = [_selection_peers()[peer]().fit(folds.split(k)[0]) for k in range(len(folds.held))]
    held = held_out_predictions(models, folds.held, folds.runs, warmup, fits=folds.fit)
    index = [i for fold in folds.held for i in fold]
    return [replace(h, condition=None if labels is None or folds.pieces else labels[i], piece=folds.pieces)
            for h, i in zip(held, index)]


def _physics_held_out(train, series, spec_info: dict, warmup: int, labels=None) -> list:
    """The chosen spec fitted on each fold's runs predicts those it holds out: with the selection's own fold
    parameters where it made them for this spec on the same folds, else fitted again (:func:`_holdout`)."""
    from hybrid.intervals import HeldOut
    from identification import IdentificationError, fitted_series
    from identification.discovery import CV_IDENTIFY

    folds = _holdout(train, warmup, labels)
    if folds is None:  # too short to hold out: no held-out predictions, no intervals
        return []
    names = [str(t.source or f"run{i}") for i, t in enumerate(folds.runs)]
    held_named = [[names[i] for i in f] for f in folds.held]
    fold_params = (spec_info.get("guesses") or {}).get(series.spec) or []
    same = (len(set(names)) == len(names) and held_named == (spec_info.get("selection") or {}).get("folds")
            and len(fold_params) == len(folds.held) > 1)
    held = []
    for k, fold in enumerate(folds.held):
        trained_on = folds.split(k)[0]
        if same:
            model = Series.from_dict(series.to_dict()).set_params(**fold_params[k])
        else:
            try:
                model, _ = fitted_series(series.spec, trained_on, series.dt, CV_IDENTIFY)
            except IdentificationError:
                continue
        for i in fold:
            window, rest = warmup_split(folds.runs[i], warmup)
            held.append(HeldOut(rest, np.asarray(model.simulate(rest.u, warmup=window), dtype=float), trained_on,
                                condition=None if labels is None or folds.pieces else labels[i], piece=folds.pieces))
    return held


def _intervals(out: Path):
    from hybrid.intervals import ConformalIntervals
    from physics.data.io import read_json

    return ConformalIntervals.from_dict(read_json(out / "intervals.json", "intervals"))


def _load(path: Path):
    from hybrid.export import load

    return load(path)


# --------------------------------------------------------------------------- results
def _pooled(model, runs, warmup: int) -> float:
    return score_model(model, runs, warmup=warmup)[-1].rmse



def _rows(model, series, train, test, warmup: int, intervals=None) -> tuple[list[dict], list]:
    """Per run: the physics', the model's and a linear ARX's (the peer, fitted on the same runs) RMSE
    after the warm-up window, and the predictions (the run after its window, the model's output, the
    physics' output and the model's :class:`~hybrid.intervals.Interval` or None). With intervals, each
    row also gives their coverage, mean width (``hi - lo``) and the share of samples outside the data."""
    from hybrid.intervals import coverage

    from hybrid.peers import LinearARX

    rows, predictions = [], []
    physics, peer = _Physics(series, "forward", train), LinearARX().fit(train)  # the baseline a reader would try first
    for part, runs in (("train", train), ("test", test)):
        for t in runs:
            window, rest = warmup_split(t, warmup)
            kwargs = {} if window is None else {"warmup": window}
            y_phys = physics.predict(rest, **kwargs)
            y = y_phys if model is series else model.predict(rest, **kwargs)
            rows.append({"run": short_name(t.source), "set": part, "samples": rest.n, "physics_rmse": rmse(rest.y, y_phys),
                         "model_rmse": rmse(rest.y, y), "arx_rmse": rmse(rest.y, peer.predict(rest, **kwargs))})
            band = None if intervals is None else intervals.interval(y, rest.u, rest.dt)
            if band is not None:
                rows[-1].update(coverage=coverage(rest.y, band.lo, band.hi), width=float(np.mean(band.hi - band.lo)),
                                outside=float(np.mean(band.outside)), run_outside=intervals.run_outside(rest.u, rest.dt))
            predictions.append((rest, y, y_phys, band))
    return rows, predictions


def _check(train, test, residual, measured: tuple[str, ...] = ()) -> tuple[str, ...]:
    """Refuse what the fit cannot do before any work; returns the measured inputs (``Columns.measured``)."""
    if not train:
        raise DataError("fit needs at least one training run; got none.")
    if residual not in RESIDUALS:
        raise DataError(f"unknown residual {residual!r}. Must be one of {list(RESIDUALS)}.")
    check_measured(residual, measured)
    for t in [*train, *test]:
        missing = [m for m in measured if m not in t.extra]
        if missing:
            raise DataError(f"run {short_name(t.source)!r} has no measured input {missing[0]!r} (its extra columns: "
                            f"{sorted(t.extra)}); every run, train and test, must carry {list(measured)}.")
    dts = {round(t.dt, 12) for t in [*train, *test]}
    if len(dts) != 1:
        raise DataError(f"all runs must share one sample rate; got steps {sorted(dts)} s. Resample them first.")
    return measured


def check_measured(residual: str, measured: Sequence[str]) -> None:
    """Refuse a physics-only model (``residual="none"``) with measured inputs: no physics block takes a
    second input, so the columns would be read and silently dropped."""
    if residual == "none" and measured:
        raise DataError(f"residual 'none' (physics only) cannot use the measured input column(s) "
                        f"{', '.join(map(repr, measured))}: no physics block takes a second input. Drop them from "
                        "the inputs (hyst fit --input), or fit a residual network that reads them "
                        "(--residual auto, fnn, fnn-hib or lstm).")


def _inputs_only(runs, measured: Sequence[str]) -> list:
    """The runs with ``extra`` cut to the measured inputs: what every stage and the network see."""
    from dataclasses import replace

    return [t if list(t.extra) == list(measured) else replace(t, extra={m: t.extra[m] for m in measured})
            for t in runs]


#: What a fit writes into its folder besides the files its card lists: an older folder's copies are not
#: carried into the new one (:func:`_not_model_file`).
FOLDER_FILES = ("physics.json", "model.pt", "model.json", PEER_FILE, "intervals.json", "step.casadi",
                "step.casadi.json", "c", "report.md", "loops.png", "residual.png", MODEL_DIR_STAGES, MANIFEST)


def _not_model_file(name: str) -> bool:
    """An entry of the old folder the new one keeps: one someone else put there, not a model file nor a
    half-written one (``.NAME.*.tmp``)."""
    return name not in FOLDER_FILES and not (name.startswith(".") and name.endswith((".tmp", ".bak")))


