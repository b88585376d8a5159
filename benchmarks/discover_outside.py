"""Discovery on effects made outside the block library, at any scale and rate.

Each dataset is simulated by plain NumPy models written here, not by ``physics`` blocks:
Duhem-type and Prandtl-Ishlinskii (weighted play operators) hysteresis, Preisach with random
weights, an exact first-order lag, a pure delay, a cubic stiffness, and combinations (lag +
hysteresis, backlash + hysteresis). Input and output get random units (scales 1e-6 to 1e3),
the rate is random in 100-1000 Hz, and a share of datasets has jittered time stamps that are
resampled to a uniform grid first (``Trajectory.from_raw``). Discovery starts from ``linear``.

Reported: exact naming (named effects equal the expected ones), false positives (an effect
named that is not there), crashes, and time per dataset.

    .venv/bin/python benchmarks/discover_outside.py --n 200 --seed 0 [--out results.json]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import traceback
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from identification import discover  # noqa: E402
from physics.data import Trajectory  # noqa: E402


# -- truths, in NumPy -------------------------------------------------------------------
def play(u: np.ndarray, r: float) -> np.ndarray:
    """Play operator of half-width ``r`` starting centred."""
    y, out = u[0], np.empty_like(u)
    for k, v in enumerate(u):
        y = min(max(y, v - r), v + r)
        out[k] = y
    return out


def prandtl_ishlinskii(u, span, rng):
    radii = np.linspace(0.05, 0.4, 6) * span
    w = rng.uniform(0.2, 1.0, radii.size)
    return sum(wi * play(u, r) for wi, r in zip(w, radii)) / w.sum()


def duhem(u, span, rng):
    """dz = a |du| (c u - z) + b du: a smooth loop that saturates (Duhem-type, not Bouc-Wen)."""
    a, b, c = rng.uniform(2, 6) / span, rng.uniform(0.2, 0.6), 1.0
    z, out = 0.0, np.empty_like(u)
    for k in range(u.size):
        du = u[k] - u[k - 1] if k else 0.0
        z += a * abs(du) * (c * u[k] - z) + b * du
        out[k] = z
    return out


def preisach(u, span, rng):
    lo, hi = INPUT_RANGE[0] - 0.05 * span, INPUT_RANGE[1] + 0.05 * span
    m = 12
    alpha = rng.uniform(lo, hi, (m, m))
    beta = alpha - np.abs(rng.normal(0, 0.25 * span, (m, m)))
    w = rng.uniform(0, 1, (m, m))
    state = np.where(u[0] >= alpha, 1.0, 0.0)
    out = np.empty_like(u)
    for k, v in enumerate(u):
        state = np.where(v >= alpha, 1.0, np.where(v <= beta, 0.0, state))
        out[k] = lo + (hi - lo) * np.sum(w * state) / w.sum()
    return out


def lag(u, dt, tau):
    a = np.exp(-dt / tau)
    y, out = u[0], np.empty_like(u)
    for k, v in enumerate(u):
        y = a * y + (1 - a) * v
        out[k] = y
    return out


def delay(u, dt, seconds):
    d = max(1, int(round(seconds / dt)))
    return np.concatenate([np.full(d, u[0]), u[:-d]])


#: Range of the input of every run (1 + e^(-tau t)(sin + c), c in {1, 0, -1}), and its span: every
#: run of a dataset goes through the same truth, so its shapes are set from these, not per run.
INPUT_RANGE = (-1.0, 3.0)
SPAN = INPUT_RANGE[1] - INPUT_RANGE[0]

HYSTERESIS = {"duhem": duhem, "prandtl_ishlinskii": prandtl_ishlinskii, "preisach": preisach}
CASES = {  # name -> expected effects
    "duhem": {"hysteresis"}, "prandtl_ishlinskii": {"hysteresis"}, "preisach": {"hysteresis"},
    "lag": {"actuator_lag"}, "delay": {"time_delay"}, "cubic": {"static_nonlinearity"},
    "lag+duhem": {"actuator_lag", "hysteresis"}, "backlash+prandtl_ishlinskii": {"backlash", "hysteresis"},
    "none": set(),
}


def dataset(case: str, rng: np.random.Generator):
    rate = float(rng.uniform(100, 1000))
    dt = 1 / rate
    su, sy = 10.0 ** rng.uniform(-6, 3), 10.0 ** rng.uniform(-6, 3)
    jitter = rng.random() < 0.3
    truth_seed, tau_lag, delay_s = int(rng.integers(1 << 30)), rng.uniform(0.05, 0.25), rng.uniform(0.03, 0.15)
    runs = []
    for f, c in ((0.3, 1.0), (0.7, 0.0), (1.5, -1.0)):
        t = np.arange(0, 5 / f, dt)
        tau = f * np.log(7 / 6)
        u = np.exp(-tau * t) * (np.sin(2 * np.pi * f * t - np.pi / 2) + c) + 1.0
        x, span = u.copy(), SPAN
        parts = case.split("+")
        if "lag" in parts:
            x = lag(x, dt, tau_lag if "lag" == case else 0.15)
        if "delay" in parts:
            x = delay(x, dt, delay_s)
        if "backlash" in parts:
            x = play(x, 0.08 * span)
        for name in parts:
            if name in HYSTERESIS:
                x = 0.5 * x + 0.5 * HYSTERESIS[name](x, span, np.random.default_rng(truth_seed))
        if "cubic" in parts:  # one static map for every run: about the middle of all inputs (1.0)
            x = x + 0.6 * (x - 1.0) ** 3 / 4.0
        y = 10.0 * x + 30.0
        noise = 0.02 * np.std(y)
        y = y + rng.normal(0, noise, y.size)
        if jitter:
            tj = t + rng.uniform(-0.2, 0.2, t.size) * dt
            order = np.argsort(tj)
            traj = Trajectory.from_raw(tj[order], u[order] * su, y[order] * sy, rate_hz=rate, source=f"{case} {f} Hz")
        else:
            traj = Trajectory(t, u * su, y * sy, source=f"{case} {f} Hz")
        runs.append(traj)
    return runs, {"rate_hz": rate, "su": su, "sy": sy, "jitter": jitter}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=27)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path)
    args = parser.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    names = list(CASES)
    rows = []
    for i in range(args.n):
        case = names[i % len(names)]
        runs, info = dataset(case, rng)
        t0 = time.perf_counter()
        try:
            named = set(discover(runs).named_effects)
            error = None
        except Exception as exc:  # noqa: BLE001 - a crash is a result here
            named, error = set(), f"{type(exc).__name__}: {exc}"
            traceback.print_exc()
        row = {"case": case, "expected": sorted(CASES[case]), "named": sorted(named), "error": error,
               "exact": error is None and named == CASES[case], "false": sorted(named - CASES[case]),
               "seconds": round(time.perf_counter() - t0, 1), **info}
        rows.append(row)
        print(f"{i:3d} {case:30s} named {row['named']} {'ok' if row['exact'] else 'MISS'} "
              f"{row['seconds']:5.1f}s rate {info['rate_hz']:.0f} Hz su {info['su']:.1e} sy {info['sy']:.1e}"
              f"{' jitter' if info['jitter'] else ''}{' ' + error if error else ''}", flush=True)
    n = len(rows)
    summary = {"n": n, "exact": sum(r["exact"] for r in rows) / n,
               "false_positive": sum(bool(r["false"]) for r in rows) / n,
               "crashes": sum(r["error"] is not None for r in rows),
               "per_case": {c: f"{sum(r['exact'] for r in rows if r['case'] == c)}/"
                               f"{sum(r['case'] == c for r in rows)}" for c in names},
               "median_seconds": float(np.median([r["seconds"] for r in rows]))}
    print(json.dumps(summary, indent=1))
    if args.out:
        args.out.write_text(json.dumps({"summary": summary, "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
