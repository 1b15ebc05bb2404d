"""What the league page and its fragment show: display strings computed here, so templates only lay them out."""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from chalicelib.domain.league import Board, BoardQuery, SortKey, Submission


@dataclass(frozen=True)
class BoardRowView:
    rank: int
    racer: str
    model_name: str
    algorithm: str
    sensor: str
    action_space: str
    best_lap: str
    average_lap: str
    laps: str
    completion: str
    off_track: int
    resets: int
    submitted: str
    detail_url: str
    detail_id: str
    source: str  # "verified by drem" or "self-reported from logs"
    verified: bool


@dataclass(frozen=True)
class BoardView:
    track: str
    sort: str
    sorts: list[tuple[str, str]]
    query: dict[str, Any]
    rows: list[BoardRowView]
    api_url: str


def seconds(value: float | None) -> str:
    return f"{value:.3f} s" if value is not None else "–"


def board_view(board: Board, query: BoardQuery, names: Mapping[str, str] | None = None) -> BoardView:
    """`names`: each racer's display name by sign-in name (the rows keep the sign-in name in their links)."""
    names = names or {}
    rows = [BoardRowView(
        rank=ranked.rank, racer=names.get(e.racer, e.racer), model_name=e.model_name, algorithm=e.algorithm,
        sensor=" + ".join(e.sensor),
        action_space=e.action_space, best_lap=seconds(e.best_lap_s), average_lap=seconds(e.average_lap_s),
        laps=f"{e.laps_completed}/{e.trials}", completion=f"{e.average_completion_pct:.1f} %",
        off_track=e.off_track_total, resets=e.reset_total, submitted=e.submitted_at[:16].replace("T", " "),
        detail_url=f"/league/{board.track}/racers/{e.racer}", detail_id=f"detail-{ranked.rank}",
        source=e.source + (" (drem's re-drive pending)" if e.verification == "pending" else ""),
        verified=e.verified)
        for ranked in board.entries for e in [ranked.entry]]
    shown = query.model_dump(mode="json", exclude_none=True)
    return BoardView(track=board.track, sort=board.sort.value,
                     sorts=[(SortKey.BEST.value, "Best lap"), (SortKey.AVG.value, "Average lap")],
                     query={k: shown.get(k, "") for k in ("algorithm", "sensor", "since", "until")},
                     rows=rows, api_url=f"/api/league/{board.track}")


@dataclass(frozen=True)
class SubmissionView:
    racer: str
    model_name: str
    track: str
    submitted: str
    layout: str
    algorithm: str
    sensor: str
    action_space: str
    training: str
    hyperparameters: list[tuple[str, str]]
    trials: list[dict[str, str]]
    verification: str


def submission_view(submission: Submission, shown_name: str = "") -> SubmissionView:
    """`shown_name`: the racer's display name (only one racer here, so never told apart); "": the sign-in name."""
    best = submission.training_best_completion_pct
    training = f"{submission.training_episodes} episodes" + (f", best completion {best:.0f} %" if best is not None
                                                              else "") + (f" on {submission.training_track}"
                                                                          if submission.training_track else "")
    return SubmissionView(
        racer=shown_name or submission.racer, model_name=submission.model_name, track=submission.track,
        submitted=submission.submitted_at[:19].replace("T", " "), layout=submission.layout,
        algorithm=submission.algorithm, sensor=" + ".join(submission.sensor), action_space=submission.action_space,
        training=training,
        hyperparameters=[(key, "" if value is None else str(value))
                         for key, value in sorted(submission.hyperparameters.items())],
        trials=[{"trial": str(t.trial), "time": seconds(t.time_s) if t.completed else "–",
                 "completion": f"{t.completion_pct:.0f} %", "off_track": str(t.off_track_count),
                 "resets": str(t.reset_count), "status": t.status} for t in submission.trials],
        verification=verification_text(submission))


def verification_text(submission: Submission) -> str:
    words = {"self_reported": "Self-reported from logs (no model pushed for drem to re-drive).",
             "pending": "Self-reported from logs until drem has re-driven the model (queued).",
             "verified": "Verified by drem: ranked on drem's re-drive; the logs' laps below are evidence only.",
             "disputed": "Not shown on the board: the logs do not agree with drem's re-drive.",
             "not_verified": "Self-reported from logs: drem could not re-drive the model."}
    note = f" {submission.verification_note}" if submission.verification_note else ""
    return words.get(submission.verification, "") + note
