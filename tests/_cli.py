"""What the command-line tests share: a refusal is exit 2 and one line on stderr, no traceback; a pose run of the
virtual catheter written as the catheter's files name their columns."""

from hybrid.cli import main


def refused(argv, capsys, *needles, absent=()) -> str:
    """Run ``hyst`` with ``argv``; assert exit 2, one stderr line holding every needle and none of ``absent``."""
    assert main([str(a) for a in argv]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    for needle in needles:
        assert needle in err, err
    for needle in absent:
        assert needle not in err, err
    return err


def write_pose(path, run, columns=("time", "Tendon Disp.", "Angle x", "Pos x", "Pos y"), **replace) -> str:
    """Write a run of ``VirtualCatheter(tip=TipArc())`` to the CSV ``path`` (17 digits) with ``columns``, each from
    the run (``time``, ``Tendon Disp.``, ``Angle x``, ``Pos x``, ``Pos y``) or from ``replace``; returns the path."""
    cols = {"time": run.time, "Tendon Disp.": run.u, "Angle x": run.y, "Pos x": run.extra["Pos x"],
            "Pos y": run.extra["Pos y"], **replace}
    rows = [",".join(f"{cols[c][i]:.17g}" for c in columns) for i in range(run.n)]
    path.write_text(",".join(columns) + "\n" + "\n".join(rows) + "\n")
    return str(path)
