"""`drem up`'s supervisor: crashed children are restarted with growing delays, and only a child that keeps failing
stops drem up, quoting the log of the run that failed (not of earlier runs)."""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

from drem_local.stack import ManagedProcess, StackError, spawn
from drem_local.supervise import GaveUp, RestartPolicy, Supervisor

pytestmark = pytest.mark.unit


def _crashing(name: str, log: Path, words: str) -> ManagedProcess:
    process = spawn(name, [sys.executable, "-c", f"print({words!r}); raise SystemExit(7)"], log)
    process.popen.wait(10)
    return process


class FakeStack:
    """Only what the supervisor touches: its children (no live server; workers absent unless a test sets one) and
    their restart methods."""

    def __init__(self, storage: ManagedProcess, app: ManagedProcess, restart_storage) -> None:
        self.storage, self.app = storage, app
        self.live = None  # no live server in these tests
        self.restart_storage = lambda: restart_storage(self)
        self.restart_app = lambda: None
        self.trainer: ManagedProcess | None = None
        self.scrutineer: ManagedProcess | None = None


def _alive(log: Path) -> ManagedProcess:
    return spawn("app server", [sys.executable, "-c", "import time; time.sleep(30)"], log)


def test_a_crashed_child_is_restarted_after_a_growing_delay(tmp_path):
    said, slept = [], []
    runs = iter(range(100))

    def restart(stack):
        stack.storage = _alive(tmp_path / "storage.log") if next(runs) >= 1 else _crashing(
            "storage server", tmp_path / "storage.log", "boom again")

    app = _alive(tmp_path / "app.log")
    stack = FakeStack(_crashing("storage server", tmp_path / "storage.log", "boom"), app, restart)
    try:
        Supervisor(stack, said.append, RestartPolicy(max_crashes=5), sleep=slept.append).check()
        assert stack.storage.alive() and slept == [0.5, 1.0]
        assert "the storage server stopped unexpectedly (exit code 7); restarting it in 0.5s" in said[0]
        assert "is running again" in said[-1]
    finally:
        for process in (stack.storage, app):
            process.kill_hard()


def test_a_child_that_keeps_crashing_stops_drem_up_with_the_last_runs_log(tmp_path):
    log = tmp_path / "storage.log"
    log.write_text("an old run's line that is not the cause\n" * 50)
    counter = iter(range(100))

    def restart(stack):
        stack.storage = _crashing("storage server", log, f"cause of crash {next(counter)}")

    app = _alive(tmp_path / "app.log")
    stack = FakeStack(_crashing("storage server", log, "first cause"), app, restart)
    try:
        with pytest.raises(GaveUp) as gave_up:
            Supervisor(stack, lambda line: None, RestartPolicy(max_crashes=3), sleep=lambda s: None).check()
    finally:
        app.kill_hard()
    message = str(gave_up.value)
    assert "failed for the 4th time" in message
    assert "cause of crash 2" in message and "old run" not in message and "cause of crash 1" not in message


def test_a_restart_that_fails_to_start_counts_as_a_crash_and_its_reason_is_shown(tmp_path):
    def restart(stack):
        raise StackError("the storage server exited with code 3 before it answered. moto version mismatch")

    app = _alive(tmp_path / "app.log")
    stack = FakeStack(_crashing("storage server", tmp_path / "storage.log", "x"), app, restart)
    said = []
    try:
        with pytest.raises(GaveUp) as gave_up:
            Supervisor(stack, said.append, RestartPolicy(max_crashes=2), sleep=lambda s: None).check()
    finally:
        app.kill_hard()
    assert "moto version mismatch" in str(gave_up.value)
    assert any("did not come back" in line for line in said)


def test_a_crashed_booth_trainer_is_restarted_like_the_app(tmp_path):
    said: list[str] = []
    stack = FakeStack(_alive(tmp_path / "storage.log"), _alive(tmp_path / "app.log"), lambda stack: None)
    stack.trainer = _crashing("booth trainer", tmp_path / "trainer.log", "torch went away")

    def restart_trainer() -> None:
        stack.trainer = _alive(tmp_path / "trainer.log")

    stack.restart_trainer = restart_trainer
    try:
        Supervisor(stack, said.append, RestartPolicy(max_crashes=3), sleep=lambda s: None).check()
        assert stack.trainer.alive()
        assert "the booth trainer stopped unexpectedly (exit code 7)" in said[0] and "running again" in said[1]
    finally:
        for child in (stack.storage, stack.app, stack.trainer):
            child.kill_hard()


def test_storage_that_dies_while_the_app_is_restarted_is_started_again_first(tmp_path):
    """A power cut seen in two checks: the app is dead, storage not yet; storage dies while the app restarts (whose
    wait then fails instead of waiting for ever on answers of 503), and the next attempt starts storage first."""
    said, order = [], []

    def restart_storage(stack):
        order.append("storage")
        stack.storage = _alive(tmp_path / "storage.log")

    stack = FakeStack(_alive(tmp_path / "storage.log"), _crashing("app server", tmp_path / "app.log", "killed"),
                      restart_storage)

    def restart_app():
        order.append("app")
        if order == ["app"]:  # the first attempt: storage goes down meanwhile
            stack.storage.kill_hard()
            raise StackError("the storage server stopped while the app server was starting")
        stack.app = _alive(tmp_path / "app.log")

    stack.restart_app = restart_app
    try:
        Supervisor(stack, said.append, RestartPolicy(max_crashes=5), sleep=lambda _s: None).check()
        assert order == ["app", "storage", "app"]
        assert stack.storage.alive() and stack.app.alive()
    finally:
        for process in (stack.storage, stack.app):
            process.kill_hard()
