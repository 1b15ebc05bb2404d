"""A crash at an exact point of the journal, for the chaos bench and its tests: kill -9 chosen processes right after
the storage server made a given journal record durable (before moto applies it and before anything is answered).

Only armed when the server was started with `DREM_KILL_POINT_FILE` in its environment (the harness sets it; `drem up`
never does), and only by that file, which the harness writes next to the state (0600, same user):
`{"at_seq": N, "pids": [app or worker pids], "self": true|false}`. The file is deleted before anything is killed, so
the restarted server never fires it again. Kill points chosen this way land anywhere inside a multi-step operation
(after its Nth storage write), the way an independent kill -9 campaign picks them on the journal, and they are the same
on a loaded machine as on an idle one, where a timer would land somewhere else each run.
"""
from __future__ import annotations

import json
import logging
import os
import signal
from pathlib import Path

log = logging.getLogger("drem.durable")

ENV = "DREM_KILL_POINT_FILE"


class KillPoint:
    def __init__(self, path: Path) -> None:
        self.path = path

    @classmethod
    def from_environment(cls) -> KillPoint | None:
        path = os.environ.get(ENV)
        return cls(Path(path)) if path else None

    def after_record(self, seq: int) -> None:
        """Called under the server's lock once record `seq` is durable."""
        try:
            armed = json.loads(self.path.read_text())
        except (OSError, ValueError):
            return  # not armed (or being written: the next record looks again)
        if seq < int(armed.get("at_seq", 0)):
            return
        self.path.unlink(missing_ok=True)
        log.warning("kill point: journal record %d is durable; kill -9 of %s%s", seq, armed.get("pids", []),
                    " and this storage server" if armed.get("self") else "")
        for pid in armed.get("pids", []):
            try:
                os.kill(int(pid), signal.SIGKILL)
            except (ProcessLookupError, PermissionError):
                pass
        if armed.get("self"):
            os.kill(os.getpid(), signal.SIGKILL)


def arm(path: Path, at_seq: int, pids: list[int], *, kill_storage: bool) -> None:
    """Arm the kill point (atomically: the server never reads half a file)."""
    partial = path.with_suffix(".partial")
    fd = os.open(partial, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w") as out:
        json.dump({"at_seq": at_seq, "pids": pids, "self": kill_storage}, out)
    os.replace(partial, path)


def disarm(path: Path) -> None:
    path.unlink(missing_ok=True)
