"""Synthetic data for the identification tests, made by models with known parameters."""

from types import SimpleNamespace

import numpy as np

from physics import Series

DT = 0.04
NOISE_DEG = 0.15
TRUTH = {
    "lag+boucwen+linear": {"lag.time_constant_s": 0.15, "boucwen.A": 0.5, "boucwen.beta": 1.0,
                           "boucwen.gamma": 0.4, "linear.gain": 10.0, "linear.offset": 30.0},
    "backlash+linear": {"backlash.width": 0.4, "linear.gain": 10.0, "linear.offset": 30.0},
}


def decaying(f: float, c: float, offset: float, cycles: float = 3, dt: float = DT):
    """The paper's decaying sinusoid 3 e^(-tau t)(sin(2 pi f t - pi/2) + c) + offset."""
    t = np.arange(0, cycles / f, dt)
    tau = f * np.log(7 / 6)
    return t, 3 * np.exp(-tau * t) * (np.sin(2 * np.pi * f * t - np.pi / 2) + c) + offset


def make_runs(model: Series, noise: float, seed: int = 0, cycles: float = 3,
              settings=((0.2, 1, 0), (0.35, 0, 3), (0.5, -1, 6))):
    """Trajectories (objects with time, u, y) simulated by ``model`` plus Gaussian noise."""
    rng = np.random.default_rng(seed)
    runs = []
    for f, c, off in settings:
        t, u = decaying(f, c, off, cycles, model.dt)
        y = model.simulate(u) + noise * rng.standard_normal(u.size)
        runs.append(SimpleNamespace(time=t, u=u, y=y, meta={"frequency_hz": f}))
    return runs


def write_csv(path, run) -> str:
    """A run of :func:`make_runs` as a ``time,u,y`` CSV file (every digit kept); returns the path."""
    lines = ["time,u,y"] + [f"{t:.17g},{u:.17g},{y:.17g}" for t, u, y in zip(run.time, run.u, run.y)]
    path.write_text("\n".join(lines) + "\n")
    return str(path)


def drifting_runs(truth: Series, n: int, noise: float, seed: int = 3) -> list:
    """Four runs (0.15-0.45 Hz) of a decaying sine on a slow drift, each with its own phase, simulated by
    ``truth`` at its rate plus Gaussian noise of std ``noise``; sources ``r0`` to ``r3``."""
    from physics.data import Trajectory

    rng = np.random.default_rng(seed)
    runs = []
    for i, f in enumerate((0.15, 0.25, 0.35, 0.45)):
        t = np.arange(n) * truth.dt
        u = 1.5 + np.sin(2 * np.pi * f * t) * np.exp(-0.05 * t) + 0.3 * np.sin(2 * np.pi * 0.05 * t + i)
        runs.append(Trajectory(t, u, truth.simulate(u) + rng.normal(0, noise, u.size), source=f"r{i}"))
    return runs


def truth_model(spec: str) -> Series:
    return Series.from_spec(spec, dt=DT).set_params(**TRUTH[spec])


def assert_torch_paths_equal_casadi(model: Series, x, u, path, rtol: float = 1e-12, atol: float = 1e-12) -> None:
    """A block's torch paths against its CasADi graph: the batched step at states ``x`` (B, n_x) and
    inputs ``u`` (B, 1), and the rollout along ``path`` with its parameter gradient."""
    import casadi as ca
    import torch

    from physics import torch_expression, torch_function

    step, tstep = model.step_function(), torch_expression(model.step_function())
    xn, y = tstep(torch.tensor(x), torch.tensor(u), torch.tensor(np.tile(model.params, (len(x), 1))))
    for i in range(len(x)):
        xr, yr = step(x[i], u[i], model.params)
        np.testing.assert_allclose(xn[i].numpy(), np.asarray(xr).ravel(), rtol=rtol, atol=atol)
        np.testing.assert_allclose(y[i].numpy(), np.asarray(yr).ravel(), rtol=rtol, atol=atol)
    rollout = torch_function(model.rollout(path.size))
    p = torch.tensor(model.params, requires_grad=True)
    _, yt = rollout(torch.tensor(model.steady_state(path[0])), torch.tensor(path[None, :]), p)
    np.testing.assert_allclose(yt.detach().numpy().ravel(), model.simulate(path), rtol=rtol, atol=atol)
    yt.sum().backward()
    xs, us, ps = ca.MX.sym("x0", model.n_x), ca.MX.sym("u", 1, path.size), ca.MX.sym("p", model.n_p)
    jac = ca.Function("j", [xs, us, ps], [ca.jacobian(ca.sum2(model.rollout(path.size)(xs, us, ps)[1]), ps)])
    np.testing.assert_allclose(p.grad.numpy(), np.asarray(jac(model.steady_state(path[0]), path[None, :],
                                                              model.params)).ravel(), rtol=1e-9, atol=1e-9 * atol)


def piezo_runs(freqs=(2.0, 5.0, 8.0, 3.5), rate: float = 1000.0, y_unit: float = 1.0) -> list:
    """A piezo-like play in volts -> metres (times ``y_unit``) at ``rate`` Hz: a 15 V backlash, a
    1e-7 m/V gain, decaying cosines 5-145 V at ``freqs`` Hz, 2e-8 m of noise, seeded."""
    from physics import Backlash, LinearMap
    from physics.data import Trajectory

    truth = Series(Backlash(smoothing=0.75), LinearMap(), dt=1 / rate)
    truth.params = [15.0, 0.0, 1e-7 * y_unit, 0.0]  # width (V), start, gain, offset
    rng = np.random.default_rng(0)
    runs = []
    for f in freqs:
        t = np.arange(int(3 * rate / f)) / rate
        u = 75 - 70 * np.cos(2 * np.pi * f * t) * np.exp(-0.2 * f * t)
        runs.append(Trajectory(t, u, truth.simulate(u) + rng.normal(0, 2e-8 * y_unit, t.size)))
    return runs
