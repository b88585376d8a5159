"""Discovery on effects made outside the block library, at any scale and rate.

Each dataset is simulated by plain NumPy models written here, not by ``physics`` blocks:
Duhem-type and Prandtl-Ishlinskii (weighted play operators) hysteresis, Preisach with random
weights, a single play operator (backlash), an exact first-order lag, a pure delay, a cubic
stiffness, creep (slow relaxations), and combinations (lag + Duhem, lag + Preisach, play + Duhem,
play + Prandtl-Ishlinskii; the expected label of the ambiguous ones is in ``EXPECTED_NOTES``). Input and output get random units (scales 1e-6 to 1e3),
the rate is random in 100-1000 Hz, and a share of datasets has jittered time stamps that are
resampled to a uniform grid first (``Trajectory.from_raw``). Discovery starts from ``linear``.

Reported: exact naming (named effects equal the expected ones), false positives (an effect
named that is not in the truth), crashes, time per dataset, per case. Each dataset is seeded by
``(seed, index)``, so shards of one suite run apart and are merged::

    .venv/bin/python benchmarks/discover_outside.py --n 208 --seed 0 [--out results.json]
    .venv/bin/python benchmarks/discover_outside.py --n 208 --shard 0/2 --out a.json   # and 1/2
    .venv/bin/python benchmarks/discover_outside.py --merge a.json b.json
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
    # at rest on the anhysteretic curve at the first input, as the other truths start centred
    # (z = 0 at any first input put a run-dependent transient into the truth)
    z, out = c * u[0], np.empty_like(u)
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


def creep(u, dt):
    """Logarithmic-type creep: a share of the output follows the input through slow lags
    (1, 3 and 10 s), the usual sum-of-relaxations model of piezo and tendon creep."""
    return 0.7 * u + 0.3 * np.mean([lag(u, dt, tau) for tau in (1.0, 3.0, 10.0)], axis=0)


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
#: name -> (expected effects, effects present in the truth). They differ where the truth's
#: structure is not identifiable from input and output (see EXPECTED_NOTES).
CASES = {
    "duhem": ({"hysteresis"},) * 2, "prandtl_ishlinskii": ({"hysteresis"},) * 2,
    "preisach": ({"hysteresis"},) * 2, "play": ({"backlash"},) * 2,
    "lag": ({"actuator_lag"},) * 2, "delay": ({"time_delay"},) * 2,
    "cubic": ({"static_nonlinearity"},) * 2, "creep": ({"creep"},) * 2,
    "lag+duhem": ({"actuator_lag", "hysteresis"},) * 2,
    "lag+preisach": ({"actuator_lag", "hysteresis"},) * 2,
    "play+duhem": ({"backlash", "hysteresis"},) * 2,
    "play+prandtl_ishlinskii": ({"hysteresis"}, {"backlash", "hysteresis"}),
    "none": (set(), set()),
}
EXPECTED_NOTES = {
    "play+prandtl_ishlinskii": "a play operator of radius r in front of plays of radii r_i is plays of "
                               "radii r + r_i: the whole is one Prandtl-Ishlinskii (hence Preisach) "
                               "operator, so 'hysteresis' alone is the exact answer; naming backlash "
                               "too is not counted as a false positive",
    "creep": "creep (0.7 u plus 0.3 u through lags of 1, 3 and 10 s) is its own effect: it is "
             "expected as 'creep', which only a library with a creep block can name; without one "
             "the case is a miss by construction and is also summarised apart ('nameable')",
}


def expected(case: str) -> tuple[set, set]:
    """Expected effects, and the effects present in the truth (naming these is no false positive)."""
    exp, present = CASES[case]
    return set(exp), set(present) | set(exp)


def nameable(case: str) -> bool:
    """Every expected effect has a block in the library."""
    from physics import EFFECTS
    return set(CASES[case][0]) <= set(EFFECTS)


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
        if "creep" in parts:
            x = creep(x, dt)
        if "lag" in parts:
            x = lag(x, dt, tau_lag if "lag" == case else 0.15)
        if "delay" in parts:
            x = delay(x, dt, delay_s)
        if "play" in parts:
            x = play(x, (0.08 if len(parts) > 1 else 0.05) * span)
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
    parser.add_argument("--only", type=int, nargs="*", help="run these dataset indices only")
    parser.add_argument("--shard", default="0/1", help="k/m: run the indices i with i %% m == k "
                        "(shards of one --n and --seed together make the same suite)")
    parser.add_argument("--cases", nargs="*", help="restrict to these cases")
    parser.add_argument("--merge", type=Path, nargs="*", help="summarise these --out files together")
    args = parser.parse_args(argv)
    names = list(CASES)
    if args.merge:
        rows = [r for f in args.merge for r in json.loads(f.read_text())["rows"]]
        return _summary(sorted(rows, key=lambda r: r["index"]), names, args.out)
    k, m = map(int, args.shard.split("/"))
    rows = []
    for i in range(args.n):
        case = names[i % len(names)]
        if i % m != k or (args.only is not None and i not in args.only) or (args.cases and case not in args.cases):
            continue
        rng = np.random.default_rng([args.seed, i])  # each dataset on its own: shards and --only agree
        runs, info = dataset(case, rng)
        exp, present = expected(case)
        t0 = time.perf_counter()
        try:
            named = set(discover(runs).named_effects)
            error = None
        except Exception as exc:  # noqa: BLE001 - a crash is a result here
            named, error = set(), f"{type(exc).__name__}: {exc}"
            traceback.print_exc()
        row = {"index": i, "case": case, "expected": sorted(exp), "named": sorted(named), "error": error,
               "exact": error is None and named == exp, "false": sorted(named - present),
               "seconds": round(time.perf_counter() - t0, 1), **info}
        rows.append(row)
        print(f"{i:3d} {case:30s} named {row['named']} {'ok' if row['exact'] else 'MISS'} "
              f"{row['seconds']:5.1f}s rate {info['rate_hz']:.0f} Hz su {info['su']:.1e} sy {info['sy']:.1e}"
              f"{' jitter' if info['jitter'] else ''}{' ' + error if error else ''}", flush=True)
    return _summary(rows, names, args.out)


def _summary(rows, names, out) -> int:
    n = len(rows)
    named_ok = [r for r in rows if nameable(r["case"])]
    summary = {"n": n, "exact": sum(r["exact"] for r in rows) / n,
               "n_nameable": len(named_ok),
               "exact_nameable": sum(r["exact"] for r in named_ok) / max(len(named_ok), 1),
               "false_positive": sum(bool(r["false"]) for r in rows) / n,
               "crashes": sum(r["error"] is not None for r in rows),
               "per_case": {c: f"{sum(r['exact'] for r in rows if r['case'] == c)}/"
                               f"{sum(r['case'] == c for r in rows)}" for c in names
                            if any(r['case'] == c for r in rows)},
               "false_per_case": {c: sum(bool(r["false"]) for r in rows if r["case"] == c) for c in names
                                  if any(r['case'] == c for r in rows)},
               "median_seconds": float(np.median([r["seconds"] for r in rows]))}
    print(json.dumps(summary, indent=1))
    if out:
        out.write_text(json.dumps({"summary": summary, "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
