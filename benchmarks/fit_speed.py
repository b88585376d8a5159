"""Wall time of ``hyst fit``'s stages, serial against the physics selection's folds in 2 workers (#43).

    nice -n 10 .venv/bin/python benchmarks/fit_speed.py [--quick] [--jobs 2] [--residual auto]

Each case is fitted twice with :func:`hybrid.experiments._fit.fit_model_dir` (what ``hyst fit``
runs), once with ``--jobs 1`` and once with ``--jobs N`` (``select_options={"n_jobs": N}``:
``select_physics`` fits each candidate's folds in N joblib worker processes, with the same choice
and numbers as serial), each into a fresh folder. The stage times are the card's ``seconds``
(physics = the selection on held-out runs, identify, residual, intervals, export, card).

Cases:

* ``catheter``   ``load_preset("catheter_2023")``: train set 1, test set 2 (25 Hz); skipped with a
  note when the data are absent;
* ``niti``       ``load_preset("niti_frequency_trials")`` (25 Hz); skipped likewise;
* ``sim-10k``    two virtual-catheter runs of 10,000 samples at 25 Hz (multisines, seeds 0 and 1),
  both trained on (the selection's folds: one run left out in turn, so 2 folds), no test runs.

``--quick``: only the simulated case, its two runs 2,000 samples each. Printed: the training
samples in all, seconds per stage and the fit's wall time, the chosen physics (the same both ways, or the row says so) and the ratio serial /
parallel of the physics stage and of the whole fit. The ratio is only as good as the machine is
idle: other jobs on the cores shrink it.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from hybrid.experiments._fit import STAGES, fit_model_dir  # noqa: E402
from physics.data import DataNotFoundError, load_preset  # noqa: E402

#: Sample rate of the simulated runs, Hz (the seed paper's).
SIM_RATE_HZ = 25.0


def simulated(n: int) -> tuple[list, list]:
    """Two virtual-catheter multisine runs of ``n`` samples at :data:`SIM_RATE_HZ`, both for training."""
    from physics.virtual import Multisine, VirtualCatheter

    cath = VirtualCatheter(seed=0, rate_hz=SIM_RATE_HZ)
    runs = [cath.run(Multisine(duration_s=(n - 1) / SIM_RATE_HZ, seed=s), name=f"multisine{s}") for s in (0, 1)]
    return runs, []


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


def fit_once(train, test, jobs: int, residual: str) -> tuple[dict, str, float]:
    """Stage seconds, the chosen physics spec and the wall time of one fit into a fresh folder."""
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        result = fit_model_dir(train, Path(tmp) / "model", test=test, residual=residual,
                               select_options={"n_jobs": jobs}, progress=False)
        return dict(result.seconds), result.spec, time.perf_counter() - t0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="only the simulated case, 2 x 2,000 samples")
    parser.add_argument("--jobs", type=int, default=2, help="worker processes of the parallel fit (default 2)")
    parser.add_argument("--residual", default="auto", help="hyst fit's --residual (default auto)")
    args = parser.parse_args()

    head = f"{'case':10s} {'samples':>8s} {'jobs':>4s} " + " ".join(f"{s:>9s}" for s in STAGES) \
        + f" {'total s':>8s}  physics"
    print(f"hyst fit stage times, s (--residual {args.residual}); ratio = serial / --jobs {args.jobs}\n")
    print(head)
    print("-" * len(head))
    ratios = []
    for name, load in cases(args.quick).items():
        try:
            train, test = load()
        except DataNotFoundError as exc:
            print(f"{name:10s} skipped: data absent ({str(exc).splitlines()[0]})")
            continue
        n = sum(t.n for t in train)
        seen = {}
        for jobs in (1, args.jobs):
            seconds, spec, wall = fit_once(train, test, jobs, args.residual)
            seen[jobs] = (seconds, spec, wall)
            print(f"{name:10s} {n:8d} {jobs:4d} " + " ".join(f"{seconds.get(s, float('nan')):9.1f}" for s in STAGES)
                  + f" {wall:8.1f}  {spec}", flush=True)
        (s1, spec1, w1), (sn, specn, wn) = seen[1], seen[args.jobs]
        physics = s1.get("physics", float("nan")) / max(sn.get("physics", float("nan")), 1e-9)
        same = "same physics" if spec1 == specn else f"DIFFERENT physics: {spec1} vs {specn}"
        print(f"{name:10s} ratio: physics stage {physics:.2f}x, whole fit {w1 / wn:.2f}x ({same})")
        ratios.append((name, physics, w1 / wn))
    if ratios:
        print("\nsummary (serial / parallel): " + ", ".join(f"{n} physics {p:.2f}x, fit {w:.2f}x" for n, p, w in ratios))


if __name__ == "__main__":
    main()
