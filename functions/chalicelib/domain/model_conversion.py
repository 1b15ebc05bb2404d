"""Console models (`agent/model.pb`) become scrutineerable: convert them to ONNX in a contained worker process.

The conversion itself (OpenVINO reads the `.pb`, `onnx` writes the graph, both runtimes must agree to 1e-4) lives in
`drem_sim.console.convert`; this module only decides how it runs. A `.pb` is hostile input and OpenVINO is native
code, so the worker is a separate process with a wall-clock limit, a CPU-time limit and an address-space limit: a
graph that crashes the converter, loops or balloons costs that process only, and the upload gets a clear verdict.
The worker runs at the lowest CPU priority (chalicelib.contained.lowest_priority), so a console upload never slows
the public pages the app serves meanwhile.

The converter is optional: where OpenVINO is not installed (the Lambda bundle, a car), console models stay AVAILABLE
for stock cars and are marked "cannot be scrutineered: the model converter is not installed on this server".
"""
from __future__ import annotations

import importlib.util
import json
import os
import shutil
import subprocess
import sys
import tempfile
import threading
from collections.abc import Callable
from pathlib import Path
from typing import IO, Literal

from pydantic import BaseModel, ValidationError

from chalicelib.contained import child_death, kill_group, limit_resources, lowest_priority
from chalicelib.formats.model_archive.extract import ArchiveRejected, safe_extract

GiB = 1024 ** 3
WORKER_MODULE = "drem_sim.console.convert"
# not_raceable: a stock car cannot load the model or would drive it wrongly (the upload becomes NOT_VALID)
Scrutiny = Literal["ready", "cannot_scrutineer", "not_raceable"]


class ConversionLimits(BaseModel):
    wall_seconds: float = 60.0
    cpu_seconds: int = 120
    memory_bytes: int = 6 * GiB  # address space: OpenVINO maps far more than it touches


class ConversionOutcome(BaseModel):
    scrutiny: Scrutiny
    reason: str | None = None
    detail: str | None = None  # for staff: the converter's own words (OpenVINO's message) behind `reason`
    max_abs_diff: float | None = None
    seconds: float | None = None
    onnx: bytes | None = None  # the converted graph when scrutiny is ready


class _WorkerAnswer(BaseModel):
    outcome: Literal["converted", "cannot_scrutineer", "not_raceable"]
    reason: str | None = None
    detail: str | None = None
    max_abs_diff: float | None = None
    seconds: float = 0.0


def converter_installed() -> bool:
    return all(importlib.util.find_spec(name) is not None for name in ("openvino", "onnx", "drem_sim"))


def _cannot(reason: str) -> ConversionOutcome:
    return ConversionOutcome(scrutiny="cannot_scrutineer", reason=reason)


class ConsoleConverter:
    """`keep_spare`: keep one worker process started ahead of time (OpenVINO loaded, waiting for a request), so a
    conversion does not wait seconds for the imports. Each conversion still gets a process of its own, with its
    limits (they count from the process's start, imports included); a new spare is started as one is taken."""

    def __init__(self, limits: ConversionLimits | None = None, *, python: str = sys.executable,
                 keep_spare: bool = False) -> None:
        self.limits = limits or ConversionLimits()
        self.python = python
        self.keep_spare = keep_spare
        self._spare: subprocess.Popen[bytes] | None = None
        self._spare_lock = threading.Lock()

    def warm_up(self) -> None:
        """Start the spare worker now if there is none (an upload is on its way)."""
        if not self.keep_spare or not converter_installed():
            return
        with self._spare_lock:
            if self._spare is None or self._spare.poll() is not None:
                self._spare = self._start_worker(["--wait"], cwd=Path(tempfile.gettempdir()))

    def _take_worker(self) -> subprocess.Popen[bytes] | None:
        with self._spare_lock:
            spare, self._spare = self._spare, None
        self.warm_up()  # the next one loads while this one converts
        return spare if spare is not None and spare.poll() is None else None

    def _start_worker(self, arguments: list[str], cwd: Path) -> subprocess.Popen[bytes]:
        environment = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONUNBUFFERED": "1"}
        return subprocess.Popen([self.python, "-m", WORKER_MODULE, *arguments], stdin=subprocess.PIPE,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=environment, cwd=cwd,
                                start_new_session=True, preexec_fn=_limit(self.limits))

    def convert(self, archive: IO[bytes]) -> ConversionOutcome:
        """Extract the (already judged AVAILABLE) archive into a sandbox and convert its `.pb` in a worker."""
        if not converter_installed():
            return _cannot("the model converter (OpenVINO) is not installed on this server")
        workdir = Path(tempfile.mkdtemp(prefix="convert-"))
        try:
            try:
                extracted = safe_extract(archive, workdir)
            except ArchiveRejected as rejected:
                return _cannot(f"the archive could not be unpacked again: {rejected.message}")
            if extracted.report.model_kind != "tensorflow":
                return _cannot("the archive holds no TensorFlow graph to convert")
            out = workdir / "converted.onnx"
            answer = self._run_worker(extracted.model_path, extracted.metadata_path, out)
            if isinstance(answer, ConversionOutcome):
                return answer
            if answer.outcome == "not_raceable":
                return ConversionOutcome(scrutiny="not_raceable", reason=answer.reason, detail=answer.detail,
                                         seconds=answer.seconds)
            if answer.outcome != "converted" or not out.is_file():
                return ConversionOutcome(scrutiny="cannot_scrutineer", reason=answer.reason,
                                         max_abs_diff=answer.max_abs_diff, seconds=answer.seconds)
            return ConversionOutcome(scrutiny="ready", max_abs_diff=answer.max_abs_diff, seconds=answer.seconds,
                                     onnx=out.read_bytes())
        finally:
            shutil.rmtree(workdir, ignore_errors=True)

    def _run_worker(self, pb: Path, metadata: Path, out: Path) -> _WorkerAnswer | ConversionOutcome:
        limits = self.limits
        process = self._take_worker() if self.keep_spare else None
        request: bytes | None = None
        if process is not None:
            request = (json.dumps([str(pb), str(metadata), str(out)]) + "\n").encode()
        else:
            process = self._start_worker([str(pb), str(metadata), str(out)], cwd=out.parent)
        try:
            stdout, stderr = process.communicate(input=request, timeout=limits.wall_seconds)
        except subprocess.TimeoutExpired:
            kill_group(process)
            process.communicate()
            return _cannot(f"the conversion took longer than {limits.wall_seconds:.0f} s and was stopped")
        if process.returncode != 0:
            return _cannot(_crash_reason(process.returncode, stderr, limits))
        try:
            return _WorkerAnswer.model_validate_json(stdout.decode("utf-8", "replace").strip().splitlines()[-1])
        except (ValidationError, IndexError):
            return _cannot("the converter gave no answer")


def _limit(limits: ConversionLimits) -> Callable[[], None]:  # a preexec_fn
    def apply() -> None:
        # The app server starts it, but it must not compete with the app for the CPU: its imports (seconds of
        # OpenVINO) and the conversion run on CPU time the pages being watched do not want.
        lowest_priority()
        limit_resources(limits.memory_bytes, limits.cpu_seconds)
    return apply


def _crash_reason(returncode: int, stderr: bytes, limits: ConversionLimits) -> str:
    death = child_death(returncode, stderr)
    if death.cause == "cpu":
        return f"the conversion used more than {limits.cpu_seconds} s of CPU and was stopped"
    if death.cause == "signal":
        return f"the converter crashed ({death.how})"
    if death.cause == "memory":
        return f"the conversion needed more than {limits.memory_bytes // GiB} GiB of memory and was stopped"
    return f"the converter failed (exit {returncode}): {death.last_line[:200]}".rstrip(": ")


__all__ = ["ConsoleConverter", "ConversionLimits", "ConversionOutcome", "Scrutiny", "converter_installed"]
