"""`drem up` waits for a child by its progress: a slow child that keeps working is waited for however long it takes
(and drem up says what it waits for); only one that does nothing for the stall window, or exits, ends the wait."""
from __future__ import annotations

import sys

import pytest

from drem_local.readiness import ChildExited, Progress, ReadinessWait, StillWaiting, process_progress
from drem_local.stack import StackError, spawn, wait_for_ok
from tests.waiting import wait_until

pytestmark = pytest.mark.unit


class FakeClock:
    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now

    def sleep(self, seconds: float) -> None:
        self.now += seconds


def _wait(clock: FakeClock, ready_at: float, progress, *, alive=lambda: True, stall_s: float = 120.0):
    said: list[str] = []
    wait = ReadinessWait("the app server (pid 42) to answer http://127.0.0.1:8000/healthz",
                         ready=lambda: clock.now >= ready_at, alive=alive, progress=progress, stall_s=stall_s,
                         say=said.append, poll_s=1.0, clock=clock, sleep=clock.sleep)
    return wait, said


def test_an_app_that_keeps_working_is_waited_for_past_any_fixed_deadline_and_drem_up_says_so():
    clock = FakeClock()
    # A loaded laptop: the app needs 5 minutes to import, using a little CPU every few seconds.
    wait, said = _wait(clock, ready_at=300.0, progress=lambda: Progress(cpu_s=int(clock.now / 5) * 0.1, log_bytes=0))

    assert wait.run() == pytest.approx(300.0, abs=1.0)
    assert len(said) >= 25  # one line every 10 s
    assert "still waiting for the app server (pid 42) to answer http://127.0.0.1:8000/healthz" in said[0]
    assert "it is working" in said[0] and "keeps waiting" in said[0]


def test_a_child_that_does_nothing_for_the_stall_window_is_called_stuck_with_what_it_waited_for():
    clock = FakeClock()
    wait, said = _wait(clock, ready_at=10_000.0, progress=lambda: Progress(1.0, 100), stall_s=120.0)

    with pytest.raises(StillWaiting) as stuck:
        wait.run()
    assert 120.0 <= clock.now < 125.0
    assert "the app server (pid 42) to answer http://127.0.0.1:8000/healthz" in str(stuck.value)
    assert "no CPU time used, no log line written" in str(stuck.value)
    assert "it has done nothing for" in said[-1]


def test_a_growing_log_alone_counts_as_progress():
    clock = FakeClock()
    wait, _ = _wait(clock, ready_at=400.0, progress=lambda: Progress(0.0, int(clock.now // 60)), stall_s=120.0)
    assert wait.run() == pytest.approx(400.0, abs=1.0)


def test_a_child_that_exits_ends_the_wait_at_once():
    clock = FakeClock()
    wait, _ = _wait(clock, ready_at=10_000.0, progress=lambda: Progress(0.0, 0), alive=lambda: clock.now < 3)
    with pytest.raises(ChildExited):
        wait.run()
    assert clock.now < 5


def test_a_real_process_cpu_time_is_read_from_proc(tmp_path):
    busy = spawn("busy", [sys.executable, "-c", "import time\nend = time.time() + 60\nwhile time.time() < end: pass"],
                 tmp_path / "busy.log")
    try:
        first = process_progress(busy.pid, busy.log_path)
        wait_until(lambda: process_progress(busy.pid, busy.log_path).cpu_s > first.cpu_s, 60,
                   "the busy process's CPU time to grow")
    finally:
        busy.kill_hard()


def test_wait_for_ok_names_a_stuck_child_and_quotes_its_log(tmp_path):
    # Prints one line, then sleeps without using CPU or writing: stuck, as far as anyone can tell.
    stuck = spawn("app server", [sys.executable, "-c", "print('importing the app', flush=True)\n"
                                                       "import time\ntime.sleep(120)"], tmp_path / "app.log")
    try:
        with pytest.raises(StackError) as error:
            wait_for_ok("http://127.0.0.1:9/healthz", stuck, timeout=3.0)
        assert "the app server seems stuck" in str(error.value) and "importing the app" in str(error.value)
        assert stuck.alive()  # the caller decides what to stop; the wait itself stops nothing
    finally:
        stuck.kill_hard()
