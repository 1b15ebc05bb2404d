"""Running untrusted work (a racer's model graph) in a child process that cannot take the machine with it: the limits
the child sets on itself before exec, the lowest CPU priority (so it never slows the pages people are watching), and
how its parent stops it with everything it started. Used by the console model conversion (domain/model_conversion)
and the scrutineering drive (drem_local.workers.scrutineer)."""
from __future__ import annotations

import os
import signal
import subprocess


def limit_resources(memory_bytes: int, cpu_seconds: int) -> None:
    """In the child, before exec: address space and CPU time capped (the kernel ends it past either), no core dump."""
    import resource

    resource.setrlimit(resource.RLIMIT_AS, (memory_bytes, memory_bytes))
    resource.setrlimit(resource.RLIMIT_CPU, (cpu_seconds, cpu_seconds))
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))


BACKGROUND_NICENESS = 10  # below the app server and the live server (0): the pages win every contest for the CPU


def lowest_priority(niceness: int = BACKGROUND_NICENESS) -> None:
    """In the calling process: `nice`, then SCHED_IDLE where Linux offers it. SCHED_IDLE runs the process only on CPU
    time nothing else wants, and any other task that wakes up (the app server answering a spectator) takes the CPU
    from it at once; `nice` alone still leaves a niced task its small share and a wait for the scheduler's wake-up
    granularity. The nice value stands where SCHED_IDLE is refused (not Linux)."""
    os.nice(niceness)
    try:
        os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
    except (AttributeError, OSError):
        pass


def kill_group(process: subprocess.Popen[bytes]) -> None:
    """SIGKILL the child's whole process group (it was started with start_new_session=True), if still there."""
    try:
        os.killpg(process.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
