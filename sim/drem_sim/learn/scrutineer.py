"""Scrutineering: test-drive an uploaded model archive in the simulator before it races.

ONNX models (our own archives) are driven directly. Console models carry a TensorFlow graph
(``agent/model.pb``) that the simulator cannot run; they are reported, not guessed at.
"""
from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import BaseModel

from drem_sim.learn.package import ArchiveError

Verdict = Literal["passed", "failed", "cannot_scrutineer", "invalid"]
PASS_COMPLETION_PCT = 100.0  # every attempted lap finished


class ScrutineerReport(BaseModel):
    archive: str
    track: str
    laps: int
    verdict: Verdict
    message: str
    completion_pct: float | None = None
    laps_completed: int = 0
    lap_times_s: list[float] = []
    mean_lap_time_s: float | None = None
    best_lap_time_s: float | None = None
    offtrack_count: int = 0


def scrutineer(archive: str | Path, track: str, laps: int = 1, seed: int = 0) -> ScrutineerReport:
    from drem_sim.learn.evaluate import evaluate_model
    from drem_sim.learn.pilot import TensorFlowModelError

    base = {"archive": Path(archive).name, "track": track, "laps": laps}
    try:
        metrics = evaluate_model(archive, track, laps, seed)
    except TensorFlowModelError as error:
        return ScrutineerReport(**base, verdict="cannot_scrutineer", message=str(error))
    except ArchiveError as error:
        return ScrutineerReport(**base, verdict="invalid", message=f"cannot scrutineer: {error}")
    passed = metrics.completion_pct >= PASS_COMPLETION_PCT
    lap = f", mean lap {metrics.mean_lap_time_s:.2f}s" if metrics.mean_lap_time_s is not None else ""
    return ScrutineerReport(
        **base, verdict="passed" if passed else "failed",
        message=f"{metrics.laps_completed}/{metrics.attempts} laps completed on {track}, "
                f"completion {metrics.completion_pct:.1f}%{lap}",
        completion_pct=metrics.completion_pct, laps_completed=metrics.laps_completed,
        lap_times_s=metrics.lap_times_s, mean_lap_time_s=metrics.mean_lap_time_s,
        best_lap_time_s=metrics.best_lap_time_s, offtrack_count=metrics.offtrack_count,
    )
