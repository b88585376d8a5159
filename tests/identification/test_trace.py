"""The critical path of a fit (``identification._trace``): a traced pool runs each task here and
times it, the driver's work is cut at every submit and read, and the graph replays on any number of
workers. A fake clock makes every duration exact."""

from __future__ import annotations

import pytest

from identification.discovery import Workers, make_pool
from identification import _trace
from identification._trace import stage, tracing


@pytest.fixture
def clock(monkeypatch):
    now = [0.0]

    class Clock:
        @staticmethod
        def perf_counter():
            return now[0]

        @staticmethod
        def advance(seconds):
            now[0] += seconds

    monkeypatch.setattr(_trace, "time", Clock)
    return Clock


def _work(clock, seconds):
    def fn(name):
        clock.advance(seconds)
        return name
    return fn


def test_independent_tasks_read_together_wait_for_the_longest(clock):
    """The driver works 1 s, submits four fits of 2, 3, 4 and 5 s, reads them, then works 1 s: one after
    another 16 s; with any number of workers 1 + 5 + 1 = 7 s; on two workers (first come, first served)
    1 + (2, 3 | then 4 after 2, 5 after 3 -> 8) + 1 = 10 s."""
    with tracing(width=8) as trace, stage("physics"):
        pool = make_pool(Workers(n_jobs=1))  # asked for one: the trace offers its width
        assert pool.workers == 8
        clock.advance(1.0)
        futures = [pool.submit(_work(clock, s), f"spec{s}") for s in (2.0, 3.0, 4.0, 5.0)]
        assert [f.result() for f in futures] == ["spec2.0", "spec3.0", "spec4.0", "spec5.0"]
        clock.advance(1.0)
    assert trace.serial == pytest.approx(16.0)
    assert trace.critical == pytest.approx(7.0)
    assert trace.makespan(1) == pytest.approx(16.0)
    assert trace.makespan(2) == pytest.approx(10.0)
    assert trace.makespan(4) == pytest.approx(7.0)
    assert [t.name for t in trace.tasks] == ["fn spec2.0", "fn spec3.0", "fn spec4.0", "fn spec5.0"]
    assert trace.by_stage()["physics"] == pytest.approx((2.0, 14.0))
    assert sum(trace.critical_stages().values()) == pytest.approx(trace.critical)


def test_a_task_submitted_after_a_read_waits_for_it_and_stages_are_told_apart(clock):
    """A step's fit (3 s) is read before the next step's (2 s) is submitted: a chain, 1 + 3 + 2 = 6 s on
    any number of workers; the driver's 4 s in 'identify' after it are on the path too; a task nobody
    reads (a stopped spec's fold, 10 s) still takes a worker, but nothing waits for it."""
    with tracing() as trace:
        pool = make_pool()
        with stage("physics"):
            clock.advance(1.0)
            first = pool.submit(_work(clock, 3.0), "a")
            first.result()
            pool.submit(_work(clock, 10.0), "stopped")
            second = pool.submit(_work(clock, 2.0), "b")
            second.result()
        with stage("identify"):
            clock.advance(4.0)
    assert trace.serial == pytest.approx(20.0)
    assert trace.critical == pytest.approx(10.0)
    assert trace.critical_stages() == pytest.approx({"physics": 6.0, "identify": 4.0})
    # one worker: a (1-4), the stopped fit (4-14) before b (14-16), then identify: 20 s
    assert trace.makespan(1) == pytest.approx(20.0) and trace.makespan(2) == pytest.approx(10.0)


def test_outside_a_trace_pools_run_as_asked():
    assert _trace.active_trace() is None and make_pool(Workers(n_jobs=1)).workers == 1
    with stage("physics"):  # no trace: nothing recorded, nothing raised
        pass
