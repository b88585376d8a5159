"""Ctrl-C stops a command promptly with one line and exit 130, and leaves the previous output intact,
also when it arrives inside CasADi/IPOPT (which swallows it)."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_ctrl_c_during_identification_exits_130_and_keeps_the_old_output(tmp_path):
    from hybrid.cli import main

    assert main(["simulate", "--out", str(tmp_path / "a.csv"), "--freq", "0.2"]) == 0
    old = tmp_path / "fit.json"
    old.write_text('{"old": 1}')
    # SIGINT is sent from inside the 5th IPOPT solve (deterministic, no timing): CasADi swallows it
    # there, so only the recorded press can stop the run
    script = textwrap.dedent(f"""
        import os, signal, sys
        from identification._problem import LeastSquaresProblem
        real, calls = LeastSquaresProblem.solve, []
        def solve(self, solver, w0):
            calls.append(1)
            if len(calls) == 5:
                os.kill(os.getpid(), signal.SIGINT)
            return real(self, solver, w0)
        LeastSquaresProblem.solve = solve
        from hybrid.cli import main
        rc = main(["identify", {str(tmp_path / "a.csv")!r}, "--model", "lag+backlash+linear", "--starts", "400",
                   "--out", {str(old)!r}])
        print("solves", len(calls))
        sys.exit(rc)
    """)
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert proc.returncode == 130, proc.stderr[-2000:]
    lines = [ln for ln in proc.stderr.splitlines() if ln.startswith("hyst")]
    assert lines == ["hyst identify: interrupted; files already written are complete (writes are atomic), "
                     "the one in progress was not written."], proc.stderr[-2000:]
    assert "Traceback" not in proc.stderr
    assert int(proc.stdout.split()[-1]) <= 6  # stopped after the solve in progress
    assert old.read_text() == '{"old": 1}'


def test_ctrl_c_during_the_mpc_ipopt_solves_exits_130_and_keeps_the_old_output(tmp_path):
    out = tmp_path / "mpc"
    out.mkdir()
    old = out / "summary.json"
    old.write_text('{"old": 1}')
    # a thread presses Ctrl-C once 3 control steps are done; the main thread is then inside an IPOPT
    # solve (or between two): either way the loop must stop within a step or two
    script = textwrap.dedent(f"""
        import os, signal, sys, threading, time
        from hybrid.control import TrackingMPC
        real, calls = TrackingMPC.solve, []
        def solve(self, *args, **kwargs):
            calls.append(1)
            return real(self, *args, **kwargs)
        TrackingMPC.solve = solve
        def press():
            while len(calls) < 3:
                time.sleep(0.001)
            os.kill(os.getpid(), signal.SIGINT)
            pressed.append(len(calls))
        pressed = []
        threading.Thread(target=press, daemon=True).start()
        from hybrid.cli import main
        rc = main(["mpc", "--model", "lag+boucwen+linear", "--solver", "ipopt", "--duration", "400",
                   "--no-figures", "--out", {str(out)!r}])
        print("solves", pressed[0], len(calls))
        sys.exit(rc)
    """)
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert proc.returncode == 130, proc.stderr[-2000:]
    assert [ln for ln in proc.stderr.splitlines() if ln.strip()] == [
        "hyst mpc: interrupted; files already written are complete (writes are atomic), "
        "the one in progress was not written."], proc.stderr[-2000:]
    at_press, total = map(int, proc.stdout.split()[-2:])
    assert total <= at_press + 2, proc.stdout  # 10000 control steps were asked for
    assert old.read_text() == '{"old": 1}' and sorted(p.name for p in out.iterdir()) == ["summary.json"]


def test_ctrl_c_while_the_command_line_starts_exits_130_with_one_line(tmp_path):
    # SIGINT sent as casadi starts to load (deterministic: an import hook, no timing), inside the second or
    # two that `hyst` spends importing scipy, casadi and torch before any command runs
    script = textwrap.dedent(f"""
        import os, signal, sys

        class Hook:
            def find_spec(self, name, path=None, target=None):
                if name == "casadi":
                    sys.meta_path.remove(self)
                    os.kill(os.getpid(), signal.SIGINT)
                return None

        sys.meta_path.insert(0, Hook())
        from hybrid.cli import main
        sys.exit(main(["simulate", "--out", {str(tmp_path / "a.csv")!r}]))
    """)
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert proc.returncode == 130, proc.stderr[-2000:]
    assert "Traceback" not in proc.stderr and proc.stderr.strip().count("\n") == 0, proc.stderr
    assert proc.stderr.startswith("hyst: interrupted") and not (tmp_path / "a.csv").exists()


def test_a_ctrl_c_as_the_command_ends_prints_nothing_and_leaves_no_worker(tmp_path):
    """Once ``hyst``'s work is over, its local workers are stopped before the interpreter exits and a
    Ctrl-C is ignored: loky's exit hook, waiting for the workers, used to print a KeyboardInterrupt
    traceback after the command's last line."""
    import os
    import signal

    script = textwrap.dedent(f"""
        import os, signal, sys, time
        signal.signal(signal.SIGINT, signal.default_int_handler)  # as in a terminal
        from identification.discovery import Workers
        from identification.discovery._pool import make_pool
        pool = make_pool(Workers(n_jobs=2))
        pids = pool.submit(os.getpid).result(), pool.submit(os.getpid).result()
        pool.close()
        sys.argv = ["hyst", "simulate", "--out", {str(tmp_path / "a.csv")!r}, "--duration", "5"]
        from hybrid.cli import main
        code = main()
        print("ended", *pids, flush=True)
        time.sleep(2)  # the Ctrl-C comes now, while the process exits
        sys.exit(code)
    """)
    proc = subprocess.Popen([sys.executable, "-c", script], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env={**os.environ, "PYTHONPATH": str(ROOT)})
    line = proc.stdout.readline()
    while line and not line.startswith("ended"):
        line = proc.stdout.readline()
    assert line.startswith("ended"), proc.communicate()[1][-2000:]
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err[-2000:]
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err[-2000:]
    for pid in map(int, line.split()[1:]):  # the workers were stopped with the command
        assert not Path(f"/proc/{pid}").exists() or "zombie" in Path(f"/proc/{pid}/status").read_text()
