"""Wall time of ``hyst fit``'s stages: serial, 2 local workers and a 2-worker Dask cluster (#43).

    nice -n 10 .venv/bin/python benchmarks/fit_speed.py [--quick] [--jobs 2] [--residual auto] [--growth]
        [--cases catheter,niti,sim-10k] [--trace] [--scaling]

Each case is fitted three times with :func:`hybrid.experiments._fit.fit_model_dir` (what ``hyst fit``
runs), each into a fresh folder: with ``--jobs 1``, with ``--jobs N`` (``Workers(n_jobs=N)``:
``select_physics`` fits the folds of all the specs tried at a step in N loky worker processes) and on a
``LocalCluster`` of N single-threaded workers (``Workers(scheduler=address)``, what
``hyst fit --scheduler`` does), all with the same choice and numbers as serial. The stage times are the
card's ``seconds`` (physics = the selection on held-out runs, identify, residual, intervals, export,
card). ``--growth`` adds how the selection's time grows with the runs and their samples: simulated runs,
2 and 4 of them, of 1,000, 2,000 and 4,000 samples, serial, and the log-log slope of time against
the samples in all.

Cases:

* ``catheter``   ``load_preset("catheter_2023")``: train set 1, test set 2 (25 Hz); skipped with a
  note when the data are absent;
* ``niti``       ``load_preset("niti_frequency_trials")`` (25 Hz); skipped likewise;
* ``sim-10k``    two virtual-catheter runs of 10,000 samples at 25 Hz (multisines, seeds 0 and 1),
  both trained on (the selection's folds: one run left out in turn, so 2 folds), no test runs.

``--trace``: instead, each case is fitted once under :func:`identification._trace.tracing`
(every task of the selection's and the residual's pools run here and timed, the driver's work between
them cut into segments): the serial CPU time, the critical path (the longest chain of work that waits
for other work), its share of the serial time, and the speed-up 1, 2, 4, 8, 16 and unlimited workers could
reach (the graph replayed on that many workers, the driver on its own core), with each stage's share
of the serial time and of the critical path. This needs no more cores than one.

``--scaling``: the default fit's wall time with ``--jobs`` 1, 2, 4, 8 and 16 (those up to the cores this
machine has), the measured speed-up beside the traced bound.

``--quick``: only the simulated case, its two runs 2,000 samples each. Printed: the training
samples in all, seconds per stage and the fit's wall time, the chosen physics (the same both ways, or the row says so) and the ratio serial /
parallel of the physics stage and of the whole fit. The ratio is only as good as the machine is
idle: other jobs on the cores shrink it.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from hybrid.experiments._fit import STAGES, fit_model_dir  # noqa: E402
from identification.discovery import FALLBACK, PhysicsPolicy, Workers  # noqa: E402
from physics.data import DataNotFoundError, load_preset  # noqa: E402

#: Sample rate of the simulated runs, Hz (the seed paper's).
SIM_RATE_HZ = 25.0


def simulated(n: int) -> tuple[list, list]:
    """Two virtual-catheter multisine runs of ``n`` samples at :data:`SIM_RATE_HZ`, both for training."""
    return simulated_pair(n, 0), []


def preset(name: str):
    def load():
        split = load_preset(name)
        return list(split.train), list(split.test)
    return load


def cases(quick: bool) -> dict:
    if quick:
        return {"sim-2k": lambda: simulated(2000)}
    return {"catheter": preset("catheter_2023"), "niti": preset("niti_frequency_trials"),
            "sim-10k": lambda: simulated(10_000)}


def fit_once(train, test, where: dict, residual: str) -> tuple[dict, str, float]:
    """Stage seconds, the chosen physics spec and the wall time of one fit into a fresh folder; ``where``
    the selection's ``n_jobs`` or ``scheduler``."""
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        policy = PhysicsPolicy("auto", fallback=FALLBACK, select_options={"workers": Workers(**where)})
        result = fit_model_dir(train, Path(tmp) / "model", test=test, residual=residual, physics=policy,
                               progress=False)
        return dict(result.seconds), result.spec, time.perf_counter() - t0


def loaded(chosen: dict):
    """``(name, train, test)`` of each case whose data are here; a line for each that is absent."""
    for name, load in chosen.items():
        try:
            train, test = load()
        except DataNotFoundError as exc:
            print(f"{name:10s} skipped: data absent ({str(exc).splitlines()[0]})")
            continue
        yield name, train, test


#: The worker counts the trace's bound and the measured scaling are given for.
WORKERS = (1, 2, 4, 8, 16)


def trace_once(train, test, residual: str):
    """The default fit of ``train`` under a trace (a fresh folder): ``(trace, spec, wall seconds)``."""
    from identification._trace import tracing

    with tempfile.TemporaryDirectory() as tmp, tracing() as trace:
        t0 = time.perf_counter()
        result = fit_model_dir(train, Path(tmp) / "model", test=test, residual=residual, progress=False)
    return trace, result.spec, time.perf_counter() - t0


def print_trace(name: str, trace, spec: str, wall: float) -> None:
    serial, critical = trace.serial, trace.critical
    print(f"\n{name}: '{spec}', traced in {wall:.1f} s: serial CPU {serial:.1f} s, critical path {critical:.1f} s "
          f"({critical / serial:.0%} of serial; at most {serial / critical:.2f}x with any number of workers), "
          f"{len(trace.tasks)} pool tasks")
    print("  workers      " + " ".join(f"{n:>6d}" for n in WORKERS) + "    inf")
    print("  speed-up     " + " ".join(f"{serial / trace.makespan(n):6.2f}" for n in WORKERS)
          + f" {serial / critical:6.2f}")
    path = trace.critical_stages()
    longest: dict[str, tuple[float, str]] = {}
    for t in trace.tasks:
        stage = trace.segments[t.after][1]
        longest[stage] = max(longest.get(stage, (0.0, "")), (t.seconds, t.name))
    print(f"  {'stage':10s} {'driver s':>9s} {'tasks s':>8s} {'of serial':>9s} {'on the path s':>13s}  longest task")
    for stage, (driver, tasks) in trace.by_stage().items():
        seconds, task = longest.get(stage, (0.0, ""))
        print(f"  {stage or '(between)':10s} {driver:9.1f} {tasks:8.1f} {(driver + tasks) / serial:9.0%} "
              f"{path.get(stage, 0.0):13.1f}  {f'{task} ({seconds:.1f} s)' if task else ''}")


def scaling(name: str, train, test, residual: str) -> None:
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    counts = [n for n in WORKERS if n <= cores]
    walls = {}
    for n in counts:
        _, spec, walls[n] = fit_once(train, test, {"n_jobs": n}, residual)
        print(f"  {name} --jobs {n:2d}: {walls[n]:7.1f} s, speed-up {walls[counts[0]] / walls[n]:.2f}x  {spec}",
              flush=True)
    if len(counts) < len(WORKERS):
        print(f"  ({cores} cores here: no measurement at {', '.join(map(str, WORKERS[len(counts):]))} workers)")


def growth() -> None:
    """The serial selection's seconds on simulated runs, by runs and samples, and the log-log slope."""
    import numpy as np

    from identification import select_physics

    print("\nselection time (serial, warm-up 10) against the training samples:")
    print(f"{'runs':>4s} {'samples/run':>11s} {'samples':>8s} {'seconds':>8s}  chosen")
    rows = []
    for runs in (2, 4):
        for n in (1000, 2000, 4000):
            train = [r for s in range(0, runs, 2) for r in simulated_pair(n, s)]
            t0 = time.perf_counter()
            sel = select_physics(train, warmup=10)
            rows.append((runs * n, time.perf_counter() - t0))
            print(f"{runs:4d} {n:11d} {runs * n:8d} {rows[-1][1]:8.1f}  {sel.spec}", flush=True)
    x, y = np.log([r[0] for r in rows]), np.log([r[1] for r in rows])
    print(f"log-log slope of seconds against samples: {np.polyfit(x, y, 1)[0]:.2f} (1: linear)")


def simulated_pair(n: int, first_seed: int) -> list:
    from physics.virtual import Multisine, VirtualCatheter

    cath = VirtualCatheter(seed=0, rate_hz=SIM_RATE_HZ)
    return [cath.run(Multisine(duration_s=(n - 1) / SIM_RATE_HZ, seed=s), name=f"multisine{s}")
            for s in (first_seed, first_seed + 1)]


def main() -> None:
    from dask.distributed import LocalCluster

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="only the simulated case, 2 x 2,000 samples")
    parser.add_argument("--jobs", type=int, default=2, help="worker processes of the parallel fit (default 2)")
    parser.add_argument("--residual", default="auto", help="hyst fit's --residual (default auto)")
    parser.add_argument("--growth", action="store_true", help="also the selection's time against runs and samples")
    parser.add_argument("--cases", help="comma-separated cases to run (default: all of catheter, niti, sim-10k)")
    parser.add_argument("--trace", action="store_true", help="the critical path of one traced fit per case instead")
    parser.add_argument("--scaling", action="store_true", help="with --trace: also the measured wall time at "
                        "1, 2, 4, 8, 16 workers (up to this machine's cores)")
    args = parser.parse_args()
    chosen = cases(args.quick)
    if args.cases:
        unknown = set(args.cases.split(",")) - set(chosen)
        if unknown:
            parser.error(f"unknown case(s) {', '.join(sorted(unknown))}; choose among {', '.join(chosen)}")
        chosen = {k: v for k, v in chosen.items() if k in args.cases.split(",")}
    if args.trace:
        for name, train, test in loaded(chosen):
            print_trace(name, *trace_once(train, test, args.residual))
            if args.scaling:
                scaling(name, train, test, args.residual)
        return
    # the cluster runs only while its own fit does: idle, its nanny and workers took about 10 % of a core
    # (heartbeats, memory monitor), which slowed the serial and loky fits beside it
    ways = {"1": {"n_jobs": 1}, str(args.jobs): {"n_jobs": args.jobs}, f"{args.jobs}d": "cluster"}

    head = f"{'case':10s} {'samples':>8s} {'jobs':>4s} " + " ".join(f"{s:>9s}" for s in STAGES) \
        + f" {'total s':>8s}  physics"
    print(f"hyst fit stage times, s (--residual {args.residual}); jobs {args.jobs}d: a {args.jobs}-worker Dask "
          f"LocalCluster; ratio = serial / parallel\n")
    print(head)
    print("-" * len(head))
    ratios = []
    for name, train, test in loaded(chosen):
        n = sum(t.n for t in train)
        seen = {}
        for label, where in ways.items():
            if where == "cluster":
                with LocalCluster(n_workers=args.jobs, threads_per_worker=1, processes=True,
                                  dashboard_address=":0") as cluster:
                    seconds, spec, wall = fit_once(train, test, {"scheduler": cluster.scheduler_address}, args.residual)
            else:
                seconds, spec, wall = fit_once(train, test, where, args.residual)
            seen[label] = (seconds, spec, wall)
            print(f"{name:10s} {n:8d} {label:>4s} " + " ".join(f"{seconds.get(s, float('nan')):9.1f}" for s in STAGES)
                  + f" {wall:8.1f}  {spec}", flush=True)
        s1, spec1, w1 = seen["1"]
        for label in list(ways)[1:]:
            sn, specn, wn = seen[label]
            physics = s1.get("physics", float("nan")) / max(sn.get("physics", float("nan")), 1e-9)
            same = "same physics" if spec1 == specn else f"DIFFERENT physics: {spec1} vs {specn}"
            print(f"{name:10s} ratio 1 / {label}: physics stage {physics:.2f}x, whole fit {w1 / wn:.2f}x ({same})")
            ratios.append((f"{name} {label}", physics, w1 / wn))
    if ratios:
        print("\nsummary (serial / parallel): " + ", ".join(f"{n} physics {p:.2f}x, fit {w:.2f}x" for n, p, w in ratios))
    if args.growth:
        growth()


if __name__ == "__main__":
    main()
