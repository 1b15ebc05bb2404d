"""Keep `drem up`'s children running: a storage, live or app server (or a background worker) that dies is started
again, with backoff.

The storage server recovers everything acknowledged from its journal on start, and the app holds no state of its own
(left-over board publishes are finished by its sweeper), so restarting either is safe at any moment. Each crash and
restart is one plain line in the terminal. Only a child that keeps crashing (`RestartPolicy.max_crashes` within
`window_s`) stops `drem up`, and then the message quotes the log lines of the run that just failed.
"""
from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

from drem_local.stack import ManagedProcess, RunningStack, StackError


@dataclass(frozen=True)
class RestartPolicy:
    max_crashes: int = 5  # within window_s; one more and drem up gives up
    window_s: float = 120.0
    first_delay_s: float = 0.5
    max_delay_s: float = 8.0

    def delay(self, crashes_in_window: int) -> float:
        return min(self.max_delay_s, self.first_delay_s * 2 ** max(0, crashes_in_window - 1))


class GaveUp(Exception):
    """A child crashed too often; the message says which, how often, and its last log lines."""


@dataclass
class Supervisor:
    stack: RunningStack
    say: Callable[[str], None]
    policy: RestartPolicy = field(default_factory=RestartPolicy)
    clock: Callable[[], float] = time.monotonic
    sleep: Callable[[float], None] = time.sleep
    crashes: dict[str, deque[float]] = field(default_factory=dict)

    def check(self) -> None:
        """Restart whichever child has died (storage first: the app needs it to answer). Raises GaveUp."""
        if not self.stack.storage.alive():
            self._revive("storage", lambda: self.stack.storage, self.stack.restart_storage)
        live = self.stack.live
        if live is not None and not live.alive():
            self._revive("live", lambda: self.stack.live or live, self.stack.restart_live)
        if not self.stack.app.alive():
            self._revive("app", lambda: self.stack.app, self.stack.restart_app)
        trainer = self.stack.trainer
        if trainer is not None and not trainer.alive():  # a job it was training is queued again when it starts
            self._revive("trainer", lambda: self.stack.trainer or trainer, self.stack.restart_trainer)
        worker = self.stack.scrutineer
        if worker is not None and not worker.alive():  # its job's lease expires; the new one drives it again
            self._revive("scrutineer", lambda: self.stack.scrutineer or worker, self.stack.restart_scrutineer)

    def _revive(self, role: str, current: Callable[[], ManagedProcess], restart: Callable[[], None]) -> None:
        failed_restart: str | None = None  # why the last restart attempt failed (its own log lines included)
        while not current().alive():
            if role != "storage" and not self.stack.storage.alive():  # died since: everything else waits on it
                self._revive("storage", lambda: self.stack.storage, self.stack.restart_storage)
            died = current()
            now = self.clock()
            recent = self.crashes.setdefault(role, deque())
            recent.append(now)
            while recent and now - recent[0] > self.policy.window_s:
                recent.popleft()
            cause = _exit_description(died)
            if len(recent) > self.policy.max_crashes:
                detail = failed_restart or f"Last lines of {died.log_path} from that run:\n{died.log_tail()}"
                raise GaveUp(f"the {died.name} failed for the {_nth(len(recent))} time within "
                             f"{self.policy.window_s:.0f}s, so drem up stops here. {detail}")
            if failed_restart is not None:
                cause = "could not be started again"
            delay = self.policy.delay(len(recent))
            self.say(f"drem up: the {died.name} {cause}; restarting it in {delay:.1f}s "
                     f"(crash {len(recent)} of at most {self.policy.max_crashes} in {self.policy.window_s:.0f}s; "
                     f"log: {died.log_path}).")
            self.sleep(delay)
            started = self.clock()
            try:
                restart()
            except StackError as exc:
                failed_restart = str(exc)
                self.say(f"drem up: the {died.name} did not come back: {exc}")
                continue
            extra = " Every acknowledged write was recovered from its journal." if role == "storage" else ""
            self.say(f"drem up: the {current().name} is running again (pid {current().pid}, "
                     f"{self.clock() - started:.1f}s).{extra}")


def _exit_description(process: ManagedProcess) -> str:
    code = process.popen.returncode
    if code is not None and code < 0:
        import signal

        try:
            return f"was killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"was killed by signal {-code}"
    return f"stopped unexpectedly (exit code {code})"


def _nth(count: int) -> str:
    return {1: "1st", 2: "2nd", 3: "3rd"}.get(count, f"{count}th")
