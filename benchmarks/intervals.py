"""Prediction intervals (issue 36): coverage and width of 90 % conformal intervals on held-out runs.

    nice -n 10 .venv/bin/python benchmarks/intervals.py [--splits virtual,catheter_2023,...]
        [--default-path] [--level 0.9] [--warmup 10]

Per split, each test run predicted free after its first ``--warmup`` measured samples, pooled over
the test runs:

* ``physics``  ``lag+backlash+linear`` identified on the training runs, intervals calibrated by
  leaving one training run out (``ConformalModel``);
* ``arx``      the linear ARX peer, the same way;
* ``default``  (``--default-path``) what ``hyst fit`` with no options writes (auto physics, auto
  residual, its own calibration from the held-out fits it makes anyway); also its fit time and
  the share of it the calibration took.

Columns: RMSE, coverage (share of test samples inside the interval), mean width ``hi - lo`` as a
multiple of the RMSE, the share of samples flagged outside the training data and the coverage
of the samples not flagged. Targets: coverage 85-95 % with width under 3x RMSE on virtual,
catheter interp, set 2 -> set 1 and NiTi Random_data; on set 1 -> set 2 coverage >= 80 % or the
misses flagged; calibration <= 20 % of ``hyst fit``'s time. Then the exported half-width:
compiled time per call.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from hybrid.experiments._datasets import load_data  # noqa: E402
from hybrid.intervals import ConformalModel, coverage  # noqa: E402
from hybrid.peers import LinearARX  # noqa: E402
from identification import PhysicsEstimator  # noqa: E402
from physics.data import DataNotFoundError, rmse, warmup_split  # noqa: E402

SPLITS = ("virtual", "catheter_2023:interp", "catheter_2023:reverse", "niti_frequency_trials", "catheter_2023")
NAMES = {"virtual": "virtual catheter", "catheter_2023:interp": "catheter interp", "catheter_2023:reverse":
         "set 2 -> set 1", "niti_frequency_trials": "NiTi Random_data", "catheter_2023": "set 1 -> set 2"}


def _tests(split, test):
    """The test runs a target names: NiTi's random excitation only."""
    if split == "niti_frequency_trials":
        return [t for t in test if "random" in str(t.source).lower()] or list(test)
    return list(test)


def _score(y, bands) -> dict:
    y = np.concatenate(y)
    lo, hi = np.concatenate([b.lo for b in bands]), np.concatenate([b.hi for b in bands])
    yhat, out = np.concatenate([b.y for b in bands]), np.concatenate([b.outside for b in bands])
    e = rmse(y, yhat)
    return {"rmse": e, "coverage": coverage(y, lo, hi), "width": float(np.mean(hi - lo)) / e,
            "outside": float(out.mean()), "covered_inside": coverage(y[~out], lo[~out], hi[~out]) if (~out).any()
            else float("nan")}


def _wrapped(model, train, test, level, warmup) -> dict:
    t0 = time.perf_counter()
    cm = ConformalModel(model, level=level, warmup=warmup).fit(train)
    ys, bands = [], []
    for t in test:
        window, rest = warmup_split(t, warmup)
        bands.append(cm.predict(rest, warmup=window, interval=level))
        ys.append(rest.y)
    return {**_score(ys, bands), "seconds": time.perf_counter() - t0}


def _default(train, test, level, warmup) -> dict:
    from hybrid.experiments._fit import fit_model_dir

    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        result = fit_model_dir(train, Path(tmp) / "m", test=test, warmup=warmup, progress=False)
        seconds = time.perf_counter() - t0
    if result.intervals is None:
        return {"rmse": float("nan"), "note": result.calibration.get("why", ""), "seconds": seconds}
    ys, bands = [], []
    for (t, y, _, _), row in zip(result.predictions, result.rows):
        if row["set"] == "test" and any(t.source == s.source or str(s.source).endswith(row["run"])
                                        for s in test):
            bands.append(result.intervals.interval(y, t.u, t.dt, level))
            ys.append(t.y)
    calib = result.seconds.get("intervals", 0.0)
    return {**_score(ys, bands), "seconds": seconds, "calibration_share": calib / seconds,
            "model": f"{result.spec} + {result.residual}"}


def _half_width_timing(level: float) -> None:
    """The exported half-width (``ConformalIntervals.function``): time per call, VM and compiled."""
    from hybrid.control._adjoint_sqp import _compiled
    from hybrid.export._codegen import has_compiler
    from physics.virtual import VirtualCatheter, paper_protocol

    split = paper_protocol(VirtualCatheter(seed=0), frequencies=(0.2, 0.3, 0.5), tests=(0.45,))
    cm = ConformalModel(LinearARX(), level=level).fit(split.train)
    n = 20000
    fn = cm.intervals_.function(level).map(n)
    args = [np.linspace(0, 6, n)[None, :], np.linspace(0, 6, n)[None, :] - 0.01, np.linspace(30, 60, n)[None, :]]
    rows = [("CasADi VM", fn)] + ([("compiled C", _compiled([fn])[0])] if has_compiler() else [])
    print(f"\nexported half-width ({cm.intervals_.distance_.rows_.shape[0]} training rows kept), per step:")
    for name, f in rows:
        f(*args)
        t0 = time.perf_counter()
        f(*args)
        print(f"  {name:12s} {1e6 * (time.perf_counter() - t0) / n:8.3f} us")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--splits", default=",".join(SPLITS))
    ap.add_argument("--default-path", action="store_true", help="also fit what `hyst fit` writes (minutes per split)")
    ap.add_argument("--level", type=float, default=0.9)
    ap.add_argument("--warmup", type=int, default=10)
    args = ap.parse_args()
    warnings.filterwarnings("ignore")
    print(f"{args.level:.0%} intervals, each test run free after {args.warmup} measured samples\n")
    print(f"{'split':18s} {'model':34s} {'RMSE':>8s} {'coverage':>9s} {'width/RMSE':>11s} {'outside':>8s} "
          f"{'cov. inside':>11s} {'s':>6s}")
    for split in args.splits.split(","):
        try:
            train, test = load_data(split)
        except DataNotFoundError as exc:
            print(f"{NAMES.get(split, split):18s} skipped: {exc}")
            continue
        train = [t.resample(25) if t.dt < 0.039 else t for t in train]
        test = [t.resample(25) if t.dt < 0.039 else t for t in _tests(split, test)]
        rows = [("physics lag+backlash+linear", lambda: _wrapped(
                    PhysicsEstimator("lag+backlash+linear", max_iter=200, allow_failure=True), train, test,
                    args.level, args.warmup)),
                ("linear ARX (peer)", lambda: _wrapped(LinearARX(), train, test, args.level, args.warmup))]
        if args.default_path:
            rows.append(("default path", lambda: _default(train, test, args.level, args.warmup)))
        for name, run in rows:
            r = run()
            if "note" in r:
                print(f"{NAMES.get(split, split):18s} {name:34s} no intervals: {r['note']}")
                continue
            label = name if "model" not in r else f"default: {r['model']}"[:34]
            extra = f"  calibration {r['calibration_share']:.1%} of the fit" if "calibration_share" in r else ""
            print(f"{NAMES.get(split, split):18s} {label:34s} {r['rmse']:8.3f} {r['coverage']:9.1%} "
                  f"{r['width']:11.2f} {r['outside']:8.1%} {r['covered_inside']:11.1%} {r['seconds']:6.0f}{extra}",
                  flush=True)
    _half_width_timing(args.level)


if __name__ == "__main__":
    main()
