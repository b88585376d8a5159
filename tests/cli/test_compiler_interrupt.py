"""A Ctrl-C, SIGTERM or SIGHUP that arrives while the C compiler runs stops the command (exit 130, 143 or 129,
one line), keeps the previous output and leaves no temporary files or compiler processes.

CasADi's own JIT ran gcc through ``system()``, which ignores SIGINT in the caller: the press was
lost and the command ran on to exit 0; a SIGTERM killed Python and left gcc writing into a
``hyst_jit_*`` folder nobody removed. Each test waits (on /proc) until the real compiler proper
(``cc1``) runs under the command, then signals the command itself, as a terminal or a job
scheduler would.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
INTERRUPTED = ("files already written are complete (writes are atomic), the one in progress was not written.")

pytestmark = pytest.mark.skipif(not (shutil.which("gcc") and Path("/proc/self/stat").exists()),
                                reason="needs gcc and /proc")


def _parents() -> dict[int, int]:
    out = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                stat = Path(f"/proc/{entry}/stat").read_text()
            except OSError:
                continue
            out[int(entry)] = int(stat[stat.rindex(")") + 2:].split()[1])
    return out


def _alive(pid: int) -> bool:
    """Running (a zombie left for a parent to reap counts as gone)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat[stat.rindex(")") + 2] != "Z"


def _compiler_under(pid: int) -> int | None:
    """A live ``cc1`` among ``pid``'s descendants (through gcc, or a shell in front of it)."""
    parents = _parents()
    for child in parents:
        p, depth = child, 0
        while p in parents and p != pid and depth < 10:
            p, depth = parents[p], depth + 1
        if p == pid and child != pid and _alive(child):
            try:
                if Path(f"/proc/{child}/comm").read_text().strip() == "cc1":
                    return child
            except OSError:
                continue
    return None


def _signal_during_compile(cmd: list[str], tmpdir: Path, sig: int, cwd: Path = ROOT):
    """Run ``cmd`` with ``TMPDIR=tmpdir``, send ``sig`` once cc1 runs under it; returns
    ``(returncode, stderr, seconds from the signal to the exit, cc1's pid)``."""
    tmpdir.mkdir(exist_ok=True)
    env = {**os.environ, "TMPDIR": str(tmpdir), "HYST_JIT_CACHE": "off",  # compile, not load a kept library
           "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}
    proc = subprocess.Popen(cmd, cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    cc1 = None
    try:
        deadline = time.monotonic() + 120
        while cc1 is None:
            if proc.poll() is not None:
                pytest.fail(f"the command ended before the compiler ran: {proc.communicate()[1][-2000:]}")
            if time.monotonic() > deadline:
                pytest.fail("no compiler ran within 120 s")
            time.sleep(0.01)
            cc1 = _compiler_under(proc.pid)
        os.kill(proc.pid, sig)
        sent = time.monotonic()
        try:
            _, err = proc.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            status = proc.poll()
            pytest.fail(f"still running 10 s after signal {sig} was sent during a compile" if status is None else
                        f"the command ended (status {status}) but the compiler it started runs on")
        elapsed = time.monotonic() - sent
        for _ in range(100):  # the compiler was stopped with the command
            if not _alive(cc1):
                break
            time.sleep(0.01)
        assert not _alive(cc1), "the compiler runs on after the command ended"
        return proc.returncode, err, elapsed
    finally:
        for pid in (proc.pid, cc1):  # only what this test started, should it still run
            if pid is not None and _alive(pid):
                try:
                    os.killpg(os.getpgid(pid), signal.SIGKILL)
                except OSError:
                    pass
        if proc.poll() is None:
            proc.communicate()


def _hyst(*args: str) -> list[str]:
    return [sys.executable, "-c", "import sys; from hybrid.cli import main; sys.exit(main(sys.argv[1:]))", *args]


@pytest.fixture(scope="module")
def run_csv(tmp_path_factory) -> Path:
    from hybrid.cli import main

    path = tmp_path_factory.mktemp("data") / "a.csv"
    assert main(["simulate", "--out", str(path), "--freq", "0.2", "--duration", "30"]) == 0
    return path


@pytest.mark.parametrize("sig, status, word", [(signal.SIGINT, 130, "interrupted"),
                                               (signal.SIGTERM, 143, "terminated"),
                                               (signal.SIGHUP, 129, "hung up")])  # a closed terminal
def test_signal_during_the_jit_compile_of_identify_stops_it_cleanly(tmp_path, run_csv, sig, status, word):
    # the hysteretic oscillator's sensitivity step takes gcc about 10 s: the signal comes early in it
    out = tmp_path / "fit.json"
    out.write_text('{"old": 1}')
    tmpdir = tmp_path / "tmp"
    rc, err, elapsed = _signal_during_compile(
        _hyst("identify", str(run_csv), "--model", "hysteretic_oscillator+linear", "--out", str(out)), tmpdir, sig)
    assert rc == status, err[-2000:]
    assert [ln for ln in err.splitlines() if ln.strip()] == [f"hyst identify: {word}; {INTERRUPTED}"], err[-2000:]
    assert elapsed < 3, f"took {elapsed:.1f} s to stop"
    assert out.read_text() == '{"old": 1}'
    assert sorted(p.name for p in tmpdir.iterdir()) == [], "hyst_jit_* folders or gcc's files were left behind"


def test_signal_during_the_c_export_keeps_the_previous_c_code(tmp_path):
    c_dir = tmp_path / "c"
    c_dir.mkdir()
    old = {name: f"/* old {name} */\n" for name in ("step.c", "step.h", "libstep.so", "step_demo.c")}
    for name, text in old.items():
        (c_dir / name).write_text(text)
    tmpdir = tmp_path / "tmp"
    rc, err, elapsed = _signal_during_compile(
        _hyst("export", "hysteretic_oscillator+linear", "--out", str(tmp_path / "step.casadi"), "--c-code", str(c_dir)),
        tmpdir, signal.SIGTERM)
    assert rc == 143, err[-2000:]
    assert [ln for ln in err.splitlines() if ln.strip()] == [f"hyst export: terminated; {INTERRUPTED}"], err[-2000:]
    assert elapsed < 3, f"took {elapsed:.1f} s to stop"
    assert {p.name: p.read_text() for p in c_dir.iterdir()} == old
    assert sorted(p.name for p in tmpdir.iterdir()) == []


def test_ctrl_c_during_the_mpc_library_build_leaves_no_build_folder(tmp_path):
    script = textwrap.dedent("""
        import sys
        import numpy as np
        from identification._sensitivity import SensitivityRollouts
        from physics import Series
        from hybrid.control._adjoint_sqp import _compiled

        model = Series.from_spec("hysteretic_oscillator+linear")
        step = SensitivityRollouts(model, np.ones(model.n_p, bool), True, jit=False)._step
        try:
            _compiled([step])
        except KeyboardInterrupt:
            sys.exit(130)
    """)
    tmpdir = tmp_path / "tmp"
    rc, err, elapsed = _signal_during_compile([sys.executable, "-c", script], tmpdir, signal.SIGINT)
    assert rc == 130, err[-2000:]
    assert elapsed < 3, f"took {elapsed:.1f} s to stop"
    left = sorted(str(p.relative_to(tmpdir)) for p in tmpdir.rglob("*"))
    assert left == ["hyst_mpc"], f"left behind: {left}"
