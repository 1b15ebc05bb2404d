"""Running untrusted work (a racer's model graph) in a child process that cannot take the machine with it: the limits
the child sets on itself before exec, the lowest CPU priority (so it never slows the pages people are watching), and
how its parent stops it with everything it started. Used by the console model conversion (domain/model_conversion)
and the scrutineering drive (drem_local.workers.scrutineer), which also read a child's death the same way
(`child_death`)."""
from __future__ import annotations

import os
import signal
import subprocess
from dataclasses import dataclass

CPU_GRACE_S = 5


def limit_resources(memory_bytes: int, cpu_seconds: int) -> None:
    """In the child, before exec: address space and CPU time capped (the kernel ends it past either), no core dump."""
    import resource

    resource.setrlimit(resource.RLIMIT_AS, (memory_bytes, memory_bytes))
    # SIGXCPU comes at the soft limit only when the hard one is above it (equal limits mean a bare SIGKILL, which
    # reads as "killed", not "used more than its CPU time"); the hard limit still ends a child that ignores SIGXCPU.
    resource.setrlimit(resource.RLIMIT_CPU, (cpu_seconds, cpu_seconds + CPU_GRACE_S))
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))


BACKGROUND_NICENESS = 10  # below the app server and the live server (0): the pages win every contest for the CPU


def lowest_priority(niceness: int = BACKGROUND_NICENESS) -> list[int]:
    """In the calling process: `nice`, then SCHED_IDLE where Linux offers it, on one core only (`background_core`,
    whose cores it returns).
    SCHED_IDLE runs the process only on CPU time nothing else wants, and another task that wakes up (the app server
    answering a spectator) takes the CPU from it at once (bench/idle_preemption.py: p99 0.03 ms beside a busy loop,
    rarely up to a 4 ms tick on a PREEMPT_NONE 250 Hz kernel; docs/league.md); `nice` alone gave way as fast in that
    probe, but still takes its small share of a core that normal tasks keep busy. The nice value stands where
    SCHED_IDLE is refused (not Linux)."""
    os.nice(niceness)
    try:
        os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
    except (AttributeError, OSError):
        pass
    return background_core()


def background_core() -> list[int]:
    """Keep the calling process (and every child it starts from now on) to the last core when it may use several, and
    say which cores it has. Idle-class work on every core still cost the pages: on the 2-core laptop, the public board
    (one reader, back to back) went from p95 0.65 ms to 2.0-3.0 ms beside two idle-class simulator drives, and stayed at
    0.7-0.9 ms with the same drives held to one core (docs/league.md). The scrutineer, its drives, the console
    converter and the booth's trainer all run there, taking turns; the other cores stay free for serving."""
    if not hasattr(os, "sched_getaffinity"):
        return []
    cores = sorted(os.sched_getaffinity(0))
    if len(cores) > 1:
        try:
            os.sched_setaffinity(0, {cores[-1]})
        except OSError:
            return cores
        return [cores[-1]]
    return cores


def kill_group(process: subprocess.Popen[bytes]) -> None:
    """SIGKILL the child's whole process group (it was started with start_new_session=True), if still there."""
    try:
        os.killpg(process.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass


@dataclass(frozen=True)
class ChildDeath:
    """Why a contained child ended badly, read from its exit status and stderr (one reading for every caller, which
    then says it in its own words). `cause` is "cpu" (its CPU limit, SIGXCPU), "memory" (an allocation failed under
    its address-space limit), "signal" (killed otherwise; `how` names the signal) or "exit" (`how`: "exit N")."""
    cause: str
    how: str
    stderr: str

    @property
    def last_line(self) -> str:
        return next((line for line in reversed(self.stderr.strip().splitlines()) if line.strip()), "")


def child_death(returncode: int, stderr: bytes) -> ChildDeath:
    text = stderr.decode("utf-8", "replace")
    if returncode < 0:
        name = signal.Signals(-returncode).name if -returncode in signal.valid_signals() else str(-returncode)
        return ChildDeath("cpu" if name == "SIGXCPU" else "signal", name, text)
    if "MemoryError" in text or "bad_alloc" in text or "Cannot allocate memory" in text:
        return ChildDeath("memory", f"exit {returncode}", text)
    return ChildDeath("exit", f"exit {returncode}", text)
