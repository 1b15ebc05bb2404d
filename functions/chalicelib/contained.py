"""Running untrusted work (a racer's model graph) in a child process that cannot take the machine with it: the limits
the child sets on itself before exec, and how its parent stops it with everything it started. Used by the console
model conversion (domain/model_conversion) and the scrutineering drive (drem_local.workers.scrutineer)."""
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


def kill_group(process: subprocess.Popen[bytes]) -> None:
    """SIGKILL the child's whole process group (it was started with start_new_session=True), if still there."""
    try:
        os.killpg(process.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
