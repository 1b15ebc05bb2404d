"""The storage server's answer when its disk refuses a write: 507 with drem's words, never moto's 500.

The request was not journaled, so it was not stored and nothing acknowledged before it is touched; the client may
repeat it once there is space again. The error codes are also known to the app (chalicelib.storage.aws_errors),
which passes the message on to the person who made the request, and to `drem up` (drem_local.stack).
"""
from __future__ import annotations

from pathlib import Path

from drem_local.disk import FULL, problem_of, sentence
from drem_local.durable.sigv4 import Refusal

DISK_FULL_CODE = "DremDataDiskFull"
DISK_READ_ONLY_CODE = "DremDataDiskReadOnly"
DISK_ERROR_CODES = (DISK_FULL_CODE, DISK_READ_ONLY_CODE)
INSUFFICIENT_STORAGE = 507


def disk_refusal(exc: BaseException, state_dir: Path) -> Refusal | None:
    """The refusal for `exc` when it is a full or read-only disk; None for any other failure."""
    problem = problem_of(exc)
    if problem is None:
        return None
    code = DISK_FULL_CODE if problem == FULL else DISK_READ_ONLY_CODE
    return Refusal(INSUFFICIENT_STORAGE, code, sentence(
        problem, state_dir, "try again: this change was not stored, and everything stored before it is kept."))
