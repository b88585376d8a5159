"""``hyst compare`` (forward, quick preset) on every real data set in ``../shared/data``: the best hybrid
beside the best pure network and the best peer.

    nice -n 10 .venv/bin/python benchmarks/compare_real.py [--sets tendon_vio_conf0,catheter_2023]
        [--out results.json] [--keep DIR]

Sets: the lab folders (``labs/*``) and the measured presets (the catheter's set 1 -> 2, set 2 -> 1 and
interpolation splits, the NiTi robot), as ``benchmarks/real_labs.py`` names them. Each runs
``hybrid.compare(compare_data(SET), directions=("forward",))``: the physics ``hyst fit`` chooses, the paper's
three networks alone and as residuals (each hybrid row its network alone where that did better on runs held out
of both fits: ``hybrid_choice``), the neural-ODE hybrid and the peers (linear ARX, NARX, SUBNET), each from every
test run's first 10 samples. RMSE pooled over the ``id`` test runs. Targets (issue 53): the best hybrid <= the
best pure network on every set, <= 0.7x the best peer on the catheter's set 1 -> 2.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from real_labs import PRESETS, set_names  # noqa: E402
from hybrid.experiments._compare import compare  # noqa: E402
from hybrid.experiments._compare_table import pooled  # noqa: E402
from hybrid.experiments._datasets import compare_data  # noqa: E402
from physics.data import DataNotFoundError, data_root  # noqa: E402
from physics.data._atomic import write_json  # noqa: E402


def run_set(name: str, root: Path, folder: Path) -> dict:
    data = compare_data(name if name in PRESETS else str(root / "labs" / name))
    t0 = time.perf_counter()
    result = compare(data, folder, progress=False, figures=False, directions=("forward",))
    seconds = time.perf_counter() - t0
    table = {m: r for (m, c), r in pooled(result.rows, "forward").items() if c == "id"}
    kinds = {r.model: r.kind for r in result.rows}
    best = {k: min(((r.rmse, m) for m, r in table.items() if kinds[m] == k), default=(float("nan"), "-"))
            for k in ("physics", "learned", "hybrid", "peer")}
    choices = json.loads((folder / "run.json").read_text())["hybrid_choice"]
    alone = [k.split("/")[-1] for k, c in choices.items() if k.startswith("all/") and c["kept"] == "network alone"]
    row = {"set": name, "physics": best["physics"][0], "hybrid": best["hybrid"][0], "hybrid_model": best["hybrid"][1],
           "learned": best["learned"][0], "learned_model": best["learned"][1], "peer": best["peer"][0],
           "peer_model": best["peer"][1], "alone_kept": alone, "seconds": round(seconds, 1)}
    row["hybrid_vs_learned"], row["hybrid_vs_peer"] = row["hybrid"] / row["learned"], row["hybrid"] / row["peer"]
    return row


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sets", help="comma-separated set names (default: every lab set and measured preset)")
    ap.add_argument("--out", help="write the rows as JSON here")
    ap.add_argument("--keep", help="keep each comparison's folder under this directory")
    args = ap.parse_args(argv)
    try:
        root = data_root()
    except DataNotFoundError as exc:
        print(f"skipped: {exc}")
        return 0
    names = set_names(ap, args.sets, root)
    rows = []
    print("| set | physics | best hybrid | best pure network | best peer | hybrid / network | hybrid / peer | "
          "network alone kept | s |")
    print("|---|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for name in names:
            folder = Path(args.keep or tmp) / name.replace(":", "_")
            r = run_set(name, root, folder)
            rows.append(r)
            print(f"| {name} | {r['physics']:.4g} | {r['hybrid_model']} {r['hybrid']:.4g} | {r['learned_model']} "
                  f"{r['learned']:.4g} | {r['peer_model']} {r['peer']:.4g} | {r['hybrid_vs_learned']:.2f} | "
                  f"{r['hybrid_vs_peer']:.2f} | {', '.join(r['alone_kept']) or '-'} | {r['seconds']:.0f} |", flush=True)
    if args.out:
        write_json(Path(args.out), rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
