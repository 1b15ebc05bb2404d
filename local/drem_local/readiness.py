"""Waiting for a child of `drem up` to become ready by its progress, not by a fixed deadline.

On a busy laptop (a power cut's restart, a build running beside it) the app can take a minute to import; a fixed
30 s deadline then stopped the whole stack, storage included, although nothing was wrong. Here a child may take as
long as it needs while it visibly works: its CPU time grows or its log grows. Only a child that does neither for
`stall_s` seconds is stuck (or one that exits). Every `report_every_s` the wait says in one line what it is waiting
for, how long it has waited and what the child has done meanwhile, so a person watching knows it is not hung.
"""
from __future__ import annotations

import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path


@dataclass(frozen=True)
class Progress:
    """What a child has done so far: CPU seconds it (and the children it reaped) used, and its log's size."""
    cpu_s: float
    log_bytes: int


def process_progress(pid: int, log_path: Path) -> Progress:
    """From /proc/<pid>/stat (utime, stime, cutime, cstime, in clock ticks) and the log's size. Without /proc
    (not Linux) the CPU part stays 0 and the log alone shows progress."""
    cpu_s = 0.0
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
        fields = stat[stat.rindex(")") + 2:].split()  # after "pid (comm) ": field 3 (state) is fields[0]
        ticks = sum(int(value) for value in fields[11:15])  # utime stime cutime cstime: fields 14..17
        cpu_s = ticks / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError):
        pass
    try:
        log_bytes = log_path.stat().st_size
    except OSError:
        log_bytes = 0
    return Progress(cpu_s, log_bytes)


class StillWaiting(Exception):
    """The child made no progress for the stall window (the message says what it was waiting for)."""


class ChildExited(Exception):
    """The child exited before it was ready."""


@dataclass
class ReadinessWait:
    """Poll `ready()` until it is true. `what` names the wait for people ("the app server (pid 123) to answer
    http://127.0.0.1:8000/healthz"). Raises ChildExited when `alive()` turns false first, StillWaiting when
    `progress()` stays the same for `stall_s` seconds."""
    what: str
    ready: Callable[[], bool]
    alive: Callable[[], bool]
    progress: Callable[[], Progress]
    stall_s: float = 120.0
    say: Callable[[str], None] | None = None
    report_every_s: float = 10.0
    poll_s: float = 0.05
    clock: Callable[[], float] = time.monotonic
    sleep: Callable[[float], None] = time.sleep
    reports: list[str] = field(default_factory=list)

    def run(self) -> float:
        """Seconds it took until `ready()`."""
        started = self.clock()
        last = self.progress()
        first = last
        moved_at = started
        next_report = started + self.report_every_s
        while True:
            if self.ready():
                return self.clock() - started
            if not self.alive():
                raise ChildExited(self.what)
            now = self.clock()
            current = self.progress()
            if current != last:
                last, moved_at = current, now
            elif now - moved_at >= self.stall_s:
                raise StillWaiting(f"still waiting for {self.what} after {now - started:.0f}s, and it has done nothing "
                                   f"for the last {now - moved_at:.0f}s (no CPU time used, no log line written)")
            if now >= next_report:
                self._report(now - started, now - moved_at, first, current)
                next_report = now + self.report_every_s
            self.sleep(self.poll_s)

    def _report(self, waited_s: float, idle_s: float, first: Progress, current: Progress) -> None:
        done = (f"{current.cpu_s - first.cpu_s:.1f}s of CPU and {current.log_bytes - first.log_bytes} bytes of log "
                "since the wait began")
        if idle_s < self.report_every_s:
            state = f"it is working ({done}), so drem up keeps waiting (a busy machine only makes it slower)"
        else:
            state = (f"it has done nothing for {idle_s:.0f}s ({done}); drem up gives it until {self.stall_s:.0f}s "
                     "without progress")
        line = f"drem up: still waiting for {self.what}: {waited_s:.0f}s so far; {state}."
        self.reports.append(line)
        if self.say is not None:
            self.say(line)
