"""What the command-line tests share: a refusal is exit 2 and one line on stderr, no traceback."""

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
