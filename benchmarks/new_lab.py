"""The default ``hyst fit`` path on data from a lab we do not see (issue 41): simulated new-lab cases.

    nice -n 10 .venv/bin/python benchmarks/new_lab.py --quick [--cases 1,3] [--seed 0]
        [--out results.json] [--keep DIR]

Each case writes its training and test runs as CSV files (``time,u,y``, plus ``volt`` in case 3)
into a temporary folder (``--keep DIR`` keeps them there) and runs the user's command on them,
``hyst fit TRAIN.csv... --test TEST.csv... --out MODEL --no-progress``, with no modelling option
(physics auto, residual auto, the default preset and warm-up). The truths are outside the block
library (plain NumPy, from ``discover_outside.py``) except case 5's virtual catheter:

1. ``slow_loop``       a tendon-driven probe: ONE training run, a single slow up-and-down loop at
                       1 Hz (280 samples), Prandtl-Ishlinskii hysteresis, gain and offset in deg;
                       the test loop has a slightly different amplitude and phase;
2. ``long_random``     TWO training runs of 9,700 samples at 25 Hz (filtered random steps),
                       lag + Duhem; the test is a third such run;
3. ``second_input``    3 + 1 runs at 200 Hz, ``y = hysteresis(u) + k volt`` with ``volt`` a slow
                       independent signal, fitted with ``--input u,volt``;
4. ``rate_500.8``      3 + 1 runs stamped at exactly 1/500.8 s, lag + play;
5. ``virtual``         the virtual catheter's paper protocol (``physics.virtual.paper_protocol``), a subset;
6. ``outside_duhem``   lag + Duhem at a random rate in 100-1000 Hz and random units, 3 + 1 runs.

Peers, scored on the same test samples after the same warm-up window (hyst fit's, as the card's
``_rows``): a linear ARX (``LinearARX``, na = nb = 3, on ``u`` alone, as the card's) fitted on the
training runs, and a static straight line ``y = a u + b`` (``np.polyfit`` on the training runs).
The test RMSE is pooled over the test samples. Target: default <= 1.0x ARX and <= 1.1x line.

``--quick`` shrinks the long cases (case 2 to 1,500 samples a run, fewer cycles elsewhere; cases 1
and 5 are small already); the default path itself has no size option, so both modes fit with it.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from discover_outside import duhem, lag, play, prandtl_ishlinskii  # noqa: E402
from hybrid.experiments._compare import WARMUP  # noqa: E402 - hyst fit's default --warmup
from hybrid.peers import LinearARX  # noqa: E402
from physics.data import Trajectory, load_csvs, rmse, warmup_split  # noqa: E402
from physics.data._atomic import write_json  # noqa: E402

#: Target: the default path's test RMSE at most these multiples of the ARX's and the line's.
ARX_TARGET, LINE_TARGET = 1.0, 1.1
#: The rate of case 4, Hz (time stamps exactly k / RATE_500).
RATE_500 = 500.8


@dataclass
class Runs:
    """A case's simulated runs before they are written: training and test trajectories, the
    options ``hyst fit`` needs to read them (``--input u,volt``) and the rate they were made at."""

    train: list[Trajectory]
    test: list[Trajectory]
    fit_args: list[str] = field(default_factory=list)
    rate_hz: float = 0.0


@dataclass
class CaseFiles:
    """A case written to a folder: the CSV paths and the options of ``hyst fit``."""

    name: str
    train: list[Path]
    test: list[Path]
    fit_args: list[str]
    rate_hz: float


# -- inputs and truths, in NumPy ---------------------------------------------------------
def filtered_steps(n: int, dt: float, rng: np.random.Generator, lo: float, hi: float,
                   hold_s: float = 4.0, tau_s: float = 0.5) -> np.ndarray:
    """Random levels in ``[lo, hi]`` held for exponential times (mean ``hold_s``), through a lag."""
    levels, k = np.empty(n), 0
    while k < n:
        m = max(1, int(rng.exponential(hold_s) / dt))
        levels[k:k + m] = rng.uniform(lo, hi)
        k += m
    return lag(levels, dt, tau_s)


def decaying(t: np.ndarray, f: float, c: float) -> np.ndarray:
    """The seed paper's decaying sinusoid ``e^(-tau t)(sin(2 pi f t - pi/2) + c) + 1``, in [-1, 3]."""
    return np.exp(-f * np.log(7 / 6) * t) * (np.sin(2 * np.pi * f * t - np.pi / 2) + c) + 1.0


def _run(t, u, y, name, **extra) -> Trajectory:
    return Trajectory(t, u, y, source=name, extra=extra)


# -- cases -------------------------------------------------------------------------------
def slow_loop(rng: np.random.Generator, quick: bool) -> Runs:
    """One slow up-and-down loop of tendon displacement (mm) at 1 Hz; tip angle (deg)."""
    truth_seed, noise = int(rng.integers(1 << 30)), 0.1

    def loop(n, amp, phase, name):
        t = np.arange(n, dtype=float)
        u = amp * (1 - np.cos(2 * np.pi * t / (n - 1) + phase)) / 2
        h = prandtl_ishlinskii(u, 5.0, np.random.default_rng(truth_seed))
        return _run(t, u, 9.0 * (0.4 * u + 0.6 * h) + 2.0 + rng.normal(0, noise, n), name)

    return Runs([loop(280, 5.0, 0.0, "loop_train")], [loop(270, 4.6, 0.15, "loop_test")], rate_hz=1.0)


def long_random(rng: np.random.Generator, quick: bool) -> Runs:
    """Filtered random steps at 25 Hz through a lag and Duhem hysteresis."""
    n, dt, truth_seed = 1500 if quick else 9700, 1 / 25, int(rng.integers(1 << 30))

    def run(name):
        t = np.arange(n) * dt
        u = filtered_steps(n, dt, rng, 0.0, 6.0)
        x = lag(u, dt, 0.3)
        x = 0.5 * x + 0.5 * duhem(x, 6.0, np.random.default_rng(truth_seed))
        return _run(t, u, 8.0 * x + 5.0 + rng.normal(0, 0.1, n), name)

    return Runs([run("random_1"), run("random_2")], [run("random_3")], rate_hz=25.0)


def second_input(rng: np.random.Generator, quick: bool) -> Runs:
    """At 200 Hz, ``y = 10 (u/2 + PI(u)/2) + k volt + 30`` with ``volt`` slow random steps (V)."""
    dt, cycles, truth_seed, k = 1 / 200, 2.0 if quick else 5.0, int(rng.integers(1 << 30)), 1.5

    def run(f, c, name):
        t = np.arange(0, cycles / f, dt)
        u = decaying(t, f, c)
        volt = filtered_steps(t.size, dt, rng, 0.0, 5.0, hold_s=3.0, tau_s=1.0)
        x = 0.5 * u + 0.5 * prandtl_ishlinskii(u, 4.0, np.random.default_rng(truth_seed))
        return _run(t, u, 10.0 * x + k * volt + 30.0 + rng.normal(0, 0.1, t.size), name, volt=volt)

    train = [run(f, c, f"volt_{i}") for i, (f, c) in enumerate(((0.3, 1.0), (0.7, 0.0), (1.5, -1.0)))]
    return Runs(train, [run(1.0, 0.5, "volt_test")], ["--input", "u,volt"], 200.0)


def rate_500(rng: np.random.Generator, quick: bool) -> Runs:
    """Time stamps exactly ``k / 500.8`` s; lag (40 ms) then a play of half-width 0.32."""
    cycles = 2.5 if quick else 6.0

    def run(f, c, name):
        t = np.arange(int(round(cycles / f * RATE_500))) / RATE_500
        u = decaying(t, f, c)
        x = play(lag(u, 1 / RATE_500, 0.04), 0.08 * 4.0)
        return _run(t, u, 10.0 * x + 30.0 + rng.normal(0, 0.1, t.size), name)

    train = [run(f, c, f"r500_{i}") for i, (f, c) in enumerate(((1.0, 1.0), (2.0, 0.0), (3.0, -1.0)))]
    return Runs(train, [run(1.5, 0.5, "r500_test")], rate_hz=RATE_500)


def virtual(rng: np.random.Generator, quick: bool) -> Runs:
    """The virtual catheter (lag, hysteresis, backlash at 25 Hz) on a subset of the paper's protocol."""
    from physics.virtual import VirtualCatheter, paper_protocol

    catheter = VirtualCatheter(seed=int(rng.integers(1 << 30)))
    if quick:
        split = paper_protocol(catheter, frequencies=(0.2, 0.3, 0.5), tests=(0.45,), baselines=("mid",))
    else:
        split = paper_protocol(catheter, frequencies=(0.1, 0.3, 0.5), tests=(0.15, 0.45))
    plain = [[_run(r.time, r.u, r.y, r.source) for r in part] for part in (split.train, split.test)]
    return Runs(*plain, rate_hz=catheter.rate_hz)  # the truth's columns are not what a lab measures


def outside_duhem(rng: np.random.Generator, quick: bool) -> Runs:
    """Lag (0.15 s) then Duhem, as ``discover_outside``'s ``lag+duhem``: a rate in 100-1000 Hz and
    random units; quick runs have 2 cycles at frequencies raised so no run passes ~1,700 samples."""
    rate = float(rng.uniform(100, 1000))
    su, sy, truth_seed = 10.0 ** rng.uniform(-3, 3), 10.0 ** rng.uniform(-3, 3), int(rng.integers(1 << 30))
    cycles, speed = (2.0, max(1.0, rate / 250)) if quick else (5.0, 1.0)

    def run(f, c, name):
        f = f * speed
        t = np.arange(0, cycles / f, 1 / rate)
        u = decaying(t, f, c)
        x = lag(u, 1 / rate, 0.15)
        x = 0.5 * x + 0.5 * duhem(x, 4.0, np.random.default_rng(truth_seed))
        y = 10.0 * x + 30.0
        return _run(t, u * su, (y + rng.normal(0, 0.02 * np.std(y), y.size)) * sy, name)

    train = [run(f, c, f"duhem_{i}") for i, (f, c) in enumerate(((0.3, 1.0), (0.7, 0.0), (1.5, -1.0)))]
    return Runs(train, [run(1.0, 0.5, "duhem_test")], rate_hz=rate)


#: Case name -> generator; ``--cases`` takes the names or their numbers (1-based, in this order).
CASES: dict[str, Callable[[np.random.Generator, bool], Runs]] = {
    "slow_loop": slow_loop, "long_random": long_random, "second_input": second_input,
    "rate_500.8": rate_500, "virtual": virtual, "outside_duhem": outside_duhem}


def case_name(key: str | int) -> str:
    """``"3"``, ``3`` or ``"second_input"`` -> ``"second_input"``."""
    names = list(CASES)
    if str(key) in CASES:
        return str(key)
    if str(key).isdigit() and 1 <= int(key) <= len(names):
        return names[int(key) - 1]
    raise ValueError(f"unknown case {key!r}. Must be one of {names} or their numbers 1-{len(names)}.")


def make_case(name: str | int, folder: str | Path, quick: bool = True, seed: int = 0) -> CaseFiles:
    """Simulate case ``name`` (seeded by ``(seed, its number)``) and write its runs as CSV files to
    ``folder/train`` and ``folder/test``."""
    name = case_name(name)
    runs = CASES[name](np.random.default_rng([seed, list(CASES).index(name)]), quick)
    folder = Path(folder)
    paths = {part: [r.to_csv(folder / part / f"{r.source}.csv") for r in getattr(runs, part)]
             for part in ("train", "test")}
    return CaseFiles(name, paths["train"], paths["test"], list(runs.fit_args), runs.rate_hz)


# -- peers and the default path ----------------------------------------------------------
def load_case(case: CaseFiles) -> tuple[list[Trajectory], list[Trajectory]]:
    """The runs as ``hyst fit`` reads them: at the training files' rate, the tests resampled to it."""
    extra = _input_columns(case)[1:]
    train = load_csvs(case.train, extra=extra, check_outliers=True)
    return train, load_csvs(case.test, extra=extra, check_outliers=True, rate_hz=train[0].meta["rate_hz"])


def _input_columns(case: CaseFiles) -> list[str]:
    args = case.fit_args
    return args[args.index("--input") + 1].split(",") if "--input" in args else ["u"]


def pooled(errors: list[tuple[float, int]]) -> float:
    """The RMSE over all samples of runs given as ``(rmse, samples)``."""
    n = sum(k for _, k in errors)
    return math.sqrt(sum(e * e * k for e, k in errors) / n) if n else math.nan


def arx_rmse(train: list[Trajectory], test: list[Trajectory], warmup: int = WARMUP) -> float:
    """``LinearARX(na=3, nb=3)`` fitted on ``train``, free on each test run after its warm-up window."""
    arx = LinearARX(na=3, nb=3).fit(train)
    parts = []
    for t in test:
        window, rest = warmup_split(t, warmup)
        parts.append((rmse(rest.y, arx.predict(rest, **({} if window is None else {"warmup": window}))), rest.n))
    return pooled(parts)


def line_rmse(train: list[Trajectory], test: list[Trajectory], warmup: int = WARMUP) -> float:
    """``y = a u + b`` by least squares on every training sample, scored after each test run's window."""
    a, b = np.polyfit(np.concatenate([t.u for t in train]), np.concatenate([t.y for t in train]), 1)
    parts = []
    for t in test:
        rest = warmup_split(t, warmup)[1]
        parts.append((rmse(rest.y, a * rest.u + b), rest.n))
    return pooled(parts)


def hyst_fit(case: CaseFiles, out: Path) -> tuple[dict | None, str, float]:
    """``hyst fit`` on the case, as a user runs it: ``(card.json or None, error, seconds)``."""
    hyst = Path(sys.executable).with_name("hyst")
    command = [str(hyst), "fit", *map(str, case.train), "--test", *map(str, case.test), "--out", str(out),
               "--no-progress", *case.fit_args]
    env = dict(os.environ)
    for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
        env.setdefault(var, "1")  # the machine is shared: one thread per fit
    t0 = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True, env=env)
    seconds = time.perf_counter() - t0
    if done.returncode != 0:
        lines = [s for s in done.stderr.strip().splitlines() if s.strip()] or [f"exit {done.returncode}"]
        return None, lines[-1][:200], seconds
    return json.loads((out / "card.json").read_text()), "", seconds


def run_case(name: str, folder: Path, quick: bool, seed: int) -> dict:
    case = make_case(name, folder / "data", quick=quick, seed=seed)
    train, test = load_case(case)
    card, error, seconds = hyst_fit(case, folder / "model")
    row = {"case": name, "n_train": len(train), "samples": sum(t.n for t in train),
           "test_samples": sum(t.n for t in test), "rate_hz": train[0].meta["rate_hz"],
           "physics": "", "residual": "", "default": math.nan, "card_arx": math.nan,
           "arx": arx_rmse(train, test), "line": line_rmse(train, test), "seconds": round(seconds, 1),
           "error": error}
    if card is not None:
        tests = [r for r in card["rows"] if r["set"] == "test"]
        n = [t.n - WARMUP for t in test]
        row.update(physics=card["spec"], residual=card["residual"],
                   default=pooled([(r["model_rmse"], k) for r, k in zip(tests, n)]),
                   card_arx=pooled([(r["arx_rmse"], k) for r, k in zip(tests, n)]))
    row["vs_arx"], row["vs_line"] = row["default"] / row["arx"], row["default"] / row["line"]
    row["met"] = bool(row["vs_arx"] <= ARX_TARGET and row["vs_line"] <= LINE_TARGET)
    return row


# -- table -------------------------------------------------------------------------------
HEADER = (f"{'case':14s} {'runs':>4s} {'samples':>8s} {'rate Hz':>8s} {'physics':24s} {'residual':8s} "
          f"{'default':>9s} {'ARX':>9s} {'line':>9s} {'/ARX':>6s} {'/line':>6s} {'met':>4s} {'s':>6s}")


def format_row(r: dict) -> str:
    line = (f"{r['case']:14s} {r['n_train']:4d} {r['samples']:8d} {r['rate_hz']:8.5g} {r['physics'][:24]:24s} "
            f"{r['residual'][:8]:8s} {r['default']:9.4g} {r['arx']:9.4g} {r['line']:9.4g} {r['vs_arx']:6.2f} "
            f"{r['vs_line']:6.2f} {'yes' if r['met'] else 'no':>4s} {r['seconds']:6.1f}")
    return line + (f"  FAILED: {r['error']}" if r["error"] else "")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="shorter runs (a few minutes in all)")
    parser.add_argument("--cases", default=",".join(str(i + 1) for i in range(len(CASES))),
                        help="comma-separated case numbers or names (default: all)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, help="write the table as JSON here")
    parser.add_argument("--keep", type=Path, help="write the cases' CSV files and models here (default: a temporary "
                        "folder)")
    args = parser.parse_args(argv)
    names = [case_name(k.strip()) for k in args.cases.split(",") if k.strip()]
    print(f"hyst fit (defaults) vs linear ARX (na=nb=3) and a static line, test RMSE after a warm-up of "
          f"{WARMUP} samples; target /ARX <= {ARX_TARGET} and /line <= {LINE_TARGET}"
          f"{' (quick)' if args.quick else ''}\n\n{HEADER}", flush=True)
    rows, t0 = [], time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        for name in names:
            folder = (args.keep or Path(tmp)) / name
            rows.append(run_case(name, folder, args.quick, args.seed))
            print(format_row(rows[-1]), flush=True)
    total = time.perf_counter() - t0
    print(f"\ntarget met in {sum(r['met'] for r in rows)}/{len(rows)} cases; {total:.0f} s in all")
    if args.out:
        plain = [{k: None if isinstance(v, float) and math.isnan(v) else v for k, v in r.items()} for r in rows]
        write_json(args.out, {"quick": args.quick, "seed": args.seed, "seconds": round(total, 1), "rows": plain})
    return 0


if __name__ == "__main__":
    sys.exit(main())
