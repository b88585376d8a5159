"""Estimation and control of the tip's pose (issue 55): the outputs measured, the output tracked, in C too.

    .venv/bin/python benchmarks/pose_control.py [--skip-catheter] [--out results.json]

1. **Tracking**: a pose model (``backlash+boucwen+linear+arc``) identified on two runs of the virtual catheter
   with its tip (``VirtualCatheter(seed=6, tip=TipArc())``, 0.2 Hz zero and 0.5 Hz end baselines, as the CLI
   tests do) tracks ``Angle x`` and then ``Pos y`` on the virtual catheter (``hyst mpc --track X --plant
   virtual --duration 20``: sensor noise 0.15 deg on the angle, 0.1 mm on the position). Three kinds of
   feedback: each tracked output's own sensor with the offset filter (the default); the estimator of every
   output fed all three at every sample (``--measure-every 1 --measure-outputs "Angle x,Pos x,Pos y"``); the
   same every 25th sample. RMSE of the true tracked output against the reference, and over the reference's
   span (the relative units the target compares: ``Pos y`` at most 1.5x the angle's).
2. **The C controller**: ``hyst export --track X --controller DIR`` of the same model, built with ``-O2``; the
   generated ``closed_loop`` (its own model as the plant, no noise) tracks its sine, scored after its first
   second.
3. **Measured outputs on the catheter** (``../shared/data``, skipped with a message where absent): ``hyst fit``
   of set 1 with ``--output "Angle x,Pos x,Pos y"``, then ``hyst predict`` of each set-2 run with
   ``--measure-every 25 --measure-outputs M`` for M none (free), the angle, the position, all three: each
   output's RMSE pooled over set 2.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from hybrid.cli._main import main as hyst  # noqa: E402
from hybrid.virtual import DecayingSinusoid, TipArc, VirtualCatheter  # noqa: E402
from physics.data import DataNotFoundError, data_root  # noqa: E402
from physics.data._atomic import write_json  # noqa: E402

OUTPUTS = ("Angle x", "Pos x", "Pos y")
COLUMNS = ("time", "Tendon Disp.", *OUTPUTS)
FEEDBACK = {"own sensor, offset filter": [],
            "estimator of every output, every sample": ["--measure-every", "1", "--measure-outputs", ",".join(OUTPUTS)],
            "estimator of every output, every 25th": ["--measure-every", "25", "--measure-outputs", ",".join(OUTPUTS)]}
#: Target: tracking Pos y at most this multiple of tracking the angle, in units of each reference's span.
RATIO_TARGET = 1.5


def run(*argv: str) -> None:
    """``hyst ARGV`` with its printing swallowed; a failure raises with what it printed."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        status = hyst(list(argv))
    if status != 0:
        raise RuntimeError(f"hyst {' '.join(argv)} exited {status}: {err.getvalue().strip()}")


def virtual_fit(folder: Path) -> Path:
    """The pose model of the virtual catheter's tip, identified on two of its runs (as the CLI tests do)."""
    cath = VirtualCatheter(seed=6, tip=TipArc())
    files = []
    for i, (f, b) in enumerate(((0.2, "zero"), (0.5, "end"))):
        r = cath.run(DecayingSinusoid(frequency_hz=f, baseline=b))
        cols = {"time": r.time, "Tendon Disp.": r.u, "Angle x": r.y, "Pos x": r.extra["Pos x"], "Pos y": r.extra["Pos y"]}
        path = folder / f"r{i}.csv"
        path.write_text(",".join(COLUMNS) + "\n" + "\n".join(",".join(f"{cols[c][k]:.17g}" for c in COLUMNS)
                                                             for k in range(r.n)) + "\n")
        files.append(str(path))
    fit = folder / "pose.json"
    run("identify", *files, "--input", "Tendon Disp.", "--output", ",".join(OUTPUTS), "--model",
        "backlash+boucwen+linear+arc", "--warmup", "10", "--rate", "25", "--out", str(fit))
    return fit


def tracking(fit: Path, folder: Path) -> list[dict]:
    rows = []
    for how, extra in FEEDBACK.items():
        row = {"feedback": how}
        for track in ("Angle x", "Pos y"):
            out = folder / f"mpc_{len(rows)}_{track[-1]}"
            run("mpc", "--model", str(fit), "--track", track, "--plant", "virtual", "--duration", "20", "--no-figures",
                "--out", str(out), *extra)
            summary = json.loads((out / "summary.json").read_text())
            span = float(np.ptp(np.loadtxt(out / "closed_loop.csv", delimiter=",", skiprows=1)[:, 1]))
            row[track] = {"rmse": summary["rmse"], "span": span, "relative": summary["rmse"] / span}
        row["ratio"] = row["Pos y"]["relative"] / row["Angle x"]["relative"]
        rows.append(row)
    return rows


def c_tracking(fit: Path, folder: Path) -> dict | None:
    if shutil.which("gcc") is None or shutil.which("make") is None:
        print("C controller: skipped (no gcc or make)")
        return None
    row = {}
    for track in ("Angle x", "Pos y"):
        ctrl = folder / f"ctrl_{track[-1]}"
        run("export", str(fit), "--out", str(folder / f"step_{track[-1]}.casadi"), "--track", track, "--controller",
            str(ctrl))
        subprocess.run(["make", "-s", "-C", str(ctrl), "CFLAGS=-O2"], check=True, capture_output=True)
        loop = np.loadtxt(subprocess.run([str(ctrl / "closed_loop")], capture_output=True, text=True,
                                         check=True).stdout.splitlines())
        main_c = (ctrl / "main.c").read_text()
        low, high = (float(re.search(rf"{n} = ([-0-9.e]+)", main_c).group(1)) for n in ("y_low", "y_high"))
        t = loop[:, 0] * float(re.search(r"dt = ([-0-9.e]+)", main_c).group(1))
        ref = low + (high - low) * 0.5 * (1 - np.cos(2 * np.pi * 0.2 * t))
        late = t >= 1.0
        rmse = float(np.sqrt(np.mean((loop[late, 2] - ref[late]) ** 2)))
        row[track] = {"rmse": rmse, "span": abs(high - low), "relative": rmse / abs(high - low)}
    row["ratio"] = row["Pos y"]["relative"] / row["Angle x"]["relative"]
    return row


def catheter(folder: Path) -> list[dict] | None:
    try:
        root = data_root() / "catheter_2023"
    except DataNotFoundError as exc:
        print(f"catheter: skipped ({exc})")
        return None
    if not root.is_dir():
        print(f"catheter: skipped (no {root})")
        return None
    model = folder / "pose_folder"
    common = ["--time", "Time", "--input", "Tendon Disp.", "--output", ",".join(OUTPUTS), "--rate", "25"]
    run("fit", *sorted(str(p) for p in root.glob("data_1_?.txt")), *common, "--no-progress", "--out", str(model))
    rows = []
    for measured in ("", "Angle x", "Pos x,Pos y", ",".join(OUTPUTS)):
        errors = {o: [] for o in OUTPUTS}
        for test in sorted(root.glob("data_2_?.txt")):
            pred = folder / f"pred_{test.stem}.csv"
            extra = ["--measure-every", "25", "--measure-outputs", measured] if measured else []
            run("predict", str(model), str(test), "--out", str(pred), *extra)
            header = pred.read_text().splitlines()[0].split(",")
            table = np.loadtxt(pred, delimiter=",", skiprows=1)
            for o in OUTPUTS:
                errors[o].append(table[:, header.index(f"{o}_pred")] - table[:, header.index(o)])
        rows.append({"measured": measured or "none (free)",
                     **{o: float(np.sqrt(np.mean(np.concatenate(e) ** 2))) for o, e in errors.items()}})
    return rows


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--skip-catheter", action="store_true", help="leave out the catheter's measured outputs")
    parser.add_argument("--out", type=Path, help="write the results as JSON")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        fit = virtual_fit(folder)
        rows = tracking(fit, folder)
        print(f"Tracking on the virtual catheter's tip, 20 s (target: Pos y <= {RATIO_TARGET}x the angle, relative)")
        print(f"{'feedback':42s} {'Angle x deg':>12s} {'%':>7s} {'Pos y mm':>10s} {'%':>7s} {'ratio':>6s}")
        for r in rows:
            a, y = r["Angle x"], r["Pos y"]
            print(f"{r['feedback']:42s} {a['rmse']:12.4g} {100 * a['relative']:7.3f} {y['rmse']:10.4g} "
                  f"{100 * y['relative']:7.3f} {r['ratio']:6.2f}")
        c_row = c_tracking(fit, folder)
        if c_row is not None:
            print(f"C closed_loop (-O2, its own model, no noise): Angle x {c_row['Angle x']['rmse']:.4g} deg "
                  f"({100 * c_row['Angle x']['relative']:.4f} %), Pos y {c_row['Pos y']['rmse']:.4g} mm "
                  f"({100 * c_row['Pos y']['relative']:.4f} %), ratio {c_row['ratio']:.2f}")
        cath = None if args.skip_catheter else catheter(folder)
        if cath is not None:
            print("Catheter set 1 -> 2, hyst predict --measure-every 25 --measure-outputs M: RMSE pooled over set 2")
            print(f"{'measured':24s} " + " ".join(f"{o:>9s}" for o in OUTPUTS))
            for r in cath:
                print(f"{r['measured']:24s} " + " ".join(f"{r[o]:9.3f}" for o in OUTPUTS))
    if args.out is not None:
        write_json(args.out, {"tracking": rows, "c": c_row, "catheter": cath})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
