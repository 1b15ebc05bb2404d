"""Scrutineering: test-drive an uploaded model archive on the event's track before it races.

ONNX models (our own archives) are driven for N lap attempts in the simulator. Console models carry a
TensorFlow graph (``agent/model.pb``) that the simulator cannot run; they are reported, not guessed at.
DREM events name a *track type*; `track_for_event` maps it to the simulator track that resembles it.
"""
from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import BaseModel

from drem_sim.learn import scrutiny_words
from drem_sim.learn.package import ArchiveError

Verdict = Literal["passed", "failed", "cannot_scrutineer", "invalid"]
PASS_COMPLETION_PCT = 100.0  # every attempted lap finished
FALLBACK_TRACK = "reinvent_base"

# DREM event track type -> the simulator track closest to it.
EVENT_TRACKS: dict[str, str] = {
    "REINVENT_2018": "reinvent_base",
    "ATOZ_SPEEDWAY": "reInvent2019_wide",
    "SUMMIT_SPEEDWAY": "2022_summit_speedway",
    "FOREVER_RACEWAY": "2024_reinvent_champ_ccw",
    "REINVENT_2019": "reInvent2019_track",
}


class EventTrack(BaseModel):
    track_type: str
    track: str
    note: str | None = None  # set when the track type has no simulator twin


def track_for_event(track_type: str) -> EventTrack:
    key = track_type.strip().upper()
    if key in EVENT_TRACKS:
        return EventTrack(track_type=key, track=EVENT_TRACKS[key])
    return EventTrack(track_type=key, track=FALLBACK_TRACK,
                      note=f"no simulator track for {key or 'an empty track type'}; driven on {FALLBACK_TRACK}")


class ScrutineerReport(BaseModel):
    archive: str
    track: str
    laps: int
    verdict: Verdict
    message: str  # a sentence for the racer (drem_sim.learn.scrutiny_words), never an exception's name
    detail: str | None = None  # what the software said, for staff only
    track_type: str | None = None
    note: str | None = None
    completion_pct: float | None = None  # mean progress per lap attempt (drem_sim.learn.evaluate)
    attempts: int | None = None
    laps_completed: int = 0
    lap_times_s: list[float] = []
    mean_lap_time_s: float | None = None
    best_lap_time_s: float | None = None
    offtrack_count: int = 0


def _words(failure: scrutiny_words.PlainFailure) -> dict[str, str]:
    return {"message": failure.message, "detail": failure.detail}


def scrutineer_for_event(archive: str | Path, track_type: str, laps: int = 3, seed: int = 0) -> ScrutineerReport:
    """Scrutineer on the simulator twin of a DREM event's track type (e.g. ATOZ_SPEEDWAY)."""
    event_track = track_for_event(track_type)
    report = scrutineer(archive, event_track.track, laps, seed)
    message = f"{report.message} ({event_track.note})" if event_track.note and report.verdict in (
        "passed", "failed") else report.message  # which real track stood in for one drem has no twin of
    return report.model_copy(update={"track_type": event_track.track_type, "note": event_track.note,
                                     "message": message})


def scrutineer(archive: str | Path, track: str, laps: int = 1, seed: int = 0) -> ScrutineerReport:
    from drem_sim.learn.evaluate import evaluate_model
    from drem_sim.learn.pilot import NotRaceableModel, TensorFlowModelError
    from drem_sim.tracks import TrackError, load_track

    if laps < 1:
        raise ValueError("scrutineering needs at least one lap")
    base = {"archive": Path(archive).name, "track": track, "laps": laps}
    try:
        load_track(track)
    except TrackError as error:
        return ScrutineerReport(**base, verdict="cannot_scrutineer", **_words(scrutiny_words.track_unavailable(
            track, error)))
    try:
        metrics = evaluate_model(archive, track, laps, seed)
    except NotRaceableModel as error:
        return ScrutineerReport(**base, verdict="invalid", **_words(scrutiny_words.not_raceable(error.reason,
                                                                                              error.detail)))
    except TensorFlowModelError as error:
        return ScrutineerReport(**base, verdict="cannot_scrutineer", **_words(scrutiny_words.console_model_unusable(
            str(error).removeprefix("cannot scrutineer: "))))
    except ArchiveError as error:
        return ScrutineerReport(**base, verdict="invalid", **_words(scrutiny_words.archive_unusable(str(error))))
    except Exception as error:  # a racer's graph can fail in ways of its own: a sentence, never a traceback
        return ScrutineerReport(**base, verdict="cannot_scrutineer", **_words(scrutiny_words.model_stopped(
            track, error)))
    passed = metrics.completion_pct >= PASS_COMPLETION_PCT
    lap = f", mean lap {metrics.mean_lap_time_s:.2f}s" if metrics.mean_lap_time_s is not None else ""
    return ScrutineerReport(
        **base, verdict="passed" if passed else "failed",
        message=f"{metrics.laps_completed}/{metrics.attempts} laps completed on {track}, "
                f"completion {metrics.completion_pct:.1f}%{lap}",
        completion_pct=metrics.completion_pct, attempts=metrics.attempts, laps_completed=metrics.laps_completed,
        lap_times_s=metrics.lap_times_s, mean_lap_time_s=metrics.mean_lap_time_s,
        best_lap_time_s=metrics.best_lap_time_s, offtrack_count=metrics.offtrack_count,
    )
