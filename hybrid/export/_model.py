"""The exported model: one pure CasADi step function in physical units, plus its state's story."""

from __future__ import annotations

import json
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike, NDArray

from physics.data.io import atomic_paths, read_json

from ._codegen import codegen
from ._errors import ExportError
from ._native import deserialize, load_function

__all__ = ["ExportedModel", "ExportError"]

_FORMAT = "hysteresis-hybrid/exported-model/1"

#: The one initial-state rule, written into every sidecar: predict, step-by-step use, export and
#: MPC start a run whose first input is u0 from the same state.
X0_RULE = ("x0 = base(u0): the state before the first sample u0 of a run, the one the fitted model's "
           "predict starts from (physics: its blocks' initial state at u0; networks: the training's "
           "start, i.e. an LSTM after seq_len - 1 flag inputs, a history buffer filled with its pad "
           "or with u0)")


@dataclass
class ExportedModel:
    """A fitted model as ``Function('step', [x, u], [x_next, y])`` in physical units.

    Everything the model knows (physical parameters, network weights, min-max
    scaling) is folded into the step as float64 constants, so the function is
    pure: the tendon displacement ``u`` (mm) and the state ``x`` in, the next
    state and the tip angle ``y`` (deg) out, at the model's sample time ``dt``.
    ``y`` at sample ``k`` may depend on ``u`` at ``k`` (direct feed-through).

    Parameters
    ----------
    step : casadi.Function
        ``(x, u) -> (x_next, y)``, inputs named ``'x', 'u'`` and outputs ``'x_next', 'y'``.
    state_names : tuple of str
        One name per entry of ``x`` (physics states ``"<block>.<state>"``; LSTM
        ``"lstm.h_l0[j]"``...; a history buffer ``"buffer.u[k-49]"``... oldest first).
    x0_base : casadi.Function
        ``(u0) -> x``: the state before the first sample ``u0`` of a run (:data:`X0_RULE`),
        the one ``predict`` of the fitted model starts from.
    dt : float or None
        Sample time (s).
    kind : str
        ``"physics"``, ``"fnn"``, ``"fnn-hib"``, ``"lstm"``, ``"hybrid"``, ...
    meta : dict
        JSON-ready facts (spec, parameters, scaler ranges, ``input_range``: the input's range
        on the data the model was fitted on) kept in the sidecar.
    approximation : casadi.Function or None
        A cheap step ``(x, u) -> (x_next, y)`` on the same state whose output
        Jacobian approximates this model's: for a hybrid, its physics part (the
        residual's states pass through). The MPC's ``"adjoint-sqp"`` solver builds
        its Hessian from it (:class:`hybrid.control.TrackingMPC`).
    init : casadi.Function or None
        ``(u_w, y_w) -> x``: the state after a window of ``meta["warmup"]`` measured samples
        (``u_w`` n_u x K, ``y_w`` 1 x K), where the next sample starts (``export_model(...,
        warmup=K)``; :mod:`hybrid.export._init`). None: the model starts from ``x0`` only.
    half_width : casadi.Function or None
        ``(u, u_prev, y) -> (half_width, outside)``: the model's calibrated prediction interval at
        one step (``y +- half_width``, level ``meta["interval_level"]``) and 1 where the sample
        leaves the training data (:meth:`hybrid.intervals.ConformalIntervals.function`; a model
        folder from ``hyst fit`` has one). None: no intervals.
    x0_physics : casadi.Function or None
        ``(u0, xp) -> x``: the state before a run's first sample ``u0`` when its physics part starts
        at ``xp`` (a state of the model's physics ``Series``) rather than at rest; each exporter
        that has a physics part says how its state is built from it. ``init`` is built on it; it is
        not saved (``init`` is). None: no physics part.

    Examples
    --------
    >>> from physics import Series
    >>> from hybrid.export import export_model
    >>> m = export_model(Series.from_spec("lag+boucwen+linear"))
    >>> m.state_names
    ('lag.position', 'lag.u_prev', 'boucwen.z', 'boucwen.u_prev')
    >>> x_next, y = m.step(m.x0(1.0), 1.0)
    >>> round(float(y), 6)
    40.8
    """

    step: ca.Function
    state_names: tuple[str, ...]
    x0_base: ca.Function
    dt: float | None = None
    kind: str = "model"
    meta: dict[str, Any] = field(default_factory=dict)
    approximation: ca.Function | None = None
    init: ca.Function | None = None
    x0_physics: ca.Function | None = None
    half_width: ca.Function | None = None

    def __post_init__(self) -> None:
        self.state_names = tuple(self.state_names)
        f = self.step
        if f.n_in() != 2 or f.n_out() != 2:
            raise ExportError(f"The step must be Function (x, u) -> (x_next, y); got {f.n_in()} inputs "
                              f"and {f.n_out()} outputs.")
        if f.size1_in(0) != len(self.state_names) or f.size1_out(0) != f.size1_in(0):
            raise ExportError(f"The step's state has {f.size1_in(0)} entries but {len(self.state_names)} "
                              "state names were given; give one name per state.")
        if self.x0_base.size1_out(0) != f.size1_in(0):
            raise ExportError("x0_base must return a state of the step's size.")
        a = self.approximation
        if a is not None and (a.n_in() != 2 or a.n_out() != 2 or a.size_in(0) != f.size_in(0)
                              or a.size_in(1) != f.size_in(1) or a.size_out(1) != f.size_out(1)):
            raise ExportError("The approximation must be a step (x, u) -> (x_next, y) of the same sizes as the model's.")

    # -- structure ----------------------------------------------------------
    @property
    def n_x(self) -> int:
        return len(self.state_names)

    @property
    def n_u(self) -> int:
        return int(self.step.size1_in(1))

    @property
    def n_y(self) -> int:
        """How many outputs the step returns (a model of the tip's angle and position: several)."""
        return int(self.step.size1_out(1))

    @property
    def input_range(self) -> tuple[float, float] | None:
        """The range of the input (``u``) the model was fitted on, ``meta["input_range"]``, or
        ``None`` where the export does not know it (a physics model never identified)."""
        r = self.meta.get("input_range")
        return None if r is None else (float(r[0]), float(r[1]))

    def output(self, index: int) -> "ExportedModel":
        """This model seen through its output ``index`` alone: the same state and rest state, a step that
        returns that output (``meta["output_index"]``). What tracks one output of a model of several (the
        tip's position ``y`` of an angle-and-position model) with the controllers of one output. The
        interval is left out unless it is that output's (``meta["interval_output"] == index``: the interval of
        one output set on the model of them all), and so is the window's ``init`` unless ``index`` is the one
        output it fits the state on (``meta["init_output"]``, or ``meta["init_outputs"]`` of that output alone):
        it then takes that output's window alone.

        Examples
        --------
        >>> from physics import Series, Lag, OutputMaps
        >>> from hybrid.export import export_model
        >>> m = export_model(Series(Lag(), OutputMaps(outputs=2, offset_2=5.0)))
        >>> m.n_y, m.output(1).n_y, float(m.output(1).step(m.x0(0.0), 0.0)[1])
        (2, 1, 5.0)
        """
        if isinstance(index, bool) or int(index) != index or not 0 <= index < self.n_y:
            raise ExportError(f"output index must be a whole number in 0..{self.n_y - 1} (the step has {self.n_y} "
                              f"output(s)). Got {index!r} instead.")
        index = int(index)

        def pick(f: ca.Function | None) -> ca.Function | None:
            if f is None:
                return None
            S = ca.SX if f.is_a("SXFunction") else ca.MX
            x, u = S.sym("x", f.size1_in(0)), S.sym("u", f.size1_in(1))
            x_next, y = f(x, u)
            return ca.Function(f.name(), [x, u], [x_next, y[index]], ["x", "u"], ["x_next", "y"])

        init = None
        reads = self.meta.get("init_outputs", [self.meta.get("init_output")])
        if self.init is not None and reads == [index]:  # it reads that output's window alone
            k = int(self.meta["warmup"])
            u_w, y_w = ca.MX.sym("u_w", self.n_u, k), ca.MX.sym("y_w", 1, k)
            rows = [y_w if j == index else ca.MX.zeros(1, k) for j in range(self.n_y)]
            init = ca.Function("init", [u_w, y_w], [self.init(u_w, ca.vertcat(*rows))], ["u_w", "y_w"], ["x"])
        meta = {k: v for k, v in self.meta.items()
                if k not in ("init_output", "init_outputs", "interval_output") and (init is not None or k != "warmup")}
        own = self.meta.get("interval_output") == index  # the interval set is this output's
        return replace(self, step=pick(self.step), approximation=pick(self.approximation), init=init,
                       half_width=self.half_width if own else None, meta={**meta, "output_index": index})

    def x0(self, u0: float | ArrayLike) -> NDArray[np.float64]:
        """The state before the first sample ``u0`` of a run (:data:`X0_RULE`): ``x0_base(u0)``."""
        u0 = ca.DM(np.asarray(u0, dtype=float).reshape(-1, 1))
        return np.asarray(self.x0_base(u0), dtype=float).ravel()

    def rollout(self, n: int) -> ca.Function:
        """``Function('rollout', [x0, u], [x, y])`` over ``n`` samples (``mapaccum``).

        ``u`` is n_u x n, ``y`` n_y x n; column ``k`` of ``x`` is the state *after* step ``k``.
        """
        if int(n) != n or n < 1:
            raise ExportError(f"A rollout needs n >= 1 samples. Got {n} instead.")
        acc = self.step.mapaccum("acc", int(n))
        x0, u = ca.MX.sym("x0", self.n_x), ca.MX.sym("u", self.n_u, int(n))
        xs, ys = acc(x0, u)
        return ca.Function("rollout", [x0, u], [xs, ys], ["x0", "u"], ["x", "y"])

    def warm_state(self, u_w: ArrayLike, y_w: ArrayLike) -> NDArray[np.float64]:
        """The state after the measured window ``(u_w, y_w)`` of ``meta["warmup"]`` samples (``init``)."""
        k = self.meta.get("warmup")
        if self.init is None:
            raise ExportError("This export has no init function; export the model with warmup=K "
                              "(`hyst export --warmup K`) to start it from K measured samples.")
        u_w = self._inputs(u_w)
        y_w = np.atleast_2d(np.asarray(y_w, dtype=float))
        y_w = y_w.T if y_w.shape[0] != self.n_y else y_w  # n_y x k, or k x n_y as a run's columns
        if u_w.shape[1] != k or y_w.shape[1] != k or y_w.shape[0] != self.n_y:
            raise ExportError(f"This export's init takes windows of {k} samples of its {self.n_y} output(s); got "
                              f"{u_w.shape[1]} inputs and outputs of shape {np.shape(y_w)}.")
        return np.asarray(self.init(u_w, y_w), dtype=float).ravel()

    def _inputs(self, u: ArrayLike) -> NDArray[np.float64]:
        u = np.atleast_2d(np.asarray(u, dtype=float))
        return u.T if u.shape[0] != self.n_u else u

    def simulate(self, u: ArrayLike, x0: ArrayLike | None = None, warmup=None) -> NDArray[np.float64]:
        """Output path for the input path ``u`` (x0 defaults to the start of a run at ``u[0]``;
        ``warmup=(u_w, y_w)``, the measured samples just before ``u``, sets it by ``init``); ``(n, n_y)``
        for a step of several outputs."""
        u = self._inputs(u)
        if warmup is not None:
            if x0 is not None:
                raise ExportError("Give x0 or a warm-up window, not both: the window sets the state.")
            x0 = self.warm_state(*warmup)
        x0 = self.x0(u[:, 0]) if x0 is None else np.asarray(x0, dtype=float).ravel()
        _, ys = self.rollout(u.shape[1])(x0, u)
        ys = np.asarray(ys, dtype=float)
        return ys.reshape(self.n_y, u.shape[1]).T if self.n_y > 1 else ys.ravel()

    # -- files -----------------------------------------------------------------
    def save(self, path) -> Path:
        """Write ``path`` (``Function.save``, loadable with ``casadi.Function.load`` alone) and
        ``path + ".json"`` (state names, the x0 rule, dt, kind, meta; :func:`sidecar`)."""
        path = Path(path)
        if path.suffix != ".casadi":
            raise ExportError(f"Exported models are saved as .casadi files; got '{path.name}'.")
        info = {
            "format": _FORMAT, "kind": self.kind, "dt": self.dt, "state_names": list(self.state_names),
            "x0": {"rule": X0_RULE, "base": self.x0_base.serialize()},
            "meta": self.meta,
            "approximation": None if self.approximation is None else self.approximation.serialize(),
            "init": None if self.init is None else self.init.serialize(),
            **({} if self.half_width is None else {"half_width": self.half_width.serialize()}),
        }
        with atomic_paths(path, sidecar(path)) as (tmp, side):  # both or neither
            self.step.save(str(tmp))
            side.write_text(json.dumps(info, indent=2) + "\n")
        return path

    @classmethod
    def load(cls, path, allow_external: bool = False) -> "ExportedModel":
        """Read a model written by :meth:`save` (needs casadi only, never torch).

        A function that calls an external library or is compiled on load runs native code
        when it is read, so it is refused unless ``allow_external`` (see ``hybrid.export._native``).
        """
        path = Path(path)
        if path.is_dir():
            raise ExportError(f"'{path}' is a folder; give the exported .casadi file.")
        if not path.is_file():
            raise ExportError(f"No exported model at '{path}'. Write one with `hyst export` or ExportedModel.save.")
        side = sidecar(path)
        if not side.is_file():
            raise ExportError(f"'{path.name}' has no sidecar '{side.name}' (state names, x0); "
                              "save with ExportedModel.save, or use casadi.Function.load for the step alone.")
        step = load_function(path, allow_external)
        info = read_json(side, "exported-model sidecar")
        if not isinstance(info, dict) or info.get("format") != _FORMAT:
            found = info.get("format") if isinstance(info, dict) else type(info).__name__
            raise ExportError(f"'{side}' is not an exported-model sidecar (format {found!r}).")
        try:
            x0 = info["x0"]
            approximation, init = info.get("approximation"), info.get("init")
            return cls(step=step, state_names=tuple(info["state_names"]),
                       x0_base=_x0_base(step, x0, deserialize(x0["base"], f"{side}: x0.base", allow_external)),
                       dt=info.get("dt"),
                       kind=info.get("kind", "model"), meta=info.get("meta", {}),
                       approximation=None if approximation is None
                       else deserialize(approximation, f"{side}: approximation", allow_external),
                       init=None if init is None else deserialize(init, f"{side}: init", allow_external),
                       half_width=None if info.get("half_width") is None
                       else deserialize(info["half_width"], f"{side}: half_width", allow_external))
        except (KeyError, TypeError, ValueError) as exc:
            if isinstance(exc, ExportError):
                raise
            raise ExportError(f"'{side}' is damaged ({type(exc).__name__}: {exc}); export the model again "
                              "with `hyst export`.") from None

    def codegen(self, directory, name: str = "step", compile: bool = True) -> Path:
        """C code of the step in ``directory``; compiled with gcc into ``lib<name>.so`` when
        ``compile`` (see :func:`hybrid.export.codegen`); ``init`` beside it where the export has one
        (one library, C symbols ``step`` and ``init``), and ``half_width`` where it has intervals.
        Returns the library (or the C file)."""
        functions = [self.step] + [f for f in (self.init, self.half_width) if f is not None]
        return codegen(functions, directory, name=name, compile=compile)

    def __repr__(self) -> str:
        return (f"ExportedModel(kind={self.kind!r}, n_x={self.n_x}, dt={self.dt}, "
                f"step={self.step.name()!r} [{self.step.class_name()}])")


def sidecar(path) -> Path:
    """The JSON sidecar beside an exported ``.casadi`` file: ``step.casadi.json``. (Not
    ``step.json``, which is the sidecar of a ``step.pt`` checkpoint in the same folder.)"""
    return Path(str(path) + ".json")


def _x0_base(step: ca.Function, x0: dict, base: ca.Function) -> ca.Function:
    """The sidecar's x0 function ``base``; files written before the one rule ran ``warmup_steps``
    steps at constant ``u0`` after it, which is folded in here so they load as written."""
    n = int(x0.get("warmup_steps", 0))
    if not n:
        return base
    u0 = ca.MX.sym("u0", base.size1_in(0))
    xs, _ = step.mapaccum("warmup", n)(base(u0), ca.repmat(u0, 1, n))
    return ca.Function("x0", [u0], [xs[:, -1]], ["u0"], ["x0"])
