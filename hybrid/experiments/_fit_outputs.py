"""A model folder of several outputs (the tip's pose): ``fit_model_dir(..., columns=Columns(output=(...)))``.

One hysteretic chain keeps one state for the tendon and every output reads its signal through its own map
(:func:`identification.identify_outputs`). The folder holds what a folder of one output holds, per output:

1. ``physics``: the spec given, or the one the selection chooses for the first output (its chain; the
   spec's last ``linear`` becomes a cubic map per output);
2. ``identify``: the joint fit -> ``physics.json`` (a fit of several outputs, as ``hyst identify`` writes);
   meanwhile (on the selection's workers) the same spec is fitted without every third run, or without each
   run's last branch, for the intervals;
3. ``residual``: a residual network of every output on that physics (``HybridModel(outputs=...)``: one unit per
   output, fed every physics output) -> ``model.pt``; ``auto`` trains each candidate (the networks on the
   physics, and alone) without every third run, or before each run's last branch, and keeps the one whose
   held-out error (each output's mean square over its spread, averaged) is lowest, the physics alone included;
4. ``intervals``: conformal intervals calibrated per output on the held-out predictions of the model kept ->
   ``intervals.json``; how often every output is inside its interval at once (joint coverage) is reported
   beside them;
5. ``export``: the step of every output -> ``step.casadi`` (and C code where gcc is);
6. ``card``: ``report.md`` with per-output rows beside a linear ARX of all outputs at once, and
   ``loops.png``, then ``card.json``.

With ``resume``, the physics, identify and residual stages are reused where their inputs are unchanged
(``stages.json``, as in a folder of one output); the intervals, the export and the card are made again.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from physics import Series
from physics.data import DataError, Trajectory, check_warmup_length, rmse, warmup_split
from physics.data.io import atomic_folder, atomic_path, write_json
from hybrid.networks import ALONE

from ._card import _label, _plt, _protocol, _save, pooled, short_name
from ._folder import FORMAT, MANIFEST, FittedModelDir, _export, _folder_files, _Log, _while_compiling
from ._split import PIECE_SAMPLES, RESIDUAL_RUNS, residual_split
from ._stages import _data_key, _Stages

__all__ = ["fit_outputs_dir", "summary", "outputs_physics", "predict_after", "check_runs"]

STAGES = ("physics", "identify", "residual", "intervals", "export", "card")
#: Another spec (the arc) replaces the maps only where its held-out error's root is lower by more than this share:
#: the margin the selection keeps a block by (``SelectionSettings().margin``).
MARGIN = 0.03


def fit_outputs_dir(train, out, outputs, *, test=(), physics="auto", residual="auto", warmup: int = 10,
                    columns=None, workers=None, progress: bool = True, networks: tuple = ("quick", 0, "cpu"),
                    measured: tuple = (), conditions: tuple = (None, ""), resume: bool = False):
    """The model folder of ``outputs`` (see the module docstring); called by
    :func:`~hybrid.experiments.fit_model_dir` with ``outputs``. Returns its
    :class:`~hybrid.experiments.FittedModelDir` (``rows``: one per run and output). ``networks``: the
    ``(preset, seed, device)`` the residual's networks train with; ``measured``: the ``Trajectory.extra`` columns
    (a motor current) the residual network reads beside the command, checked by ``fit_model_dir``: the chain
    ignores them, so ``auto`` keeps them only where a network that reads them beats the physics alone held out
    (``FittedModelDir.dropped`` where none does), and the exported step of a network takes ``[u, *measured]``;
    ``conditions``: ``(labels, how)`` of :func:`hybrid.intervals.run_conditions`, each condition left out whole of a
    refit of the physics for the intervals (:func:`_condition_held_out`); ``resume``: reuse the stages of the folder
    already at ``out`` whose inputs are unchanged (the physics, the joint fit, the residual network), as
    ``fit_model_dir(..., resume=True)`` does for one output."""
    from hybrid.networks import RESIDUALS

    outputs = tuple(outputs)
    train, test = list(train), list(test)
    if not train:
        raise DataError("fit needs at least one training run; got none.")
    if residual not in RESIDUALS:
        raise DataError(f"unknown residual {residual!r}. Must be one of {list(RESIDUALS)}.")
    if not isinstance(physics, str):
        raise DataError(f"physics must be 'auto' or one spec for a model of several outputs; got {physics!r}.")
    if physics != "auto":
        Series.from_spec(physics)  # a misspelt spec fails here, before any work
    warmup = check_warmup_length(warmup)
    check_runs(train, test, outputs, warmup)
    if len({round(t.dt, 12) for t in [*train, *test]}) != 1:
        raise DataError("all runs must share one sample rate; resample them first.")

    out = Path(out)
    log = _Log(progress, STAGES)
    result = FittedModelDir(out, "", "none", None, [], {}, warmup=warmup)
    result.outputs = outputs
    dt = train[0].dt
    with atomic_folder(out) as work:
        # the stages as a folder of one output keeps them (stages.json): with ``resume`` each is reused where its
        # inputs are unchanged, the physics' selection, the joint fit and the residual network with what they held out
        stages = _Stages(work, resume, _data_key(train, test, networks[1], networks[0]), previous=out)
        key = stages.key("physics", physics, "outputs", list(outputs), warmup)
        selection = None if physics != "auto" else SimpleNamespace(**(stages.reuse("physics", key) or stages.done(
            "physics", key, log.run("physics", lambda: _selection_record(_select(train, outputs, warmup, workers)),
                                    result))))
        chosen = physics if selection is None else selection.spec
        specs = candidates(chosen, outputs, given=selection is None)
        key = stages.key("identify", key, specs)
        record = stages.reuse("identify", key)
        if record is None:
            fit, held, tried = log.run("identify", lambda: _identify(specs, dt, train, outputs, warmup, workers), result)
            record = stages.done("identify", key, {
                **_fit_json(fit, chosen, "selection" if physics == "auto" else "given", tried),
                "held_out": _predictions(held[0])})
        fit, held, tried = _fit_of(record, train, warmup)
        series = fit.series
        result.spec, result.model, result.tried = series.spec, series, tried
        write_json(work / "physics.json", {k: v for k, v in record.items() if k != "held_out"})
        key = stages.key("residual", key, residual, list(measured), *([] if networks[2] == "cpu" else [networks[2]]))
        record = stages.reuse("residual", key)
        if record is None:
            choice, model, model_held = log.run(
                "residual", lambda: _residual(series, outputs, train, residual, networks, warmup, workers, measured),
                result)
            if model is not None:
                model.save(work / "model.pt")
            record = stages.done("residual", key, {"residual": choice["residual"], "choice": choice,
                                                   "held_out": _predictions(model_held[0] if model_held else [])})
        chosen_residual, model, model_held = _residual_of(record, work, train, warmup)
        stages.save()  # every stage kept, those reused too
        result.residual = chosen_residual["residual"]
        result.reused = stages.reused
        if model is None and measured:  # the physics alone, which ignores them, did better held out
            result.dropped = list(measured)
        if model is not None:
            result.model = model

        def calibrate():
            labels, by = conditions
            if model is not None:  # the hybrid's own held-out fit
                held_out, pieces, how = model_held
                if labels is not None:
                    how += "; the conditions were not left out whole (the network would be retrained per condition)"
                return _calibrate(train, outputs, held_out, pieces, how, warmup, None if labels is None else by)
            if labels is not None:  # each condition left out whole of a refit of the physics
                return _calibrate(train, outputs, *_condition_held_out(tried["kept"], train, outputs, warmup, workers,
                                                                      labels), warmup, by)
            # the selection's own folds (each run left out of the chain's fit, the maps refitted without it) where
            # the maps were kept: as many held-out runs as there are runs, at no refit of the whole model
            folds = _fold_held_out(chosen, selection, train, outputs, warmup) if tried["kept"] == specs[0] else None
            return _calibrate(train, outputs, *(held if folds is None else folds), warmup)

        intervals, calibration = log.run("intervals", calibrate, result)
        if intervals:
            from hybrid.intervals import per_output_to_dict

            write_json(work / "intervals.json", per_output_to_dict(intervals))
        result.intervals, result.calibration = intervals or None, calibration

        exported = log.run("export", lambda: _export(result.model, series, work, warmup), result)
        with _while_compiling(exported):
            result.rows, result.predictions = _rows(result.model, series, outputs, train, test, warmup, intervals)
            log.run("card", lambda: _write_card(work, result, fit, chosen, physics, calibration, tried,
                                                chosen_residual), result)
            t0 = time.perf_counter()
            c_code = exported[1].result()  # the C library, compiled meanwhile
            result.seconds["export"] = round(result.seconds["export"] + time.perf_counter() - t0, 2)
        write_json(work / MANIFEST, {
            "format": FORMAT, "model": "physics.json" if result.residual == "none" else "model.pt",
            "step": "step.casadi", "spec": result.spec, "residual": result.residual,
            "peer": None, "outputs": list(outputs), "warmup": warmup, "residual_choice": chosen_residual,
            "intervals": "intervals.json" if intervals else None, "rate_hz": round(1.0 / dt, 9),
            **({"columns": columns} if columns else {}), "rows": result.rows, "failures": [],
            "held_out_rmse": calibration.get("held_out_rmse"), "c_code": c_code, "seconds": result.seconds,
            "files": _folder_files(work)})  # last
    return result


def _selection_record(selection) -> dict:
    """What the folder reads of the selection, as ``stages.json`` keeps it: the spec chosen, and the folds and their
    fits that calibrate the intervals (:func:`_fold_held_out`)."""
    return {"spec": selection.spec, "ranked": list(selection.ranked()), "rate_hz": selection.rate_hz,
            "folds": [list(f) for f in selection.folds],
            "fold_parameters": selection.fold_parameters}


def _predictions(held: list) -> list:
    """The held-out predictions of ``held`` (``(run, prediction or why there is none, trained_on)`` each) as
    ``stages.json`` keeps them; the runs are :func:`residual_split`'s, found again from the training runs."""
    return [p if isinstance(p, str) else np.asarray(p, dtype=float).tolist() for _, p, _ in held]


def _held_again(predictions: list, train, warmup: int, min_piece: int | None = None) -> list:
    """``(run, prediction, trained_on)`` per held-out run: ``predictions`` beside the runs :func:`residual_split`
    holds out (the same split the stage made: it depends on the training runs alone)."""
    fit_on, held, _ = residual_split(train, warmup, *([] if min_piece is None else [min_piece]))
    return [(t, p if isinstance(p, str) else np.asarray(p, dtype=float), fit_on) for t, p in zip(held, predictions)]


def _fit_of(record: dict, train, warmup: int):
    """``(fit, held, tried)`` of the identify stage from its record: the joint fit as ``physics.json`` holds it,
    and (``held_out``) the runs held out of the specs' fits with the kept spec's predictions of them."""
    fit = record
    tried = fit["tried"]
    fitted = SimpleNamespace(series=Series.from_dict(fit["series"]), parameters=fit["parameters"],
                             standard_errors=fit["standard_errors"], status=fit["status"],
                             iterations=fit["iterations"])
    _, _, how = residual_split(train, warmup)
    held = (_held_again(record["held_out"], train, warmup), len(train) < RESIDUAL_RUNS,
            f"the physics refitted without them ({how})")
    return fitted, held, tried


def _residual_of(record: dict, folder: Path, train, warmup: int):
    """``(choice, model, held)`` of the residual stage from its record: the network kept, loaded from ``folder``
    (None: the physics alone), and its held-out predictions beside the runs it was scored on."""
    choice = record["choice"]
    kept = choice["residual"]
    if kept == "none":
        return choice, None, None
    from hybrid.learning import LearnedModel
    from hybrid.models import HybridModel

    model = (LearnedModel if kept.endswith(ALONE) else HybridModel).load(folder / "model.pt")
    held = _held_again(record["held_out"], train, warmup, choice["min_piece"])
    return choice, model, (held, len(train) < RESIDUAL_RUNS, f"the hybrid's held-out fit ({choice['how']})")


def outputs_physics(chain: str, train, outputs, *, warmup: int = 10, workers=None, how: str = "given",
                    chain_options: dict | None = None):
    """The model of several ``outputs`` read from ``chain``, a spec chosen for the first output (by the selection,
    or by :func:`identification.discovery.discover`): a cubic map per output and, for three outputs, the same
    chain read by a constant-curvature arc, the arc kept where it is lower held out by more than :data:`MARGIN`
    (:func:`candidates`, as ``hyst fit --output A,B,C`` chooses). Returns ``(fit, tried, record)``: the
    :func:`identification.identify_outputs` fit on every run, ``{"specs": each one's held-out error or why
    it has none, "kept": the spec kept}``, and the fit as ``hyst identify --output A,B,...`` writes it (its
    chain reached by ``how``), which ``hyst predict``, ``export`` and ``mpc`` read. ``chain_options``: how the chain
    is fitted (:func:`identification.identify_outputs`)."""
    Series.from_spec(chain)  # a misspelt spec fails here
    outputs = tuple(outputs)
    fit, _, tried = _identify(candidates(chain, outputs, given=False), train[0].dt, list(train), outputs,
                              check_warmup_length(warmup), workers, chain_options)
    return fit, tried, _fit_json(fit, chain, how, tried)


# ---------------------------------------------------------------------------- stages
def check_runs(train, others, outputs, warmup: int) -> None:
    """Refuse, before any work, a run (training or ``others``) too short for its ``warmup`` window or without one of
    the ``outputs`` (missing, or a copy of the input), and an output that does not move in any training run:
    nothing of its map can be identified."""
    from identification import output_columns
    from physics.data import is_constant

    measured = []
    for t in [*train, *others]:
        if t.n <= warmup:
            raise DataError(f"A warm-up of {warmup} samples leaves nothing to score in run {t.source!r} ({t.n} samples); "
                            "give a shorter --warmup.")
        measured.append(output_columns(t, outputs, error=DataError))
    measured = np.vstack(measured[:len(train)])
    for j, name in enumerate(outputs):
        if is_constant(measured[:, j]):
            raise DataError(f"output {name!r} is constant ({measured[0, j]:g}) in every training run, so its map "
                            "cannot be identified; name an output that moves.")


def _select(train, outputs, warmup: int, workers):
    from identification.discovery import select_outputs

    return select_outputs(train, outputs, warmup=warmup, progress=False,
                          **({"workers": workers} if workers is not None else {}))


def candidates(spec: str, outputs, given: bool) -> list[str]:
    """The specs a folder of ``outputs`` tries: the one given; else the chain chosen for the first output with a
    cubic map per output and, for three outputs (the tip's angle, then its position in the bending plane), the
    same chain read by a constant-curvature arc (``+arc``), the better held out kept (:func:`_identify`)."""
    if given or len(outputs) != 3 or not spec.endswith("linear"):
        return [spec]
    return [spec, spec + "+arc"]


def _identify(specs: list[str], dt: float, train, outputs, warmup: int, workers, chain: dict | None = None):
    """The joint fit on every training run of the first of ``specs`` and, at once on ``workers``, each spec
    fitted without the runs (or branches) held out (:func:`~hybrid.experiments.residual_split`). The spec
    whose held-out error (each output's mean square over its spread, averaged) is lowest is kept, the first
    unless another's root is lower by more than :data:`MARGIN`, and fitted on every run if it is not the first: ``(fit, (held, pieces, how), tried)``, ``held``
    ``(run, prediction or why there is none, trained_on)`` per held-out run,
    ``tried``: ``{"specs": each spec's held-out error or why it has none, "kept": the spec kept}``; ``chain``: the
    chain's fit options (:func:`identification.identify_outputs`' ``chain_options``)."""
    from identification import IdentificationError, identify_outputs
    from identification.discovery import make_pool

    def fit_all(spec):
        return identify_outputs(Series.from_spec(spec, dt=dt), train, outputs, warmup=warmup, chain_options=chain)

    fit_on, held, how = residual_split(train, warmup)
    pool = make_pool(workers)
    futures = {s: pool.submit(_held_out_fit, s, dt, fit_on, held, tuple(outputs), warmup, chain) for s in specs} \
        if held else {}
    try:
        try:
            fits = {specs[0]: fit_all(specs[0])}
        except IdentificationError as exc:
            raise DataError(f"'{specs[0]}' could not be fitted to the outputs {', '.join(outputs)}: {exc}") from None
        predictions = {s: f.result() for s, f in futures.items()}
    except BaseException:
        pool.abort(list(futures.values()))
        raise
    finally:
        pool.close()
    spread = _spread(train, outputs, warmup)
    tried = {s: (p if isinstance(p, str) else _standardized(held, p, outputs, warmup, spread))
             for s, p in predictions.items()}
    scored = {s: v for s, v in tried.items() if not isinstance(v, str)}
    best = specs[0]
    if scored.get(best) is not None:  # another kept only where clearly lower, as the selection keeps a block
        for s in specs[1:]:
            if s in scored and math.sqrt(scored[s]) < (1 - MARGIN) * math.sqrt(scored[best]):
                best = s
    if best not in fits:
        try:
            fits[best] = fit_all(best)
        except IdentificationError as exc:  # held out it fitted, on every run not: the first is kept
            tried[best], best = f"did not fit every run: {exc}", specs[0]
    kept = predictions.get(best)
    held_info = [(t, kept if isinstance(kept, str) else kept[i], fit_on) for i, t in enumerate(held)]
    return (fits[best], (held_info, len(train) < RESIDUAL_RUNS, f"the physics refitted without them ({how})"),
            {"specs": tried, "kept": best})


def _residual(series, outputs, train, residual: str, networks: tuple, warmup: int, workers, measured: tuple = ()):
    """The residual stage: ``(choice, model, held)``, ``choice`` ``{"residual": name, "validation": each candidate's
    held-out error, "how": what was held out, "held_out_runs": ...}`` (the card's), ``model`` the hybrid (or the
    network alone) fitted on every run or None, ``held`` ``(held, pieces, how)`` of its held-out fit for the
    intervals. ``auto`` trains each candidate of :data:`~hybrid.networks.AUTO_RESIDUALS` (on
    ``series``, and alone) without the runs or branches :func:`residual_split` holds out, at once on
    ``workers``, and keeps the lowest held-out error (:func:`_standardized`), the physics alone (``none``)
    scored on the same runs; a named network is trained so, for the intervals, and on every run. Each network reads
    the ``measured`` inputs beside the command (the physics alone ignores them)."""
    from identification import output_columns, predict_outputs
    from identification.discovery import make_pool
    from hybrid.networks import AUTO_RESIDUALS

    from ._presets import folder_network

    if residual == "none":
        return {"residual": "none", "validation": {}}, None, None
    names = tuple(AUTO_RESIDUALS) if residual == "auto" else (residual,)
    if residual == "auto":  # a network whose history is longer than a run cannot be fitted on it: no candidate
        names = tuple(n for n in names if folder_network(n).history <= min(t.n for t in train))
    candidates = (*names, *(n + ALONE for n in names)) if residual == "auto" else names
    min_piece = max([PIECE_SAMPLES, *(folder_network(n.removesuffix(ALONE)).history for n in candidates)])
    fit_on, held, how = residual_split(train, warmup, min_piece)
    if not held and residual == "auto":
        return {"residual": "none", "validation": {}, "how": how, **({"measured": list(measured)} if measured else {})}, \
            None, None
    check = held or train
    spread = _spread(train, outputs, warmup)
    # a network registered by the user's own code (not this package's) is unknown in a new worker process
    ours = all(type(folder_network(n.removesuffix(ALONE))).__module__.startswith("hybrid.") for n in candidates)
    pool = make_pool(workers if ours else None)
    futures = {n: pool.submit(_residual_held_out, series.to_dict(), n, networks, tuple(outputs), fit_on, check, warmup,
                              tuple(measured)) for n in candidates}
    try:
        predictions = {n: f.result() for n, f in futures.items()}  # in order, whatever order they finish in
    except BaseException:
        pool.abort(list(futures.values()))
        raise
    finally:
        pool.close()
    scores = {n: _standardized(check, p, outputs, warmup, spread) for n, p in predictions.items()}
    if residual == "auto":
        physics = [predict_outputs(series, t.u, output_columns(t, outputs), warmup) for t in check]
        scores = {"none": _standardized(check, physics, outputs, warmup, spread), **scores}
    kept = min(scores, key=scores.get)
    choice = {"residual": kept, "validation": scores, "how": how, "held_out_runs": [str(t.source) for t in held],
              "min_piece": min_piece, **({"measured": list(measured)} if measured else {})}
    if kept == "none":
        return choice, None, None
    model = _residual_candidate(series, kept, networks, outputs, measured).fit(train)
    held_info = [(t, np.asarray(p), fit_on) for t, p in zip(held, predictions[kept])]
    return choice, model, (held_info, len(train) < RESIDUAL_RUNS, f"the hybrid's held-out fit ({how})")


def predict_after(model, run: Trajectory, columns: np.ndarray, warmup: int) -> np.ndarray:
    """``(n - warmup, k)``: ``model``'s outputs of ``run`` after its first ``warmup`` samples, from the state they
    set: a physics Series of several outputs by :func:`identification.predict_outputs` (its state fitted on the
    output :func:`~identification._outputs.primary_view` names, read from ``columns``, the run's measured outputs),
    any other model (a hybrid, a network alone, a peer) by ``predict(rest, warmup=window)``."""
    if isinstance(model, Series):
        from identification import predict_outputs

        return predict_outputs(model, run.u, columns, warmup)
    window, rest = warmup_split(run, warmup)
    return np.asarray(model.predict(rest) if window is None else model.predict(rest, warmup=window))


def _residual_candidate(series, name: str, networks: tuple, outputs, measured: tuple = ()):
    """The unfitted model of residual candidate ``name`` on ``series``: a :class:`~hybrid.models.HybridModel` of
    every output, or with :data:`~hybrid.networks.ALONE` the network alone (a :class:`~hybrid.learning.LearnedModel`
    of every output); either reads the ``measured`` inputs (``Trajectory.extra`` columns) beside the command."""
    from hybrid.learning import LearnedModel
    from hybrid.models import HybridModel
    from hybrid.models._hybrid import BUILTIN_FEATURES

    from ._presets import folder_network, folder_training

    network = name.removesuffix(ALONE)
    training = folder_training(network, networks)
    if name.endswith(ALONE):
        return LearnedModel(folder_network(network), "forward", features=tuple(measured), outputs=outputs,
                            training=training)
    return HybridModel(physics=series, residual=folder_network(network), features=(*BUILTIN_FEATURES, *measured),
                       outputs=outputs, training=training)


def _residual_held_out(series: dict, name: str, networks: tuple, outputs, fit_on, check, warmup: int,
                       measured: tuple = ()) -> list:
    """Residual candidate ``name`` fitted on ``fit_on``: its predictions ``(n - warmup, k)`` of each ``check`` run
    after its warm-up window (a worker's task: plain data in, plain numbers out)."""
    from hybrid.learning._learned import _threads

    with _threads(1):
        model = _residual_candidate(Series.from_dict(series), name, networks, outputs, measured).fit(fit_on)
        return [predict_after(model, t, None, warmup) for t in check]  # never a Series: no columns read


def _fold_held_out(spec: str, selection, train, outputs, warmup: int):
    """``(held, pieces, how)`` from the selection's folds of whole runs: each fold's chain (fitted without its
    runs, on the first output) read by cubic maps fitted by least squares on the same runs
    (:func:`identification._outputs.fit_maps`), predicting the runs it left out. None where the selection has
    no such folds for ``spec`` (pieces of runs, fewer than three folds, folds fitted at another rate)."""
    from identification import output_columns, predict_outputs
    from identification._outputs import fit_maps
    from physics import OutputMaps

    if selection is None or selection.rate_hz is not None:
        return None
    names = [str(t.source) for t in train]
    params = selection.fold_parameters.get(spec) or []
    folds = selection.folds
    if (len(set(names)) != len(names) or len(folds) < RESIDUAL_RUNS or len(params) != len(folds)
            or not all(n in names for fold in folds for n in fold)):
        return None
    held = []
    for fold, p in zip(folds, params):
        fit_on = [t for t in train if str(t.source) not in fold]
        chain = Series.from_spec(spec, dt=train[0].dt).set_params(**p)
        model = fit_maps(chain, fit_on, [output_columns(t, outputs) for t in fit_on],
                         OutputMaps(outputs=len(outputs), cubic=True))
        inputs = np.concatenate([t.u for t in fit_on])
        model.input_range = (float(inputs.min()), float(inputs.max()))
        for name in fold:
            t = train[names.index(name)]
            held.append((t, predict_outputs(model, t.u, output_columns(t, outputs), warmup), fit_on))
    return held, False, (f"each run left out: the selection's chain fitted without it, each output's map refitted "
                         f"on the other runs ({len(folds)} folds)")


def _spread(train, outputs, warmup: int) -> np.ndarray:
    """Each output's spread (std) over the training runs' scored samples: what a held-out error is measured in."""
    from identification import output_columns

    return np.std(np.vstack([output_columns(t, outputs)[warmup:] for t in train]), axis=0)


def _standardized(held, predictions, outputs, warmup: int, spread) -> float:
    """The held-out error of one spec: each output's mean square over its training spread, averaged."""
    from identification import output_columns

    y = np.vstack([output_columns(t, outputs)[warmup:] for t in held])
    e = (y - np.vstack([np.asarray(p) for p in predictions])) / spread
    return float(np.mean(np.mean(e**2, axis=0)))


def _held_out_fit(spec: str, dt: float, fit_on, held, outputs, warmup: int, chain: dict | None = None):
    """The spec fitted on ``fit_on``: its predictions of each ``held`` run after its warm-up window, or the
    reason it could not be fitted (a worker's task: plain data in, plain numbers out)."""
    from identification import IdentificationError, identify_outputs, output_columns, predict_outputs
    from hybrid.learning._learned import _threads

    with _threads(1):
        try:
            fit = identify_outputs(Series.from_spec(spec, dt=dt), fit_on, outputs, warmup=warmup, chain_options=chain)
        except IdentificationError as exc:
            return str(exc)
        return [predict_outputs(fit.series, t.u, output_columns(t, outputs), warmup).tolist() for t in held]


def _as_output(run: Trajectory, outputs, j: int) -> Trajectory:
    """``run`` with output ``j`` of ``outputs`` as its ``y`` (what one output's intervals are calibrated on)."""
    from identification import output_columns

    return replace(run, y=output_columns(run, outputs)[:, j], output_name=outputs[j], extra={})


def _calibrate(train, outputs, held: list, pieces: bool, how: str, warmup: int, conditions: str | None = None):
    """Conformal intervals per output from the held-out predictions (``held``: ``(run, prediction, trained_on)``
    each): ``({name: intervals}, calibration)``; ``({}, {"why": ...})`` where there are none. The calibration
    also gives each output's held-out RMSE beside a linear ARX of all outputs fitted on the same runs
    (:func:`_held_out_scores`), and how the runs' ``conditions`` were told apart (None: each run its own)."""
    from hybrid.intervals import ConformalIntervals, HeldOut

    if not held:
        return {}, {"why": how}
    if isinstance(held[0][1], str):
        return {}, {"why": f"the spec fitted without the held-out runs failed: {held[0][1]}"}
    scores = _held_out_scores(outputs, held, warmup)
    intervals, half = {}, {}
    for j, name in enumerate(outputs):
        scored = [HeldOut(warmup_split(_as_output(t, outputs, j), warmup)[1], np.asarray(p)[:, j],
                          [_as_output(r, outputs, j) for r in fit_on], piece=pieces) for t, p, fit_on in held]
        try:
            intervals[name] = ConformalIntervals().fit([_as_output(t, outputs, j) for t in train], scored)
            half[name] = intervals[name].quantile()
        except DataError as exc:
            return {}, {"why": str(exc), "held_out_rmse": scores}
    first = intervals[outputs[0]]
    return intervals, {"level": first.level, "held_out_runs": first.runs_, "half_width": half, "source": how,
                       "conditions": conditions or "none (each run its own)", "held_out_rmse": scores}


def _condition_held_out(spec: str, train, outputs, warmup: int, workers, labels) -> tuple[list, bool, str]:
    """``(held, pieces, how)`` with each condition (``labels``: one per training run) left out whole: ``spec``
    fitted on the other conditions' runs (:func:`_held_out_fit`, at once on ``workers``) predicts each of its
    runs. A fold that cannot be fitted gives its reason in place of the predictions (no intervals, and why)."""
    from hybrid.intervals import condition_folds
    from identification.discovery import make_pool

    folds = condition_folds(labels)
    pool = make_pool(workers)
    splits = [([t for i, t in enumerate(train) if i not in fold], [train[i] for i in fold]) for fold in folds]
    futures = [pool.submit(_held_out_fit, spec, train[0].dt, fit_on, left, tuple(outputs), warmup)
               for fit_on, left in splits]
    try:
        predictions = [f.result() for f in futures]  # in order, whatever order they finish in
    except BaseException:
        pool.abort(futures)
        raise
    finally:
        pool.close()
    held = [(t, p if isinstance(p, str) else p[k], fit_on)
            for (fit_on, left), p in zip(splits, predictions) for k, t in enumerate(left)]
    held.sort(key=lambda h: isinstance(h[1], str), reverse=True)  # a failed fold first: _calibrate says why
    return held, False, f"each condition left out: the physics refitted without it ({len(folds)} folds)"


def _held_out_scores(outputs, held, warmup: int) -> dict:
    """Per output, the pooled RMSE on the held-out runs of the physics fitted without them and of a linear
    ARX of all outputs fitted on the same runs: ``{name: {"physics": ..., "arx": ...}}``. Where the ARX is
    lower the card and ``hyst fit`` say so (a folder of several outputs keeps the physics: the peer has
    no exported step of several outputs)."""
    from identification import output_columns
    from hybrid.peers import LinearARX

    arx = {}
    measured, model, peer = [], [], []
    for t, p, fit_on in held:
        if id(fit_on) not in arx:  # one ARX per fold
            arx[id(fit_on)] = LinearARX(outputs=outputs).fit(fit_on)
        window, rest = warmup_split(t, warmup)
        measured.append(output_columns(rest, outputs))
        model.append(np.asarray(p))
        peer.append(arx[id(fit_on)].predict(rest, **({} if window is None else {"warmup": window})))
    y, p, a = (np.vstack(v) for v in (measured, model, peer))
    return {name: {"physics": rmse(y[:, j], p[:, j]), "arx": rmse(y[:, j], a[:, j])} for j, name in enumerate(outputs)}


def arx_ahead(calibration: dict) -> list[str]:
    """The outputs on which the linear ARX beat the physics on the runs held out of both fits."""
    scores = calibration.get("held_out_rmse") or {}
    return [name for name, s in scores.items() if s["arx"] < s["physics"]]


def _fit_json(fit, chosen: str, how: str, tried: dict) -> dict:
    """``physics.json``: the fit of several outputs as ``hyst identify --output A,B,...`` writes it, with how its
    chain was chosen (``how``: "selection", "given", "discovery") and what was tried held out."""
    return {"model": fit.series.spec, "series": fit.series.to_dict(), "dt": fit.series.dt,
            "outputs": list(fit.outputs), "parameters": fit.parameters, "standard_errors": fit.standard_errors,
            "train_rmse": fit.train_rmse, "status": fit.status, "iterations": fit.iterations,
            "wall_time_s": fit.wall_time_s, "warmup": fit.warmup,
            "chain": {"spec": chosen, "how": how}, "tried": tried}


# --------------------------------------------------------------------------- results
def _rows(model, series, outputs, train, test, warmup: int, intervals: dict):
    """One row per run and output: the model's, its physics' and a linear ARX's (all outputs at once, fitted on
    the same runs) RMSE after the warm-up window, with intervals their coverage and width and the run's joint
    coverage (every output inside its interval at once); and per run ``(run, measured, model)``."""
    from identification import output_columns, predict_outputs
    from hybrid.intervals import coverage
    from hybrid.peers import LinearARX

    arx = LinearARX(outputs=outputs).fit(train)  # the baseline a reader would try first, on every output
    rows, predictions = [], []
    for part, runs in (("train", train), ("test", test)):
        for t in runs:
            window, rest = warmup_split(t, warmup)
            columns = output_columns(t, outputs)
            measured, phys = columns[warmup:], predict_outputs(series, t.u, columns, warmup)
            y = phys if model is series else predict_after(model, t, columns, warmup)
            peer = arx.predict(rest, **({} if window is None else {"warmup": window}))
            inside = np.ones(rest.n, dtype=bool)
            for j, name in enumerate(outputs):
                row = {"run": short_name(t.source), "set": part, "output": name, "samples": rest.n,
                       "physics_rmse": rmse(measured[:, j], phys[:, j]), "model_rmse": rmse(measured[:, j], y[:, j]),
                       "arx_rmse": rmse(measured[:, j], peer[:, j])}
                if intervals:
                    band = intervals[name].interval(y[:, j], rest.u, rest.dt)
                    inside &= (measured[:, j] >= band.lo) & (measured[:, j] <= band.hi)
                    row.update(coverage=coverage(measured[:, j], band.lo, band.hi),
                               width=float(np.mean(band.hi - band.lo)))
                rows.append(row)
            if intervals:
                for row in rows[-len(outputs):]:
                    row["joint_coverage"] = float(np.mean(inside))
            predictions.append((rest, measured, y))
    return rows, predictions


def pooled_rows(rows, key: str) -> float:
    """``key`` pooled over the rows' scored samples: an RMSE (:func:`._card.pooled`) or a share (their mean)."""
    if key.endswith("rmse"):
        return pooled(rows, key)
    n = np.array([r["samples"] for r in rows], dtype=float)
    return float(np.sum(n * np.array([r[key] for r in rows], dtype=float)) / n.sum())


def summary(rows, outputs) -> dict:
    """Per set and output: pooled model and ARX RMSE, coverage; and each set's joint coverage."""
    table = {}
    for part in ("train", "test"):
        sel = [r for r in rows if r["set"] == part]
        if not sel:
            continue
        table[part] = {}
        for name in outputs:
            mine = [r for r in sel if r["output"] == name]
            entry = {k: pooled_rows(mine, k) for k in ("model_rmse", "arx_rmse")}
            if "coverage" in mine[0]:
                entry.update(coverage=pooled_rows(mine, "coverage"), width=pooled_rows(mine, "width"))
            table[part][name] = entry
        first = [r for r in sel if r["output"] == outputs[0]]
        if "joint_coverage" in first[0]:
            table[part]["joint_coverage"] = pooled_rows(first, "joint_coverage")
    return table


def _write_card(out: Path, result, fit, chosen: str, physics, calibration: dict, tried: dict,
                residual: dict) -> None:
    outputs = result.outputs
    first = result.predictions[0][0]
    units = {name: (first.output_unit if name == first.output_name else None) for name in outputs}
    _plot_loops(out / "loops.png", result)
    table = summary(result.rows, outputs)
    n_train = sum(r["set"] == "train" for r in result.rows) // len(outputs)
    n_test = sum(r["set"] == "test" for r in result.rows) // len(outputs)
    how = (f"its chain chosen for `{outputs[0]}` by runs left out of the fit" if physics == "auto"
           else "given")
    kind = "physics only" if result.residual == "none" else f"physics + {result.residual} residual"
    if result.residual.endswith(ALONE):
        kind = f"the network {result.residual}"
    lines = [f"# Model card: {result.spec}, outputs {', '.join(outputs)} ({kind})", "",
             f"Data: {n_train} training and {n_test} test runs at {1.0 / first.dt:.6g} Hz (the model's rate); input "
             f"`{first.input_name or '?'}`" + (f" ({first.input_unit})" if first.input_unit else "")
             + f", outputs {', '.join(f'`{o}`' for o in outputs)}.", "",
             f"Physics `{result.spec}` (`{chosen}`, {how}): one chain, one state for the tendon, and each output read "
             "through its own map of the chain's signal; each output's error counts over its own spread in the fit. "
             + _residual_line(residual) + " Files: `physics.json` (fit), "
             + ("" if result.residual == "none" else "`model.pt` (the model), ")
             + ("`intervals.json` (per output), " if result.intervals else "")
             + "`step.casadi` (CasADi step of every output, its `init` fitting the state on "
             f"`{outputs[_init_output(fit.series)]}`'s window; `hyst export --track OUTPUT` picks one output).", "",
             *([_tried_line(tried), ""] if len(tried["specs"]) > 1 else []),
             "## RMSE per output", "", _protocol(result.warmup), "",
             "| output | set | model RMSE | linear ARX (all outputs) RMSE | model / ARX |"
             + (" interval covers | mean width |" if result.intervals else ""),
             "|---|---|---|---|---|" + ("---|---|" if result.intervals else "")]
    for part, entries in table.items():
        for name in outputs:
            e = entries[name]
            unit = f" {units[name]}" if units[name] else ""
            lines.append(f"| {name} | {part} | {e['model_rmse']:.4g}{unit} | {e['arx_rmse']:.4g} | "
                         f"{e['model_rmse'] / e['arx_rmse'] if e['arx_rmse'] > 0 else math.nan:.2f} |"
                         + (f" {e['coverage']:.1%} | {e['width']:.4g} |" if "coverage" in e else ""))
    lines += ["", "## RMSE per run", "", "Model RMSE (linear ARX in brackets), each output in its own unit.", "",
              "| run | set | " + " | ".join(outputs) + " |", "|---|---|" + "---|" * len(outputs)]
    for k in range(0, len(result.rows), len(outputs)):
        group = result.rows[k:k + len(outputs)]
        lines.append(f"| {group[0]['run']} | {group[0]['set']} | "
                     + " | ".join(f"{r['model_rmse']:.4g} ({r['arx_rmse']:.4g})" for r in group) + " |")
    scores = calibration.get("held_out_rmse")
    if scores:
        what = "physics" if result.residual == "none" else "model"
        lines += ["", "## Held out of the fits", "", f"The {what} fitted without the held-out runs or pieces, and a "
                  "linear ARX of all outputs fitted on the same runs, on them (pooled RMSE):", "",
                  f"| output | {what} | linear ARX |", "|---|---|---|",
                  *(f"| {o} | {scores[o]['physics']:.4g} | {scores[o]['arx']:.4g} |" for o in outputs)]
        if arx_ahead(calibration):
            lines += ["", f"**The linear ARX did better held out on {', '.join(arx_ahead(calibration))}**: the folder "
                          f"keeps the {what} (no peer exports several outputs yet); compare before you rely on it."]
    lines += ["", "## Intervals", ""]
    if result.intervals:
        level = calibration["level"]
        lines.append(f"{level:.0%} conformal intervals, calibrated per output on "
                     f"{len(calibration['held_out_runs'])} held-out runs or pieces ({calibration['source']}; "
                     f"conditions: {calibration.get('conditions', 'none (each run its own)')}); half-widths: " + ", ".join(f"{o} {calibration['half_width'][o]:.4g}" for o in outputs) + ".")
        for part, entries in table.items():
            if "joint_coverage" in entries:
                lines.append(f"On the {part} runs, every output is inside its interval at once on "
                             f"{entries['joint_coverage']:.1%} of the samples (joint coverage; each interval alone "
                             f"asks {level:.0%}).")
        short = [o for o in outputs if table.get("test", {}).get(o, {}).get("coverage", 1.0) < level - 0.05]
        if short:
            lines += ["", f"**The test runs are covered less than asked on {', '.join(short)}**: they differ from the "
                          "training runs in a way the held-out runs did not show."]
    else:
        lines.append(f"None: {calibration.get('why', 'not calibrated').rstrip('.')}.")
    lines += ["", "## Parameters", "", "| parameter | value | standard error |", "|---|---|---|"]
    for name, value in fit.parameters.items():
        se = fit.standard_errors.get(name)
        lines.append(f"| {name} | {value:.6g} | {'held' if se is None else f'{se:.3g}'} |")
    lines += ["", f"Joint fit: {fit.status} after {fit.iterations} iterations.", "",
              "![measured and model against the input](loops.png)", ""]
    with atomic_path(out / "report.md") as tmp:
        tmp.write_text("\n".join(lines))


def _residual_line(residual: dict) -> str:
    """What the card says of the residual stage: the network kept, or none, and each candidate's held-out error."""
    scores = residual.get("validation") or {}
    if not scores:
        return ("Residual network: none (asked for)." if not residual.get("how") else
                f"Residual network: none ({residual['how'].rstrip('.')}).") + _measured_line(residual)
    shown = ", ".join(f"`{n}` {v:.4g}" for n, v in scores.items())
    kept = residual["residual"]
    what = ("none: the physics alone was lowest held out" if kept == "none"
            else f"`{kept}`, one network of every output")
    return (f"Residual network: {what} ({residual['how']}; each output's mean square error over its spread, "
            f"averaged: {shown}).") + _measured_line(residual)


def _measured_line(residual: dict) -> str:
    """What the card says of the measured inputs: read by the network kept, or not read at all."""
    measured = residual.get("measured") or []
    if not measured:
        return ""
    names = ", ".join(f"`{m}`" for m in measured)
    if residual["residual"] == "none":
        return (f" The measured input(s) {names} are **not read**: the physics alone, which ignores them, did better "
                "held out than every network that reads them; the exported step takes the command alone.")
    return f" The network reads the measured input(s) {names} beside the command; the exported step takes both."


def _plot_loops(path: Path, result, most: int = 3) -> None:
    """Each output (rows) against the input for up to ``most`` runs (columns), test runs first."""
    plt = _plt()
    both = list(zip(result.rows[::len(result.outputs)], result.predictions))
    both = ([b for b in both if b[0]["set"] == "test"] + [b for b in both if b[0]["set"] == "train"])[:most]
    k = len(result.outputs)
    fig, axes = plt.subplots(k, len(both), figsize=(3.2 * len(both), 2.4 * k), squeeze=False)
    for c, (row, (t, measured, y)) in enumerate(both):
        for j, name in enumerate(result.outputs):
            ax = axes[j][c]
            ax.plot(t.u, measured[:, j], color="0.7", lw=2.2, label="measured")
            ax.plot(t.u, y[:, j], color="C0", lw=0.8, label="model")
            if j == 0:
                ax.set_title(f"{row['run']} ({row['set']})", fontsize=9)
            if c == 0:
                ax.set_ylabel(_label(name, t.output_unit if name == t.output_name else None, "output"))
        axes[-1][c].set_xlabel(_label(t.input_name, t.input_unit, "input"))
    axes[0][0].legend(fontsize=8)
    _save(fig, path, plt)


def _init_output(series) -> int:
    """The output whose warm-up window sets the state (:func:`identification._outputs.primary_view`)."""
    from identification._outputs import primary_view

    return primary_view(series)[1]


def tried_entries(tried: dict, quote: str = "`") -> list[str]:
    """Each spec tried held out with its error, or why it has none (``quote`` around the spec's name)."""
    return [f"{quote}{s}{quote} {v:.4g}" if not isinstance(v, str) else f"{quote}{s}{quote} none ({v})"
            for s, v in tried["specs"].items()]


def _tried_line(tried: dict) -> str:
    """What the card says of the specs tried held out: each one's error, and which was kept."""
    shown = "; ".join(tried_entries(tried))
    return (f"Tried on the runs held out of their fits (each output's mean square error over its spread, averaged): "
            f"{shown}. Kept: `{tried['kept']}` (the arc replaces the maps only where the root of its error is lower by "
            f"more than {MARGIN:.0%}).")
