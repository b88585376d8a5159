"""Tracking MPC on exported steps: constraints hold, a perfect model tracks, solvers agree."""

import numpy as np
import pytest

from hybrid.export import ExportError, export_model
from hybrid.control import Feedback, MPCSettings, TrackingMPC, reference_signal, rest_output, run_closed_loop
from physics import Series


@pytest.fixture(scope="module")
def model():
    return export_model(Series.from_spec("lag+boucwen+linear"))


@pytest.mark.parametrize("solver", ["sqp", "ipopt", "adjoint-sqp", "fixed-sqp"])
def test_bounds_and_rate_limits_hold(model, solver):
    mpc = TrackingMPC(model, horizon=10, u_bounds=(0.0, 6.0), du_max=0.2, solver=solver)
    u = mpc.solve(model.x0(1.0), [120.0] * 10, u_prev=1.0)  # out of reach upwards
    assert u == pytest.approx(1.2, abs=1e-6)
    u = mpc.solve(model.x0(5.9), [120.0] * 10, u_prev=5.9)
    assert 5.9 <= u <= 6.0 + 1e-9
    u = mpc.solve(model.x0(0.05), [0.0] * 10, u_prev=0.05)
    assert u == pytest.approx(0.0, abs=1e-6)
    assert all(mpc.stats.success)


def test_sqp_and_ipopt_find_the_same_input(model):
    x, ref = model.x0(2.0), np.linspace(rest_output(model, 2.0), rest_output(model, 3.0), 15)
    us = [TrackingMPC(model, u_bounds=(0.0, 6.0), horizon=15, solver=s).solve(x, ref, u_prev=2.0) for s in ("sqp", "ipopt")]
    assert us[0] == pytest.approx(us[1], abs=1e-4)


def test_ipopt_keeps_an_output_bound_out_of_reach_as_a_soft_one(model):
    """A run that starts above its output bound, which the rate limit keeps it from reaching within the horizon:
    with hard rows the NLP has no feasible point (IPOPT ended Infeasible_Problem_Detected or at its iteration limit);
    with a slack per row at an exact penalty it converges and heads for the bound as fast as the rate limit lets it.
    Where the bound can be kept, IPOPT gives the input that sqpmethod's hard bound gives."""
    hi = rest_output(model, 3.0)
    mpc = TrackingMPC(model, horizon=10, u_bounds=(0.0, 6.0), du_max=0.2, solver="ipopt", y_bounds=(None, hi))
    u = mpc.solve(model.x0(5.0), [rest_output(model, 5.0)] * 10, u_prev=5.0)  # the reference above the bound too
    assert mpc.stats.success == [True]
    assert u == pytest.approx(4.8, abs=1e-6)
    x, ref = model.x0(2.0), np.linspace(rest_output(model, 2.0), rest_output(model, 3.5), 15)
    us = [TrackingMPC(model, u_bounds=(0.0, 6.0), horizon=15, solver=s, y_bounds=(None, hi)).solve(x, ref, u_prev=2.0)
          for s in ("sqp", "ipopt")]
    assert us[0] == pytest.approx(us[1], abs=1e-4)


def test_a_perfect_model_tracks_a_reachable_reference(model):
    ref = reference_signal("sine", rest_output(model, 0.5), rest_output(model, 5.5), duration_s=6.0)
    mpc = TrackingMPC(model, u_bounds=(0.0, 6.0), horizon=15, solver="sqp")
    result = run_closed_loop(mpc, model, ref, noise_std_deg=0.0)
    assert result.rmse_deg < 0.5  # deg, over ~65 deg of travel
    assert np.all(result.u >= -1e-9) and np.all(result.u <= 6 + 1e-9)
    assert np.max(np.abs(np.diff(result.u))) <= mpc.du_max + 1e-6
    np.testing.assert_allclose(result.y_model, result.y_true, atol=1e-9)  # same model, no noise
    assert mpc.stats.summary()["solves"] == ref.size


@pytest.mark.parametrize("solver", ["sqp", "ipopt", "adjoint-sqp", "fixed-sqp"])
@pytest.mark.parametrize("reference", ["sine", "steps"])
def test_a_backlash_dead_band_does_not_hold_the_controller(solver, reference):
    """At rest inside a play operator's dead band dy/du = 0, so a gradient method started there
    stays (the controller held u for the whole run: 29-35 deg RMSE); it restarts from the inputs
    whose rest outputs are the reference and keeps the better solution."""
    model = export_model(Series.from_spec("backlash+linear", dt=0.04).set_params(**{"backlash.width": 0.4}))
    ref = reference_signal(reference, rest_output(model, 0.5), rest_output(model, 5.5), duration_s=6.0)
    mpc = TrackingMPC(model, u_bounds=(0.0, 6.0), horizon=15, solver=solver)
    result = run_closed_loop(mpc, model, ref, noise_std_deg=0.0)
    # measured: sine 0.01-0.3 deg, steps ~2 deg (the steps' jumps exceed du_max) over ~57 deg of travel
    assert result.rmse_deg < (0.5 if reference == "sine" else 3.0), result.rmse_deg
    assert np.max(np.abs(np.diff(result.u))) <= mpc.du_max + 1e-6


def test_offset_correction_removes_a_gain_error(model):
    plant = Series.from_spec("lag+boucwen+linear").set_params(**{"linear.offset": 33.0})
    ref = reference_signal("steps", rest_output(model, 1.0), rest_output(model, 5.0), duration_s=6.0, step_s=2.0)
    plain = run_closed_loop(TrackingMPC(model, u_bounds=(0.0, 6.0), horizon=10), plant, ref, noise_std_deg=0.0,
                            feedback=Feedback(correction="none"))
    fixed = run_closed_loop(TrackingMPC(model, u_bounds=(0.0, 6.0), horizon=10), plant, ref, noise_std_deg=0.0)
    tail = slice(-20, None)  # settled on the last step
    assert np.mean(np.abs(plain.y_true[tail] - ref[tail])) > 2.5
    assert np.mean(np.abs(fixed.y_true[tail] - ref[tail])) < 0.3


def test_mpc_works_on_a_bare_casadi_function(model):
    mpc = TrackingMPC(model.step, u_bounds=(0.0, 6.0), horizon=5, solver="sqp")
    assert mpc.model is None and mpc.expand
    assert 0 <= mpc.solve(model.x0(1.0), [45.0]) <= 6
    with pytest.raises(ExportError, match="needs the MPC's model"):
        run_closed_loop(mpc, model, [45.0] * 3)


def test_bad_settings_are_reported(model):
    with pytest.raises(ExportError, match="horizon"):
        TrackingMPC(model, u_bounds=(0.0, 6.0), horizon=0)
    with pytest.raises(ExportError, match="Must be one of"):
        TrackingMPC(model, u_bounds=(0.0, 6.0), solver="magic")
    with pytest.raises(ExportError, match="u_bounds"):
        TrackingMPC(model, u_bounds=(6, 0))
    with pytest.raises(ExportError, match="Unknown reference"):
        reference_signal("zigzag", 0, 1)
    with pytest.raises(ExportError, match="4 entries"):
        TrackingMPC(model, u_bounds=(0.0, 6.0), horizon=3).solve(np.zeros(3), [1.0])
    with pytest.raises(ExportError, match="non-finite entries at \\[1\\]"):
        TrackingMPC(model, u_bounds=(0.0, 6.0), horizon=3).solve(np.array([0.0, np.nan, 0.0, 0.0]), [1.0])


def test_single_and_multiple_shooting_agree(model):
    x, ref = model.x0(2.0), np.linspace(rest_output(model, 2.0), rest_output(model, 3.0), 12)
    us = [TrackingMPC(model, MPCSettings(u_bounds=(0.0, 6.0), horizon=12, solver_options={"shooting": s}))
          .solve(x, ref, u_prev=2.0) for s in ("multiple", "single")]
    assert us[0] == pytest.approx(us[1], abs=1e-4)
    with pytest.raises(ExportError, match="shooting"):
        TrackingMPC(model, MPCSettings(u_bounds=(0.0, 6.0), solver_options={"shooting": "triple"}))


@pytest.fixture(scope="module")
def hybrid(model):
    torch = pytest.importorskip("torch")
    from physics.data import MinMaxScaler
    from hybrid.export import compose_hybrid, export_network
    from hybrid.networks._fnn import BufferMLP

    torch.manual_seed(2)
    net = BufferMLP(1, 5, (8,), 1, "edge").double()
    residual = export_network(net, MinMaxScaler().fit(np.array([[0.0], [6.0]])),
                              MinMaxScaler().fit(np.array([[-6.0], [6.0]])), symbolic="MX")
    return compose_hybrid(export_model(Series.from_spec("lag+boucwen+linear"), symbolic="MX"), residual)


def test_adjoint_sqp_reaches_the_full_models_optimum(hybrid):
    """Hessian from the physics, gradient exact: converged, it solves the hybrid's own problem."""
    x = hybrid.x0(2.0)
    ref = np.linspace(rest_output(hybrid, 2.0), rest_output(hybrid, 3.5), 12)
    auto = TrackingMPC(hybrid, u_bounds=(0.0, 6.0), horizon=12, solver_options={"max_iter": 200, "tol": 1e-7})
    assert auto.solver_name == "adjoint-sqp"
    u_adj = auto.solve(x, ref, u_prev=2.0)
    assert auto.stats.success[-1]
    exact = TrackingMPC(hybrid, u_bounds=(0.0, 6.0), horizon=12, solver="sqp")
    u_sqp = exact.solve(x, ref, u_prev=2.0)
    assert u_adj == pytest.approx(u_sqp, abs=1e-5)
    np.testing.assert_allclose(auto.predicted_output(), exact.predicted_output(), atol=1e-4)
    # the residual matters here: the physics alone would ask for another input
    phys = TrackingMPC(hybrid.approximation, u_bounds=(0.0, 6.0), horizon=12, solver="sqp").solve(x, ref, u_prev=2.0)
    assert abs(phys - u_sqp) > 1e-2


def test_adjoint_sqp_tracks_in_closed_loop(hybrid):
    ref = reference_signal("sine", rest_output(hybrid, 0.5), rest_output(hybrid, 5.5), duration_s=4.0)
    mpc = TrackingMPC(hybrid, u_bounds=(0.0, 6.0), horizon=15)
    result = run_closed_loop(mpc, hybrid, ref, noise_std_deg=0.0)
    assert result.rmse_deg < 0.5
    assert np.max(np.abs(np.diff(result.u))) <= mpc.du_max + 1e-9
    assert np.all(result.u >= -1e-12) and np.all(result.u <= 6 + 1e-12)


@pytest.mark.parametrize("which, iterations, slack", [("model", 1, 0.0), ("hybrid", 3, 0.02)])
def test_fixed_sqp_tracks_as_the_converged_controller(which, iterations, slack, request):
    """A fixed number of iterations per control step, warm-started, tracks as the converged adjoint SQP:
    within 5 % on physics with one iteration (its Hessian is the model's own); on a hybrid whose
    (random, large) network the physics Hessian does not see, three iterations come within 0.02 deg
    (one: 0.50 deg RMSE against 0.008, measured)."""
    m = request.getfixturevalue(which)
    ref = reference_signal("sine", rest_output(m, 1.0), rest_output(m, 5.0), duration_s=4.0)
    runs = {}
    for name, solver, options in (("converged", "adjoint-sqp", {"max_iter": 20}),
                                  ("fixed", "fixed-sqp", {"iterations": iterations})):
        mpc = TrackingMPC(m, u_bounds=(0.0, 6.0), horizon=10, solver=solver, solver_options=options)
        runs[name] = run_closed_loop(mpc, m, ref, noise_std_deg=0.0).rmse_deg
    assert runs["fixed"] <= 1.05 * runs["converged"] + slack, runs


_COUNT_ALLOCATIONS = r"""/* counts the heap allocations of the program it is linked into (gcc -Wl,--wrap=...) */
#include <stdio.h>
#include <stdlib.h>
void *__real_malloc(size_t n);
void *__real_calloc(size_t n, size_t size);
void *__real_realloc(void *p, size_t n);
static long allocations = 0;
void *__wrap_malloc(size_t n) { ++allocations; return __real_malloc(n); }
void *__wrap_calloc(size_t n, size_t size) { ++allocations; return __real_calloc(n, size); }
void *__wrap_realloc(void *p, size_t n) { ++allocations; return __real_realloc(p, n); }
__attribute__((destructor)) static void report(void) { fprintf(stderr, "allocations %ld\n", allocations); }
"""


def test_the_c_controller_of_a_hybrid_runs_as_the_python_one(hybrid, tmp_path):
    """write_controller on a hybrid (physics + an FNN-HIB residual), three SQP iterations: main.c's closed
    loop, built with the Makefile (C99), equals the same loop on the CasADi reference function (each QP solved
    by DAQP from an empty working set there, from the last step's in C: the same optimum to DAQP's
    tolerances, so 1e-6); its control call allocates nothing (the program's allocations do not grow with
    its samples), and it tracks."""
    import re
    import shutil
    import subprocess

    from hybrid.control import write_controller

    if shutil.which("gcc") is None or shutil.which("make") is None:
        pytest.skip("gcc and make are needed to build the C controller")
    mpc = TrackingMPC(hybrid, u_bounds=(0.0, 6.0), horizon=10, solver="fixed-sqp",
                      solver_options={"iterations": 3, "compile": False})
    folder = write_controller(mpc, tmp_path / "ctrl", duration_s=4.0)  # 100 samples at 25 Hz
    assert {"control.c", "control.h", "control_config.h", "daqp"} <= {p.name for p in folder.iterdir()}
    assert "MIT License" in (folder / "daqp" / "LICENSE").read_text()
    subprocess.run(["make", "-s", "-C", str(folder), "CFLAGS=-O1"], check=True, capture_output=True)
    ran = subprocess.run([str(folder / "closed_loop")], capture_output=True, text=True, check=True)
    c_loop = np.loadtxt(ran.stdout.splitlines())
    assert c_loop.shape == (100, 3) and re.search(r"control us: median \S+ p99", ran.stderr)
    u0 = 0.5  # a twelfth inside the bounds, as main.c
    ref = reference_signal("sine", rest_output(hybrid, u0), rest_output(hybrid, 5.5), duration_s=4.4,
                           dt=hybrid.dt)
    x, u_prev, rows = hybrid.x0(u0), u0, []
    for k in range(c_loop.shape[0]):
        u = mpc.solve(x, ref[k:k + 10], u_prev=u_prev)
        x, y = hybrid.step(x, u)
        x, u_prev = np.asarray(x, dtype=float).ravel(), u
        rows.append((k, u, float(y)))
    np.testing.assert_allclose(c_loop, np.array(rows), rtol=0, atol=1e-6)
    assert np.sqrt(np.mean((c_loop[25:, 2] - ref[25:100]) ** 2)) < 1.0  # deg
    # no allocation per control step: the same count for 100 and 300 samples
    (folder / "count.c").write_text(_COUNT_ALLOCATIONS)
    main_c = (folder / "main.c").read_text()
    counts = []
    for steps in (100, 300):
        (folder / "main.c").write_text(main_c.replace("#define STEPS 100", f"#define STEPS {steps}"))
        subprocess.run(["gcc", "-O1", "-std=c99", "-I.", "-Idaqp", "-o", "counted", "main.c", "control.c",
                        "controller.c", *sorted(str(p.relative_to(folder)) for p in (folder / "daqp").glob("*.c")),
                        "count.c", "-Wl,--wrap=malloc,--wrap=calloc,--wrap=realloc", "-lm"],
                       cwd=folder, check=True, capture_output=True)
        err = subprocess.run([str(folder / "counted")], capture_output=True, text=True, check=True).stderr
        counts.append(int(re.search(r"allocations (\d+)", err).group(1)))
    assert counts[0] == counts[1] > 0, counts


def test_the_estimator_of_a_hybrid_fits_its_physics_states_and_offset(hybrid):
    from hybrid.control import MovingHorizonEstimator

    u = 3.0 + 2.0 * np.sin(np.linspace(0, 12, 200))
    y = hybrid.simulate(u) + 3.0
    mhe = MovingHorizonEstimator(hybrid, window=30, u_bounds=(0.0, 6.0), compile=False)
    assert [hybrid.state_names[i] for i in mhe.states] == ["physics.lag.position", "physics.boucwen.z"]
    y_hat = mhe.filter(u, y, measure_every=10)
    assert np.sqrt(np.mean((y_hat - y)[60:] ** 2)) < 0.1 and mhe.offset_ == pytest.approx(3.0, abs=0.05)
