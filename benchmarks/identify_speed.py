"""Wall time of identify() on the seed paper's protocol, and how it grows with data length.

    .venv/bin/python benchmarks/identify_speed.py [--quick]

The data are made here with the truth model (lag+boucwen+linear, 0.15 deg
Gaussian noise): 15 trajectories at 25 Hz, the decaying sinusoids
q(t) = 3 e^(-tau t)(sin(2 pi f t - pi/2) + c) + offset, tau = f ln(7/6),
7 cycles, f in 0.1..0.5 Hz, (c, offset) in (1, 0), (0, 3), (-1, 6). The
scaling rows repeat each trajectory's input k times (k = 1, 2, 4, 8).
Each run starts cold (the compiled sensitivity step is rebuilt), so times
include the C compile (about 0.7 s), the initial-guess grid and the standard
errors; "ipopt s" is IPOPT alone.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from identification import identify  # noqa: E402
from identification import _sensitivity  # noqa: E402
from physics import Series  # noqa: E402

SPEC = "lag+boucwen+linear"
TRUTH = {"lag.time_constant_s": 0.15, "boucwen.A": 0.5, "boucwen.beta": 1.0,
         "boucwen.gamma": 0.4, "linear.gain": 10.0, "linear.offset": 30.0}
NOISE = 0.15
FREQS = (0.1, 0.2, 0.3, 0.4, 0.5)
BASELINES = ((1.0, 0.0), (0.0, 3.0), (-1.0, 6.0))


def protocol(model: Series, repeat: int = 1, seed: int = 0, cycles: int = 7):
    rng = np.random.default_rng(seed)
    runs = []
    for f in FREQS:
        for c, off in BASELINES:
            t = np.arange(0, cycles / f, model.dt)
            u = 3 * np.exp(-f * np.log(7 / 6) * t) * (np.sin(2 * np.pi * f * t - np.pi / 2) + c) + off
            u = np.tile(u, repeat)
            y = model.simulate(u) + NOISE * rng.standard_normal(u.size)
            runs.append(SimpleNamespace(u=u, y=y))
    return runs


def run(repeat: int, starts: int = 1):
    truth = Series.from_spec(SPEC).set_params(**TRUTH)
    runs = protocol(truth, repeat)
    _sensitivity._JIT_CACHE.clear()  # cold start: include the compile
    t0 = time.perf_counter()
    fit = identify(Series.from_spec(SPEC), runs, starts=starts)
    wall = time.perf_counter() - t0
    ipopt = sum(s["wall_time_s"] for s in fit.starts)
    worst = max(abs(fit.parameters[k] / v - 1) for k, v in TRUTH.items())
    within = all(abs(fit.parameters[k] - v) <= 3 * fit.standard_errors[k] for k, v in TRUTH.items())
    return fit, wall, ipopt, worst, within


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="scaling up to 4x only")
    args = parser.parse_args(argv)
    print(f"identify('{SPEC}') on the paper protocol, 15 trajectories, 25 Hz, "
          f"noise {NOISE} deg, jit={_sensitivity.jit_available()}")
    print(f"{'data':>5} {'samples':>8} {'starts':>6} {'total s':>8} {'ipopt s':>8} {'iter':>5} "
          f"{'train RMSE':>10} {'max rel err':>11} {'all in 3 SE':>11} status")
    rows = [(1, 1), (1, 4)] + [(k, 1) for k in ((2, 4) if args.quick else (2, 4, 8))]
    for repeat, starts in rows:
        fit, wall, ipopt, worst, within = run(repeat, starts)
        print(f"{repeat:>4}x {fit.n_samples:>8} {starts:>6} {wall:>8.2f} {ipopt:>8.2f} "
              f"{fit.iterations:>5} {fit.train_rmse:>10.4f} {worst:>11.2%} {str(within):>11} "
              f"{fit.status}")
    print("(time per sample should stay about constant: single shooting is linear in the data)")


if __name__ == "__main__":
    main()
