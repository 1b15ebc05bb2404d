"""Start a CLI the way a user's shell starts it, whatever an earlier test left in the test worker's own process.

A child inherits a signal that is ignored or blocked, and its CPU priority, from whoever starts it. A test that
stops the CLI with Ctrl-C (SIGINT) must not depend on what ran before it in the same pytest-xdist worker: two full
runs of the suite had three such CLIs (`drem car run`, `drem sim drive`) ignore the SIGINT the test sent, while each
passes alone. `from_a_shell` is their `preexec_fn`; `state` names what the child had, for a failure's message.
"""
from __future__ import annotations

import os
import signal
from pathlib import Path


def from_a_shell() -> None:
    """In the child before it runs: SIGINT at its default and no signal blocked, normal scheduling."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_SETMASK, set())
    try:
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    except (AttributeError, OSError):
        pass


def state(pid: int) -> str:
    """The process's blocked and ignored signals, scheduling policy and nice value (from /proc)."""
    try:
        fields = dict(line.split(":\t", 1) for line in Path(f"/proc/{pid}/status").read_text().splitlines()
                      if line.startswith(("SigBlk", "SigIgn", "SigCgt")))
        policy = os.sched_getscheduler(pid)
        nice = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[16]
    except (OSError, ValueError, IndexError):
        return f"pid {pid}: gone"
    return f"pid {pid}: {fields}, scheduling policy {policy}, nice {nice}"
