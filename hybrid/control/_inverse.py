"""Model-based inverse: the tendon path that makes a forward model follow a wanted tip-angle path.

The forward model (physics, hybrid or learned) is exported to one CasADi step
(``hybrid.export.export_model``: the residual network written into the graph from
its torch weights) and the input is solved for over a receding window: minimise
``sum (y_k - r_k)^2 + w_du g^2 sum (u_k - u_{k-1})^2`` over the next ``window``
inputs, ``g`` the model's rest gain (so the balance holds in any units; the cost is divided by
the output's scale, so the solver's tolerances do too), plus ``w_physics`` times the inputs'
distance from the physics inverse, with single shooting and
``sqpmethod`` with a Gauss-Newton Hessian, or IPOPT,
keep the first ``commit`` of them, advance the model's state with them and solve
again. It looks ``window`` samples ahead along the wanted path, as a tracking
controller does, where a learned inverse sees only the past.
"""

from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike, NDArray

from physics import Series
from physics.data import BaseEstimator, DataError, NotFittedError, Trajectory, as_warmup
from physics.data.io import raise_if_pressed, recording, stop_callback

__all__ = ["ModelInverse", "SOLVERS"]

SOLVERS = ("sqp", "ipopt")
#: A window's solve ends once its best cost has dropped by no more than ``STALL_RTOL`` of itself
#: over ``STALL_WINDOW`` iterations. Through a backlash or a play the Gauss-Newton steps can cycle
#: between two points a hair apart (line searches failing every other iteration) up to the
#: iteration limit: on the Bouc-Wen benchmark's hybrid, 17 of 20 iterations on average, for a cost
#: that had stopped moving after 4.
STALL_WINDOW, STALL_RTOL = 3, 1e-3


class ModelInverse(BaseEstimator):
    """Invert a fitted forward model numerically over a receding window.

    Parameters
    ----------
    model
        A forward model: ``physics.Series``, ``FitResult``, forward
        :class:`HybridModel` (fed ``u`` and ``physics``), forward
        :class:`LearnedModel`, or an ``ExportedModel``. An unfitted estimator is
        fitted by :meth:`fit`.
    window : int, default 50
        Samples solved for at once (2 s at 25 Hz).
    commit : int, default 25
        Samples of each solution applied before solving again (1: a classic
        receding horizon, ``window`` times dearer).
    w_du : float, default 1e-5
        Weight of the input's change per sample, as the output change it would make at the
        model's rest gain ``g`` (``w_du (g du)^2`` against ``(y - r)^2``: unit-free; on the
        catheter, ``g`` near 10 deg/mm, 1e-5 is 1e-3 per mm^2 against 1/deg^2): keeps the input
        still inside a backlash's dead band, where the output does not see it.
    u_bounds : (float, float) or None
        Limits on the input (its units); None: unbounded (a model of several outputs: the input range it
        was fitted on, where it records one: the tip's position alone may not tell which side it bends to).
    solver : {"sqp", "ipopt"}
    mode : str, optional
        Export mode of an LSTM residual (default "carried").
    w_physics : float, default 1e-2
        Weight of the input's distance from the physics inverse (the first window's guess, and
        each later window's last samples' guess),
        over the input's typical size, against the output error over its scale: a residual
        network's gradients then correct the physics' input rather than steer the windows away
        from it. Without it (0), a 20-sample window on a 500 Hz friction stage's FNN-HIB hybrid
        drove the input from bound to bound (RMSE 487 N on a 578 N sweep, against 11 N with it;
        the physics inverse alone: 10.5 N). Applies to a model with a physics part and more
        (a hybrid); a physics model is its own inverse's reference.
    output : int or None
        A model of several outputs (the tip's angle and position): the index of the output to follow.
        One tendon cannot put every output where each wants; the others go where that path takes them
        (:meth:`ExportedModel.output`, :meth:`physics.Series.output_view`). None for a model of one output.

    Examples
    --------
    >>> import numpy as np
    >>> from physics import Series
    >>> model = Series.from_spec("boucwen+linear")
    >>> u = 3 - 2 * np.cos(np.linspace(0, 6, 120))
    >>> inv = ModelInverse(model, window=20, commit=10).fit()
    >>> bool(np.max(np.abs(inv.predict(model.simulate(u)) - u)) < 1e-3)
    True
    """

    direction = "inverse"

    def __init__(self, model: Any, window: int = 50, commit: int = 25, w_du: float = 1e-5,
                 u_bounds: tuple[float, float] | None = None, solver: str = "sqp", mode: str | None = None,
                 w_physics: float = 1e-2, output: int | None = None):
        self.model = model
        self.window = window
        self.commit = commit
        self.w_du = w_du
        self.u_bounds = u_bounds
        self.solver = solver
        self.mode = mode
        self.w_physics = w_physics
        self.output = output

    @property
    def name(self) -> str:
        followed = "" if self.output is None else f"[output {self.output}]"
        return f"model-inverse:{getattr(self.model, 'name', type(self.model).__name__)}{followed}"

    def _follow(self, n_y: int) -> None:
        """A model of several outputs seen through the one :attr:`output` names (its export and its physics)."""
        if n_y == 1:
            if self.output not in (None, 0):
                raise DataError(f"output={self.output!r} picks the output to follow of a model of several; this one has "
                                "one output. Leave it out.")
            return
        j = self.output
        if j is None or isinstance(j, bool) or not isinstance(j, (int, np.integer)) or not 0 <= j < n_y:
            raise DataError(f"This model has {n_y} outputs, and one tendon cannot put each where it wants: name the one "
                            f"to follow, ModelInverse(model, output=j) with j in 0..{n_y - 1} (the others go where "
                            f"its path takes them). Got output={j!r}.")
        self.exported_ = self.exported_.output(int(j))
        if self.physics_ is not None and getattr(self.physics_, "n_y", 1) > 1:
            self.physics_ = self.physics_.output_view(int(j))
        if self.u_bounds_ is None:  # a position alone may not tell the bending's side (an arc's y is even in
            self.u_bounds_ = self.exported_.input_range  # its angle): keep to the inputs the model was fitted on

    def fit(self, data=None) -> ModelInverse:
        """Export the forward model (fitting it on ``data`` first if it is an unfitted estimator)."""
        from hybrid.export import export_model

        for name in ("window", "commit"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
                raise DataError(f"The {name!r} parameter of ModelInverse must be an integer >= 1. Got {value!r}.")
        if self.commit > self.window:
            raise DataError(f"commit ({self.commit}) must be <= window ({self.window}).")
        for name in ("w_du", "w_physics"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value < np.inf:
                raise DataError(f"The {name!r} parameter of ModelInverse must be a finite number >= 0. Got {value!r}.")
        if self.solver not in SOLVERS:
            raise DataError(f"Unknown solver {self.solver!r}. Must be one of {list(SOLVERS)}.")
        model = self.model.model() if hasattr(self.model, "fitted_model") else self.model  # a FitResult
        if hasattr(model, "fit") and not _is_fitted(model):
            if data is None:
                raise DataError("The forward model is not fitted: call fit(trajectories).")
            model.fit(data)
        if getattr(model, "direction", "forward") != "forward":
            raise DataError("ModelInverse inverts a forward model; got a model with direction="
                            f"{model.direction!r}.")
        options = {"mode": self.mode} if self.mode and not isinstance(model, Series) else {}
        self.exported_ = export_model(model, **options)
        self.physics_ = model if hasattr(model, "inverse") and hasattr(model, "blocks") else getattr(model, "physics_", None)
        # the pull towards the physics inverse is for a model with more than physics in it (a hybrid)
        self._w_physics = self.w_physics if self.physics_ is not None and self.physics_ is not model else 0.0
        self.u_bounds_ = self.u_bounds
        self._follow(self.exported_.n_y)
        self.scales_ = self._scales(data)
        self._build()
        return self

    def _rest_output(self, u: float) -> float:
        return float(self.exported_.step(self.exported_.x0(u), u)[1])

    def _scales(self, data) -> dict[str, float]:
        """The input's centre and typical size (from the training runs, else ``u_bounds``, else 0 and
        1), the model's rest gain there and the output's scale: gain times the input's size."""
        u = np.concatenate([np.asarray(t.u, dtype=float) for t in data]) if data is not None else None
        lo, hi = self.u_bounds_ if self.u_bounds_ is not None else (-np.inf, np.inf)
        if u is not None and u.size and np.std(u) > 0:
            center, size = float(np.mean(u)), float(np.std(u))
        elif np.isfinite(lo) and np.isfinite(hi) and hi > lo:
            center, size = (lo + hi) / 2, (hi - lo) / 4
        else:
            center, size = 0.0, 1.0
        gain = (self._rest_output(center + size) - self._rest_output(center - size)) / (2 * size)
        y_scale = abs(gain) * size
        if not np.isfinite(y_scale) or y_scale <= 0:
            ys = np.concatenate([np.asarray(t.y, dtype=float) for t in data]) if data is not None else np.ones(1)
            y_scale = float(np.std(ys)) or 1.0
            gain = y_scale / size
        return {"u_center": center, "u_scale": size, "gain": float(gain), "y_scale": float(y_scale)}

    def _build(self) -> None:
        step, W, s = self.exported_.step, int(self.window), self.scales_
        # The solvers see O(1) numbers in any units: the input as (u - centre) / size, both terms
        # of the cost in units of the output's scale, so their tolerances mean the same everywhere.
        V = ca.MX.sym("V", W)
        U = s["u_center"] + s["u_scale"] * V
        x0, u_prev, ref = ca.MX.sym("x0", self.exported_.n_x), ca.MX.sym("u_prev"), ca.MX.sym("ref", W)
        prior = ca.MX.sym("prior", W)  # the physics inverse over the window
        _, ys = step.mapaccum("window", W)(x0, U.T)
        du = U - ca.vertcat(u_prev, U[:-1])
        res = ca.vertcat((ys.T - ref) / s["y_scale"], np.sqrt(self.w_du) * abs(s["gain"]) * du / s["y_scale"],
                         np.sqrt(self._w_physics) * (U - prior) / s["u_scale"])
        p = ca.vertcat(x0, u_prev, ref, prior)
        nlp = {"x": V, "p": p, "f": ca.sumsqr(res)}
        expand = step.is_a("SXFunction")
        if self.solver == "sqp":
            lam_f, lam_g = ca.MX.sym("lam_f"), ca.MX.sym("lam_g", 0)
            J = ca.jacobian(res, V)
            hess = ca.Function("nlp_hess_l", [V, p, lam_f, lam_g], [2 * lam_f * ca.mtimes(J.T, J)],
                               ["x", "p", "lam_f", "lam_g"], ["hess_gamma_x_x"])
            opts = {"qpsol": "qrqp", "hess_lag": hess.expand() if expand else hess, "max_iter": 20,
                    "print_time": False, "print_header": False, "print_iteration": False, "print_status": False,
                    "error_on_fail": False, "show_eval_warnings": False, "tol_pr": 1e-8, "tol_du": 1e-8,
                    "qpsol_options": {"print_iter": False, "print_header": False, "print_info": False,
                                      "error_on_fail": False}}
            self._solver = ca.nlpsol("inverse", "sqpmethod", nlp, {**opts, "expand": expand,
                                                                   "iteration_callback": self._stop_callback(nlp)})
        else:
            self._solver = ca.nlpsol("inverse", "ipopt", nlp, {"expand": expand, "print_time": False,
                                                                "ipopt.print_level": 0, "ipopt.sb": "yes",
                                                                "ipopt.max_iter": 100,
                                                                "iteration_callback": self._stop_callback(nlp)})
        self._advance = {}
        self._cost_fn = ca.Function("cost", [V, p], [nlp["f"]])

    def _stop_callback(self, nlp):
        """Ctrl-C or a stall ends a solve in progress (kept on the estimator as long as the solver lives)."""
        self._stop = stop_callback(int(nlp["x"].numel()), 0, int(nlp["p"].numel()),
                                   stall=(STALL_WINDOW, STALL_RTOL))
        return self._stop

    def _cost(self, x, u_prev, ref, U, prior) -> float:
        value = float(self._cost_fn(self._scaled(U), np.r_[x, u_prev, ref, prior]))
        return value if np.isfinite(value) else np.inf

    def _target(self, trajectory: Trajectory) -> NDArray[np.float64]:
        return trajectory.u  # the input that made the trajectory's output

    def predict(self, data: Trajectory | ArrayLike, mode: str | None = None, warmup=None) -> NDArray[np.float64]:
        """Input path for a trajectory's output (the wanted tip angle) or a wanted output path.

        ``warmup``, the measured samples just before (a Trajectory, or ``(wanted_output, input)``
        arrays: :func:`physics.data.as_warmup`), sets the model's state (the export's ``init``) and
        the last input; without one the model starts at rest at the input whose rest output is the
        first wanted one."""
        if not hasattr(self, "exported_"):
            raise NotFittedError("This ModelInverse is not fitted yet. Call fit() first.")
        r = np.asarray(data.y if isinstance(data, Trajectory) else data, dtype=float)
        if r.ndim != 1 or r.size == 0 or not np.all(np.isfinite(r)):
            raise DataError(f"the wanted output must be a finite 1-D path; got shape {r.shape}.")
        W, C, n = int(self.window), int(self.commit), r.size
        lo, hi = self.u_bounds_ if self.u_bounds_ is not None else (-np.inf, np.inf)
        window = as_warmup(warmup, inverse=True)
        if window is None:
            u0 = self._rest_input(r[0])
            x, u_prev, measured = self.exported_.x0(u0), u0, None
        else:  # the forward model's roles: the input applied over the window, and its output
            u_w = window.w
            y_w = np.asarray(window.data.y if isinstance(window.data, Trajectory) else window.data, dtype=float)
            x, u_prev, measured = self._warm_export(u_w.size).warm_state(u_w, y_w), float(u_w[-1]), (u_w, y_w)
        # Start each window from the physics inverse (when there is one): inside a backlash's dead
        # band the output does not see the input, so a constant first guess has no gradient.
        first = (self.physics_.inverse(r, bounds=self.u_bounds_, warmup=measured) if self.physics_ is not None
                 else np.full(n, u_prev))
        first = np.r_[first, np.full(W, first[-1])]
        guess, out, k = first[:W], np.empty(n), 0
        with recording():  # Ctrl-C: KeyboardInterrupt after the window in progress
            while k < n:
                raise_if_pressed()
                ref = np.r_[r[k:k + W], np.full(max(0, k + W - n), r[-1])]
                prior = first[k:k + W]
                self._stop.reset()
                sol = self._solver(x0=self._scaled(guess), p=np.r_[x, u_prev, ref, prior],
                                   lbx=self._scaled(np.full(W, lo)), ubx=self._scaled(np.full(W, hi)))
                U = self.scales_["u_center"] + self.scales_["u_scale"] * np.asarray(sol["x"], dtype=float).ravel()
                f = float(sol["f"])
                if not (np.all(np.isfinite(U)) and np.isfinite(f)) or f > self._cost(x, u_prev, ref, guess, prior):
                    U = guess  # a failed or worse solve (e.g. the network far outside its data): keep the guess
                U = np.clip(U, lo, hi)
                c = min(C, n - k)
                out[k:k + c] = U[:c]
                x = self._advance_by(c)(x, U[:c][None, :])
                x = np.asarray(x, dtype=float).ravel()
                u_prev, k = U[c - 1], k + c
                guess = np.r_[U[c:], first[k + W - c:k + W]]
        return out

    def _warm_export(self, k: int):
        """The exported model with ``init`` over windows of ``k`` samples (built once per ``k``)."""
        from hybrid.export._init import with_init

        cache = self.__dict__.setdefault("_warm_exports", {})
        if k not in cache:
            cache[k] = with_init(self.exported_, self.physics_, k)
        return cache[k]

    def _scaled(self, u) -> NDArray[np.float64]:
        return (np.asarray(u, dtype=float) - self.scales_["u_center"]) / self.scales_["u_scale"]

    def _advance_by(self, c: int) -> ca.Function:
        if c not in self._advance:
            step = self.exported_.step
            x0, U = ca.MX.sym("x0", self.exported_.n_x), ca.MX.sym("U", 1, c)
            xs, _ = step.mapaccum("advance", c)(x0, U)
            self._advance[c] = ca.Function("advance", [x0, U], [xs[:, -1]])
        return self._advance[c]

    def _rest_input(self, y0: float) -> float:
        """The input whose rest output is ``y0`` (secant on the exported model's rest output)."""
        def rest(u):
            return self._rest_output(u) - y0

        size = self.scales_["u_scale"]
        a, b = self.scales_["u_center"], self.scales_["u_center"] + size
        fa, fb = rest(a), rest(b)
        for _ in range(30):
            if fb == fa:
                break
            a, fa, b = b, fb, b - fb * (b - a) / (fb - fa)
            fb = rest(b)
            if abs(b - a) < 1e-10 * size:
                break
        return float(b)

    def __repr__(self) -> str:
        return f"ModelInverse({self.model!r}, window={self.window}, commit={self.commit}, solver={self.solver!r})"


def _is_fitted(model) -> bool:
    return any(hasattr(model, a) for a in ("residual_", "module_", "exported_"))
