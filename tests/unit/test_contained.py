"""How a contained child's death is read (chalicelib.contained.child_death), the one reading behind what the console
model conversion and the scrutineering drive tell a racer. Real children, ended the ways a hostile model ends them."""
from __future__ import annotations

import subprocess
import sys

import pytest

from chalicelib.contained import child_death, limit_resources

pytestmark = pytest.mark.unit


def _child(code: str, **options) -> tuple[int, bytes]:
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, timeout=120, **options)
    return done.returncode, done.stderr


def test_a_child_stopped_at_its_cpu_limit_reads_as_cpu() -> None:
    returncode, stderr = _child("while True: pass", preexec_fn=lambda: limit_resources(1024**3, 1))
    assert child_death(returncode, stderr).cause == "cpu", "the racer is told the model used too much CPU time"


def test_a_child_whose_allocation_fails_reads_as_memory() -> None:
    returncode, stderr = _child("x = bytearray(8 * 1024**3)", preexec_fn=lambda: limit_resources(1024**3, 60))
    death = child_death(returncode, stderr)
    assert death.cause == "memory" and "MemoryError" in death.last_line


def test_a_killed_child_names_the_signal() -> None:
    returncode, stderr = _child("import os, signal; os.kill(os.getpid(), signal.SIGKILL)")
    death = child_death(returncode, stderr)
    assert (death.cause, death.how) == ("signal", "SIGKILL")


def test_a_child_that_exits_with_an_error_gives_its_code_and_last_line() -> None:
    returncode, stderr = _child("import sys; print('first', file=sys.stderr); sys.exit('the graph has no input')")
    death = child_death(returncode, stderr)
    assert (death.cause, death.how, death.last_line) == ("exit", "exit 1", "the graph has no input")
