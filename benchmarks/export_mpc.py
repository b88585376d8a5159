"""Exported models: time per step (CasADi VM SX/MX, compiled C, torch eager) and MPC on them.

Run: ``.venv/bin/python benchmarks/export_mpc.py [--quick]`` (about 4-6 minutes on 2 cores;
``--quick`` skips the LSTM MPC and shortens the runs). Prints two tables:

1. Time per step of an LSTM (2 x 64, carried state) and a hybrid (lag+boucwen+linear
   plus an LSTM 2 x 64 residual): CasADi VM per call from Python and amortised over
   ``mapaccum(1000)``, compiled C (``hybrid.export.codegen``: gcc -O3) of the SX and of
   the MX export timed inside a C loop, the MX one also per call through
   ``casadi.external``, and torch eager (``FlaggedLSTM.step``, float32, no_grad).
2. MPC (horizon 25) against the virtual catheter's truth with 0.15 deg noise: solve
   time per control step (median, p99, worst) and tracking RMSE (also for the fixed-sqp
   controller, 1 iteration, and for the converged adjoint SQP it is compared with), for physics only (sqp +
   qrqp on the full NLP), hybrids with an FNN-HIB and an LSTM 2 x 64 residual
   (adjoint-sqp: exact gradient, physics Gauss-Newton Hessian, compiled) and the
   pure LSTM (sqp; slow, for its tracking RMSE); beside them open-loop feed-forward
   through learned inverse networks (FNN-HIB, LSTM window mode).

3. The moving-horizon estimator's compiled update (median, p99) per model, and the closed loop
   with a measurement every second on a model fitted on the 0 BL runs, the reference elsewhere.
4. The C controller (``hyst export --controller``, its QP solved by DAQP): one control step from
   Python (the compiled step) and in C (the generated ``closed_loop`` program, per sample), as a
   ratio, the control call alone as ``closed_loop`` times it around each call (median, p99, worst),
   and the estimator's update in C the same way, each built with ``-O2``, ``-O3`` and ``-O3 -march=native``
   (the generated Makefile's default where the compiler takes ``-march=native``, else ``-O3``). acados is timed beside it only where ``acados_template`` is installed (it is
   not on the machine this was written on: see the table's last line).

The MPC table also tracks a ``lag+boucwen+linear`` fitted to the catheter's set 1 (``../shared/data``;
skipped with a message where it is absent) with the fixed-iteration controller, on that model itself.

The networks are trained briefly on the virtual catheter's paper protocol (a quick
fit, not the paper's 500 epochs): their accuracy is not the point here, timing is.
"""

from __future__ import annotations

import argparse
import subprocess
import tempfile
import time
from pathlib import Path

import casadi as ca
import numpy as np
import torch

from hybrid.export import compose_hybrid, export_model, export_network, has_compiler, load_compiled
from hybrid.control import Feedback, MPCSettings, TrackingMPC, reference_signal, rest_output, run_closed_loop
from hybrid.export._codegen import CFLAGS, codegen
from physics import Series

C_LOOP = r"""
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include "step.h"
int main(int argc, char** argv) {
  long n = atol(argv[1]);
  casadi_int sz_arg, sz_res, sz_iw, sz_w;
  step_work(&sz_arg, &sz_res, &sz_iw, &sz_w);
  const casadi_real** arg = malloc(sz_arg * sizeof(*arg)); casadi_real** res = malloc(sz_res * sizeof(*res));
  casadi_int* iw = malloc((sz_iw + 1) * sizeof(*iw)); casadi_real* w = malloc((sz_w + 1) * sizeof(*w));
  int nx = step_sparsity_in(0)[0];
  casadi_real* x = calloc(nx + 1, sizeof(*x)); casadi_real* xn = calloc(nx + 1, sizeof(*xn));
  casadi_real u = 0, y = 0, acc = 0;
  arg[0] = x; arg[1] = &u; res[0] = xn; res[1] = &y;
  struct timespec a, b; clock_gettime(CLOCK_MONOTONIC, &a);
  for (long k = 0; k < n; ++k) {
    u = 3.0 + 2.5 * ((k % 200) / 100.0 - 1.0);
    step(arg, res, iw, w, 0);
    casadi_real* t = x; x = xn; xn = t; arg[0] = x; res[0] = xn; acc += y;
  }
  clock_gettime(CLOCK_MONOTONIC, &b);
  printf("%.6f %g\n", ((b.tv_sec - a.tv_sec) * 1e9 + (b.tv_nsec - a.tv_nsec)) / n / 1e3, acc);
  return 0;
}
"""


def best_of(fn, repeats=5, number=200):
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(number):
            fn()
        times.append((time.perf_counter() - t0) / number)
    return min(times) * 1e6  # us


def train(network, split, epochs, stride):
    from hybrid.learning import LearnedModel, TrainingSettings

    model = LearnedModel(network, training=TrainingSettings(epochs=epochs, stride=stride, progress=False, threads=2))
    return model.fit(split.train)


def c_loop_us(step, directory):
    """Microseconds per step of the generated C, called in a C loop (the flags of ``codegen``)."""
    codegen(step, directory, name="step", compile=False)
    (directory / "loop.c").write_text(C_LOOP)
    exe = directory / "loop"
    flags = [f for f in CFLAGS if f not in ("-fPIC", "-shared")]
    subprocess.run(["gcc", *flags, str(directory / "loop.c"), str(directory / "step.c"), "-o", str(exe), "-lm"],
                   check=True, cwd=directory)
    out = subprocess.run([str(exe), "20000"], capture_output=True, text=True, check=True).stdout.split()
    return float(out[0])


def step_table(name, learned, physics_series, tmp):
    """Rows of timing (us per step) for the LSTM or the hybrid built on it."""
    module = learned.module_
    sx = export_model(learned, mode="carried", symbolic="SX")
    mx = export_model(learned, mode="carried", symbolic="MX")
    physics = export_model(physics_series)
    if name == "hybrid":
        sx, mx = compose_hybrid(physics, sx), compose_hybrid(export_model(physics_series, symbolic="MX"), mx)
    x0 = sx.x0(3.0)
    rows = {}
    for label, m in (("CasADi VM, SX", sx), ("CasADi VM, MX", mx)):
        rows[label + " (per call)"] = best_of(lambda: m.step(x0, 3.0))
        n = 1000
        roll = m.step.mapaccum("acc", n)
        u = np.full((1, n), 3.0)
        rows[label + " (mapaccum 1000)"] = best_of(lambda: roll(x0, u), repeats=3, number=3) / n
    if has_compiler():
        for label, m in (("SX", sx), ("MX", mx)):
            t0 = time.perf_counter()
            lib = codegen(m.step, tmp / name / label, name="step")
            compile_s = time.perf_counter() - t0
            rows[f"compiled C, {label} (C loop)"] = c_loop_us(m.step, tmp / name / label)
            print(f"  [{name} {label}: gcc took {compile_s:.1f} s; "
                  f"C file {(tmp / name / label / 'step.c').stat().st_size / 1e6:.1f} MB]")
        f = load_compiled(lib)
        rows["compiled C, MX (casadi.external per call)"] = best_of(lambda: f(x0, 3.0))
    state = module.initial_state(torch.zeros(1), mode="carried")
    x = torch.tensor([0.5])
    if name == "hybrid":
        pstep, px = physics.step, physics.x0(3.0)

        def torch_step():
            nonlocal state
            _, yp = pstep(px, 3.0)  # the physics half, as the hybrid must
            state, y = module.step(state, x)
    else:
        def torch_step():
            nonlocal state
            state, y = module.step(state, x)
    rows["torch eager (float32, per call)"] = best_of(torch_step)
    return rows


def mpc_row(label, model, plant, duration, horizon=25, solver="auto", **options):
    ref = reference_signal("sine", rest_output(model, 0.5), rest_output(model, 5.5), duration_s=duration)
    t0 = time.perf_counter()
    mpc = TrackingMPC(model, MPCSettings(u_bounds=(0.0, 6.0), horizon=horizon, solver=solver, solver_options=options or None))
    build = time.perf_counter() - t0
    label = f"{label} [{mpc.shooting[0]}s, {mpc.solver_name}]"
    res = run_closed_loop(mpc, plant, ref, noise_std_deg=0.15, seed=0)
    s = mpc.stats.summary()
    return (f"{label:<62} {model.n_x:>4} {build:>7.1f} {s['median_ms']:>9.2f} {s['p99_ms']:>9.2f} {s['max_ms']:>8.2f} "
            f"{s['mean_iterations']:>6.1f} {s['success_rate']:>6.2f} {res.rmse_deg:>8.3f}  ({ref.size} steps)")


def feedforward_row(label, inverse, plant, reference_model, duration, seed=0):
    """Open loop: the reference through a learned inverse network, clipped to the travel, into the plant."""
    ref = reference_signal("sine", rest_output(reference_model, 0.5), rest_output(reference_model, 5.5),
                           duration_s=duration)
    u = np.clip(inverse.predict(ref), 0.0, 6.0)
    y = export_model(plant).simulate(u) + np.random.default_rng(seed).normal(0, 0.15, u.size)
    rmse = float(np.sqrt(np.mean((y - ref) ** 2)))
    return f"{label:<62} {'':>4} {'':>7} {'':>9} {'':>9} {'':>8} {'':>6} {'':>6} {rmse:>8.3f}  ({ref.size} steps)"


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="skip the LSTM MPC, shorter runs")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    from hybrid import HybridModel, TrainingSettings
    from identification import identify
    from hybrid.networks import FNNHIBNet, LSTMNet
    from physics.virtual import VirtualCatheter, paper_protocol

    catheter = VirtualCatheter()
    split = paper_protocol(catheter, frequencies=(0.1, 0.5), tests=(0.45,))
    t0 = time.perf_counter()
    lstm = train(LSTMNet(hidden=64, layers=2, mode="carried"), split, epochs=2, stride=16)
    hib = train(FNNHIBNet(buffer=50), split, epochs=20, stride=4)
    print(f"(trained LSTM 2x64 and FNN-HIB briefly in {time.perf_counter() - t0:.0f} s)")

    physics_series = Series.from_spec("lag+boucwen+linear")
    physics = export_model(physics_series)
    print("\n== time per step (microseconds) ==")
    with tempfile.TemporaryDirectory() as tmp:
        for name in ("lstm", "hybrid"):
            rows = step_table(name, lstm, physics_series, Path(tmp))
            torch_us = rows["torch eager (float32, per call)"]
            print(f"-- {name} (LSTM 2x64{' + lag+boucwen+linear' if name == 'hybrid' else ''})")
            for k, v in rows.items():
                print(f"  {k:<42} {v:>10.2f} us   torch/this = {torch_us / v:6.1f}x")

    plant = catheter.truth_model()
    duration = 8.0 if args.quick else 20.0
    t0 = time.perf_counter()
    fit = identify(Series.from_spec("lag+boucwen+linear", dt=split.train[0].dt), list(split.train))
    physics = export_model(fit.model())  # what a user would control with: the identified physics
    hybrids = {name: HybridModel(fit, residual=net, training=TrainingSettings(epochs=epochs, stride=stride,
                                                                             progress=False, threads=1)).fit(split.train)
               for name, net, epochs, stride in (("fnn-hib", FNNHIBNet(buffer=50), 20, 4),
                                                 ("lstm", LSTMNet(hidden=64, layers=2, mode="carried"), 2, 16))}
    print(f"\n(identified lag+boucwen+linear and trained the hybrids' residuals briefly on it "
          f"in {time.perf_counter() - t0:.0f} s)")
    print("\n== MPC, horizon 25, sine reference, virtual catheter plant (0.15 deg noise) ==")
    print("(ms/ss = multiple/single shooting; conv = share of solves that met the tolerance)")
    print("(fixed-sqp: a fixed number of SQP iterations, the same cost every step; 1 = real-time iteration)")
    print(f"{'model':<62} {'n_x':>4} {'build_s':>7} {'median_ms':>9} {'p99_ms':>9} {'max_ms':>8} {'iters':>6} "
          f"{'conv':>6} {'RMSE_deg':>8}")
    print(mpc_row("physics lag+boucwen+linear (identified)", physics, plant, duration))
    print(mpc_row("physics, converged (adjoint-sqp, max_iter 20)", physics, plant, duration, solver="adjoint-sqp",
                  max_iter=20))
    print(mpc_row("physics, fixed-sqp 1 iteration", physics, plant, duration, solver="fixed-sqp", iterations=1))
    print(catheter_row())
    exports = {}
    for name, hybrid in hybrids.items():
        exported = exports[name] = export_model(hybrid, symbolic="MX")  # compact graph: its C compiles in seconds
        print(mpc_row(f"hybrid {name} residual", exported, plant, duration))
        print(mpc_row(f"hybrid {name}, converged (max_iter 20)", exported, plant, duration, max_iter=20))
        print(mpc_row(f"hybrid {name}, fixed-sqp 1 iteration", exported, plant, duration, solver="fixed-sqp",
                      iterations=1))
        print(mpc_row(f"hybrid {name}, fixed-sqp 1 iteration, exact gradient", exported, plant, duration,
                      solver="fixed-sqp", iterations=1, gradient="exact"))
    estimator_table(physics, exports, catheter, plant, split)
    controller_table(physics, exports, Path(tempfile.mkdtemp()))
    from hybrid.learning import LearnedModel, TrainingSettings

    for name, net, epochs, stride in (("FNN-HIB", FNNHIBNet(buffer=50), 20, 4), ("LSTM", LSTMNet(), 5, 8)):
        inverse = LearnedModel(net, direction="inverse", training=TrainingSettings(
            epochs=epochs, stride=stride, progress=False, threads=1)).fit(split.train)
        print(feedforward_row(f"open-loop feed-forward, inverse {name} (quick fit)", inverse, plant, physics,
                              duration))
    # the truth's sharp backlash has a dead band where dy/du = 0: a gradient-based MPC stalls there
    print(mpc_row("truth model (sharp backlash)", export_model(plant), plant, duration))
    if not args.quick:
        print(mpc_row("FNN-HIB pure (buffer 50)", export_model(hib), plant, duration))
        lstm_model = export_model(lstm, mode="carried", symbolic="SX")
        # expanding 25 copies of a 151k-instruction SX step is too slow to build: MX map over SX
        print(mpc_row("LSTM 2x64 pure (carried)", lstm_model, plant, 2.0, expand=False))

def estimator_table(physics, exports, catheter, plant, split) -> None:
    """The moving-horizon estimator: compiled update time, and the closed loop with a measurement
    every second on a model fitted on one baseline while the plant runs over another."""
    from hybrid.control import MovingHorizonEstimator
    from identification import identify
    from physics.virtual import paper_protocol

    print("\n== moving-horizon estimator (window 50, 3 Gauss-Newton iterations, compiled) ==")
    print(f"{'model':<40} {'build_s':>7} {'median_ms':>9} {'p99_ms':>9}")
    for label, model in (("physics lag+boucwen+linear", physics), *((f"hybrid {k}", v) for k, v in exports.items())):
        t0 = time.perf_counter()
        mhe = MovingHorizonEstimator(model, u_bounds=(0.0, 6.0))
        build = time.perf_counter() - t0
        mhe.reset(u0=3.0)
        U = 3.0 + 2.0 * np.sin(np.linspace(0, 6, 50))[None, :]
        Y = np.asarray(model.simulate(U[0]))[None, :]
        mask = (np.arange(50) % 25 == 0)[None, :] * 1.0
        times = []
        for _ in range(200):
            t = time.perf_counter()
            mhe._update(mhe._x_start, 0.0, U, Y, mask)
            times.append(time.perf_counter() - t)
        print(f"{label:<40} {build:>7.1f} {np.median(times) * 1e3:>9.3f} {np.percentile(times, 99) * 1e3:>9.3f}")
    zero = paper_protocol(catheter, frequencies=(0.1, 0.3, 0.5), tests=(0.45,), baselines=("zero",))
    fit = identify(Series.from_spec("lag+boucwen+linear", dt=zero.train[0].dt), list(zero.train))
    model = export_model(fit.model())
    truth = export_model(plant)
    ref = reference_signal("sine", rest_output(truth, 3.0), rest_output(truth, 5.8), duration_s=20.0)
    noise = 0.15
    print(f"\n-- closed loop, model fitted on the 0 BL runs only, reference over 3-5.8 mm, noise {noise} deg --")
    print(f"{'feedback':<44} {'RMSE_deg':>8} {'RMSE/noise':>10}")
    for label, feedback in (("none (model alone)", Feedback(correction="none")),
                            ("every sample (offset filter)", Feedback()),
                            ("every 25 samples = 1 s (estimator)", Feedback(measure_every=25))):
        mpc = TrackingMPC(model, u_bounds=(0.0, 6.0), horizon=25)
        res = run_closed_loop(mpc, plant, ref, noise_std_deg=noise, seed=0, feedback=feedback)
        print(f"{label:<44} {res.rmse_deg:>8.3f} {res.rmse_deg / noise:>10.2f}")


C_CALL = r"""
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include "controller.h"
#define CALLS 2000
static double spent[CALLS];
static int by_value(const void *a, const void *b) {
  double d = *(const double *)a - *(const double *)b;
  return (d > 0) - (d < 0);
}
int main(void) {
%(inputs)s
  casadi_int sz_arg, sz_res, sz_iw, sz_w;
  %(f)s_work(&sz_arg, &sz_res, &sz_iw, &sz_w);
  const casadi_real **arg = malloc((sz_arg + 1) * sizeof(*arg));
  casadi_real **res = malloc((sz_res + 1) * sizeof(*res));
  casadi_int *iw = malloc((sz_iw + 1) * sizeof(*iw));
  casadi_real *w = malloc((sz_w + 1) * sizeof(*w));
  static casadi_real out[%(n_out)d][4096];
  for (int k = 0; k < CALLS; ++k) {
%(set)s
    struct timespec a, b;
    clock_gettime(CLOCK_MONOTONIC, &a);
    if (%(f)s(arg, res, iw, w, 0)) return 1;
    clock_gettime(CLOCK_MONOTONIC, &b);
    spent[k] = (b.tv_sec - a.tv_sec) * 1e6 + (b.tv_nsec - a.tv_nsec) * 1e-3;
  }
  qsort(spent, CALLS, sizeof(*spent), by_value);
  printf("%%.2f %%.2f %%.2f\n", spent[CALLS / 2], spent[(int)(0.99 * (CALLS - 1))], spent[CALLS - 1]);
  return 0;
}
"""


def c_call_us(folder: Path, function, inputs, flags: str, repeats: int = 3) -> tuple[float, float, float]:
    """Median, p99 and worst microseconds of one call of ``function`` (in the folder's ``controller.c``) on
    ``inputs``, timed around each call in C: of the run (of ``repeats``) with the least median."""
    values = [np.asarray(v, dtype=float).ravel(order="F") for v in inputs]
    name = function.name()
    decl = "\n".join(f"  static const casadi_real in{i}[] = {{{', '.join(repr(float(a)) for a in v)}}};"
                      for i, v in enumerate(values))
    sets = " ".join(f"arg[{i}] = in{i};" for i in range(len(values)))
    sets += " " + " ".join(f"res[{i}] = out[{i}];" for i in range(function.n_out()))
    (folder / f"time_{name}.c").write_text(C_CALL % dict(inputs=decl, f=name, n_out=function.n_out(), set="    " + sets))
    subprocess.run(["gcc", *flags.split(), "-std=c99", "-D_XOPEN_SOURCE=600", "-I.", "-o", f"time_{name}",
                    f"time_{name}.c", "controller.c", "-lm"], cwd=folder, check=True, capture_output=True)
    runs = [subprocess.run([str(folder / f"time_{name}")], capture_output=True, text=True, check=True).stdout.split()
            for _ in range(repeats)]
    return min(tuple(float(v) for v in out) for out in runs)


def controller_table(physics, exports, folder: Path) -> None:
    """The C controller (hyst export --controller) against the same control step from Python: the generated
    closed_loop per sample, the control call timed around each call, and the estimator's update in C."""
    from hybrid.control import MovingHorizonEstimator, write_controller

    if not has_compiler():
        print("\n(no gcc: the C controller is not timed)")
        return
    print("\n== C controller (fixed-sqp, 1 iteration, horizon 25; its QP by DAQP): one control step ==")
    print("(python_ms: the compiled step from Python; C: the generated closed_loop; control and estimator in us, "
          "median / p99 / worst, of the run with the least median of three)")
    print(f"{'model':<28} {'CFLAGS':<18} {'python_ms':>9} {'C_ms':>7} {'python/C':>8} {'control_us':>22} "
          f"{'estimator_us':>22}")
    for label, model in (("physics lag+boucwen+linear", physics), *((f"hybrid {k}", v) for k, v in exports.items())):
        model.meta.setdefault("input_range", [0.0, 6.0])
        mpc = TrackingMPC(model, u_bounds=(0.0, 6.0), horizon=25, solver="fixed-sqp", solver_options={"iterations": 1})
        x, ref = model.x0(1.0), np.full(25, rest_output(model, 3.0))
        times = []
        for _ in range(200):
            t = time.perf_counter()
            mpc.solver.control(x, 1.0, ref, np.full(25, 1.0))
            times.append(time.perf_counter() - t)
        py_ms = float(np.median(times) * 1e3)
        mhe = MovingHorizonEstimator(model, u_bounds=(0.0, 6.0), compile=False)
        U = 3.0 + 2.0 * np.sin(np.linspace(0, 6, mhe.window))[None, :]
        mhe_inputs = (model.x0(3.0), 0.0, U, np.asarray(model.simulate(U[0]))[None, :],
                      (np.arange(mhe.window) % 25 == 0)[None, :] * 1.0)
        where = folder / label.replace(" ", "_")
        write_controller(mpc, where, duration_s=20.0, estimator=mhe)
        for flags in ("-O2", "-O3", "-O3 -march=native"):  # the last: the Makefile's default (where gcc takes it)
            subprocess.run(["make", "-s", "-B", "-C", str(where), f"CFLAGS={flags}"], check=True, capture_output=True)
            runs = []  # the best of three runs: on this 2-core VM one core runs the same binary 30 % slower
            for _ in range(3):
                t = time.perf_counter()
                ran = subprocess.run([str(where / "closed_loop")], capture_output=True, text=True, check=True)
                c_ms = (time.perf_counter() - t) * 1e3 / len(ran.stdout.splitlines())  # the program per sample
                # the control call alone, timed in C around each call (main.c's last line on stderr)
                runs.append(([float(v) for v in ran.stderr.split("median")[1].split()[0:5:2]], c_ms))
            control, c_ms = min(runs)
            estimator = c_call_us(where, mhe.function, mhe_inputs, flags)
            fmt = lambda v: " / ".join(f"{a:.0f}" for a in v)  # noqa: E731
            print(f"{label:<28} {flags:<18} {py_ms:>9.3f} {c_ms:>7.3f} {py_ms / c_ms:>8.1f} {fmt(control):>22} "
                  f"{fmt(estimator):>22}")
    import importlib.util

    if importlib.util.find_spec("acados_template") is None:
        print("(acados is not timed beside it: acados_template is not installed; on the machine this was written on, "
              "the package registry has no acados, acados-template or hpipm, and acados's C library builds from "
              "its GitHub sources, which it cannot reach)")
    else:
        print("(acados_template is installed, but this benchmark does not run an acados RTI beside it yet)")


def catheter_row() -> str:
    """fixed-sqp tracking on a lag+boucwen+linear fitted to the catheter's set 1 (the plant is that model)."""
    from identification import identify
    from physics.data import DataNotFoundError, load_preset

    try:
        data = load_preset("catheter_2023")
    except DataNotFoundError as exc:
        return f"(catheter set 1 skipped: {exc})"
    u = np.concatenate([np.ravel(t.u) for t in data.train])
    lo, hi = float(u.min()), float(u.max())
    fit = identify(Series.from_spec("lag+boucwen+linear", dt=data.train[0].dt), list(data.train))
    model = export_model(fit.model())
    model.meta["input_range"] = [lo, hi]
    margin = (hi - lo) / 12
    ref = reference_signal("sine", rest_output(model, lo + margin), rest_output(model, hi - margin), duration_s=20.0)
    mpc = TrackingMPC(model, MPCSettings(u_bounds=(lo, hi), horizon=25, solver="fixed-sqp",
                                         solver_options={"iterations": 1}))
    res = run_closed_loop(mpc, model, ref, noise_std_deg=0.15, seed=0)
    s = mpc.stats.summary()
    label = "catheter set 1 fit (lag+boucwen+linear), fixed-sqp 1 iteration, on itself"
    return (f"{label:<62} {model.n_x:>4} {'':>7} {s['median_ms']:>9.2f} {s['p99_ms']:>9.2f} {s['max_ms']:>8.2f} "
            f"{s['mean_iterations']:>6.1f} {s['success_rate']:>6.2f} {res.rmse_deg:>8.3f}  ({ref.size} steps)")


if __name__ == "__main__":
    main()
