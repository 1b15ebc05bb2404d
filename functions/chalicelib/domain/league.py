"""The virtual league: racers submit their model's evaluation on a track; the board ranks the latest submission of
each racer by best lap or by average of completed laps.

Submissions are assembled on the server from the files the racer uploaded (domain/league_intake.py); the figures the
board ranks by (best lap, average, laps completed) are recomputed here from the trials. Every submission passes the
same checks, whatever tool wrote its logs: the track is one drem knows (domain/league_tracks.py); a lap with an
off-track is not a completed lap; no lap is faster than the track's centre-line length driven at the action space's
top speed; and an evaluation's log content belongs to the first racer who pushed it.

Rules: a racer pushes only under their own username (admins may push for anyone); anyone may read; admins delete.
"""
from __future__ import annotations

import re
from collections.abc import Callable
from datetime import UTC, date, datetime
from enum import StrEnum
from typing import Annotated, Any, Literal, Protocol

from pydantic import BaseModel, ConfigDict, Field, field_validator

from chalicelib.core.errors import Conflict, Forbidden, InvalidInput, NotFound
from chalicelib.core.principals import Principal, Role
from chalicelib.domain.league_board_cache import LeagueBoardCache
from chalicelib.domain.league_tracks import DREM_TRACK_LENGTHS_M, RegisteredTrack, TrackSet

NAME_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9_.@+-]{0,63}$"
TRACK_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9_-]{0,63}$"
MAX_TRIALS = 100
MAX_HYPERPARAMETERS = 60
LAP_COMPLETE = 100.0

HyperValue = Annotated[str, Field(max_length=200)] | int | float | bool | None
# self_reported: logs only; pending: the model came with it and waits for drem's re-drive; verified: ranked on what
# drem measured; disputed: the logs claim laps more than LOG_MARGIN faster than drem's re-drive (not shown);
# not_verified: the re-drive could not run (the entry stays self-reported, with why).
Verification = Literal["self_reported", "pending", "verified", "disputed", "not_verified"]
# drem's simulator is not DeepRacer's Gazebo: a model's laps differ between them. Logs may claim laps at most this
# much faster than drem measured for the same model; more is not the simulator gap but an edited log.
LOG_MARGIN = 0.15


class EvaluationTrial(BaseModel):
    model_config = ConfigDict(extra="forbid")
    trial: int = Field(ge=0, le=10_000)
    time_s: float = Field(ge=0, le=24 * 3600, allow_inf_nan=False, description="elapsed time of the trial")
    completion_pct: float = Field(ge=0, le=100, allow_inf_nan=False)
    off_track_count: int = Field(default=0, ge=0, le=100_000)
    reset_count: int = Field(default=0, ge=0, le=100_000)
    crash_count: int = Field(default=0, ge=0, le=100_000)
    status: str = Field(default="", max_length=40)

    @property
    def completed(self) -> bool:
        """A whole lap without leaving the track: the same rule for console, DRfC, DROA and drem laps (a console lap
        that went off, was reset and finished still reports 100 %)."""
        return self.completion_pct >= LAP_COMPLETE and self.off_track_count == 0


class SubmissionInput(BaseModel):
    """One submission as the server assembled it from the uploaded export (chalicelib.domain.league_assembler)."""
    model_config = ConfigDict(extra="forbid")

    racer: str = Field(pattern=NAME_PATTERN)
    track: str = Field(pattern=TRACK_PATTERN)
    model_name: str = Field(pattern=r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,79}$")
    layout: str = Field(max_length=40)
    sensor: list[Annotated[str, Field(max_length=40)]] = Field(min_length=1, max_length=4)
    algorithm: str = Field(max_length=40)
    action_space_type: str = Field(max_length=20)
    action_space: str = Field(max_length=200, description="a one-line summary of the action space")
    hyperparameters: dict[Annotated[str, Field(max_length=64)], HyperValue] = Field(max_length=MAX_HYPERPARAMETERS)
    training_track: str | None = Field(default=None, max_length=64)
    training_episodes: int = Field(ge=0, le=10_000_000)
    training_best_completion_pct: float | None = Field(default=None, ge=0, le=100, allow_inf_nan=False,
                                                       description="None when training has no episodes (cloning)")
    trials: list[EvaluationTrial] = Field(min_length=1, max_length=MAX_TRIALS)
    # None only in submissions stored before the server assembled them (LeagueService.push requires both).
    top_speed_m_s: float | None = Field(default=None, gt=0, le=20, allow_inf_nan=False,
                                        description="the action space's top speed")
    evidence_digest: str | None = Field(default=None, pattern=r"^[0-9a-f]{64}$",
                                        description="SHA-256 of the evaluation's laps as logged (who pushed them "
                                                    "first)")
    model_id: str | None = Field(default=None, max_length=64, description="the uploaded model drem re-drives")


class VerifiedDrive(BaseModel):
    """What drem measured when it re-drove the model in its simulator on the board's track."""
    model_config = ConfigDict(extra="forbid", frozen=True)
    laps: int = Field(ge=0)
    laps_completed: int = Field(ge=0)
    best_lap_s: float | None = None
    mean_lap_s: float | None = None
    offtrack_count: int = Field(default=0, ge=0)
    completion_pct: float = Field(default=0.0, ge=0, le=100)
    message: str = Field(default="", max_length=500)
    at: str = ""


class BoardEntry(BaseModel):
    """One racer's latest submission on a track, as the board shows it (no hyperparameters: those are on demand)."""
    model_config = ConfigDict(frozen=True)

    racer: str
    model_name: str
    algorithm: str
    sensor: list[str]
    action_space: str
    layout: str
    submitted_at: str
    submission_id: str
    trials: int
    laps_completed: int
    best_lap_s: float | None
    average_lap_s: float | None
    average_completion_pct: float
    off_track_total: int
    reset_total: int
    verification: Verification = "self_reported"

    @property
    def verified(self) -> bool:
        return self.verification == "verified"

    @property
    def source(self) -> str:
        """How the board labels the entry."""
        return "verified by drem" if self.verified else "self-reported from logs"


class Submission(SubmissionInput):
    model_config = ConfigDict(extra="forbid", frozen=True)
    submission_id: str
    submitted_at: str
    submitted_by: str
    verification: Verification = "self_reported"
    verified_drive: VerifiedDrive | None = None
    verification_note: str = Field(default="", max_length=600)

    def claimed_best_s(self) -> float | None:
        completed = [t.time_s for t in self.trials if t.completed]
        return min(completed) if completed else None

    def entry(self) -> BoardEntry:
        drive = self.verified_drive
        if self.verification == "verified" and drive is not None:  # ranked on what drem measured
            return BoardEntry(
                racer=self.racer, model_name=self.model_name, algorithm=self.algorithm, sensor=list(self.sensor),
                action_space=self.action_space, layout=self.layout, submitted_at=self.submitted_at,
                submission_id=self.submission_id, trials=drive.laps, laps_completed=drive.laps_completed,
                best_lap_s=round(drive.best_lap_s, 3) if drive.best_lap_s is not None else None,
                average_lap_s=round(drive.mean_lap_s, 3) if drive.mean_lap_s is not None else None,
                average_completion_pct=round(drive.completion_pct, 2), off_track_total=drive.offtrack_count,
                reset_total=0, verification="verified")
        completed = [t.time_s for t in self.trials if t.completed]
        return BoardEntry(
            racer=self.racer, model_name=self.model_name, algorithm=self.algorithm, sensor=list(self.sensor),
            action_space=self.action_space, layout=self.layout, submitted_at=self.submitted_at,
            submission_id=self.submission_id, trials=len(self.trials), laps_completed=len(completed),
            best_lap_s=round(min(completed), 3) if completed else None,
            average_lap_s=round(sum(completed) / len(completed), 3) if completed else None,
            average_completion_pct=round(sum(t.completion_pct for t in self.trials) / len(self.trials), 2),
            off_track_total=sum(t.off_track_count for t in self.trials),
            reset_total=sum(t.reset_count for t in self.trials), verification=self.verification)

    def with_drive(self, drive: VerifiedDrive | None, failure: str | None, at: str) -> Submission:
        """This submission once drem re-drove its model: verified, disputed (logs too fast) or not verified."""
        if drive is None:
            return self.model_copy(update={"verification": "not_verified", "verification_note":
                                           f"drem could not re-drive the model: {failure or 'no report'}"[:600]})
        claimed = self.claimed_best_s()
        if claimed is not None and drive.best_lap_s is not None and claimed < drive.best_lap_s * (1 - LOG_MARGIN):
            note = (f"the logs claim a {claimed:.3f} s lap, but drem measured {drive.best_lap_s:.3f} s for the same "
                    f"model: more than {LOG_MARGIN:.0%} faster, so the logs are not believed")
            return self.model_copy(update={"verification": "disputed", "verified_drive": drive,
                                           "verification_note": note})
        if claimed is not None and drive.best_lap_s is None:
            note = (f"the logs claim a {claimed:.3f} s lap, but the model completed no lap when drem re-drove it "
                    f"({drive.message})")[:600]
            return self.model_copy(update={"verification": "disputed", "verified_drive": drive,
                                           "verification_note": note})
        return self.model_copy(update={"verification": "verified", "verified_drive": drive,
                                       "verification_note": f"re-driven by drem at {at}: {drive.message}"[:600]})


class SortKey(StrEnum):
    BEST = "best"
    AVG = "avg"


class BoardQuery(BaseModel):
    model_config = ConfigDict(extra="forbid")
    sort: SortKey = SortKey.BEST
    algorithm: str | None = Field(default=None, max_length=40)
    sensor: str | None = Field(default=None, max_length=40)
    since: date | None = Field(default=None, description="only submissions on or after this day (UTC)")
    until: date | None = Field(default=None, description="only submissions on or before this day (UTC)")

    @field_validator("algorithm", "sensor", mode="before")
    @classmethod
    def _blank_is_none(cls, value: Any) -> Any:
        return None if isinstance(value, str) and not value.strip() else value

    @field_validator("since", "until", mode="before")
    @classmethod
    def _blank_date_is_none(cls, value: Any) -> Any:
        return None if value == "" else value

    def keeps(self, entry: BoardEntry) -> bool:
        day = entry.submitted_at[:10]
        return ((self.algorithm is None or entry.algorithm == self.algorithm)
                and (self.sensor is None or self.sensor in entry.sensor)
                and (self.since is None or day >= self.since.isoformat())
                and (self.until is None or day <= self.until.isoformat()))


class RankedEntry(BaseModel):
    model_config = ConfigDict(frozen=True)  # boards are shared between requests (domain/league_board_cache.py)

    rank: int
    entry: BoardEntry


class Board(BaseModel):
    # Boards are shared between requests (domain/league_board_cache.py): none may be changed by the one that reads it.
    model_config = ConfigDict(frozen=True)

    track: str
    sort: SortKey
    entries: tuple[RankedEntry, ...]
    racer_names: dict[str, str] = Field(
        default_factory=dict, description="{sign-in name: the racer's display name, told apart where two collide}")

    def rows(self) -> list[dict[str, Any]]:
        """Flat rows (CSV, terminal table): the same columns everywhere; "racer" is the display name."""
        return [board_row(ranked, self.racer_names.get(ranked.entry.racer, "")) for ranked in self.entries]


BOARD_COLUMNS = ("rank", "racer", "model", "algorithm", "sensor", "best_lap_s", "average_lap_s", "laps_completed",
                 "trials", "completion_pct", "off_track", "resets", "source", "submitted_at")


def board_row(ranked: RankedEntry, racer_name: str = "") -> dict[str, Any]:
    entry = ranked.entry
    return {"rank": ranked.rank, "racer": racer_name or entry.racer, "sign_in_name": entry.racer,
            "model": entry.model_name, "algorithm": entry.algorithm,
            "sensor": "+".join(entry.sensor), "best_lap_s": entry.best_lap_s, "average_lap_s": entry.average_lap_s,
            "laps_completed": entry.laps_completed, "trials": entry.trials,
            "completion_pct": entry.average_completion_pct, "off_track": entry.off_track_total,
            "resets": entry.reset_total, "source": entry.source, "submitted_at": entry.submitted_at}


class SelfReported(StrEnum):
    """What a league's organiser does with entries drem has not verified."""
    SHOWN = "shown"  # ranked with the verified ones
    BELOW_VERIFIED = "below_verified"  # ranked after every verified entry
    REFUSED = "refused"  # not taken: a push must bring its model, and only verified entries are shown


class LeaguePolicy(BaseModel):
    model_config = ConfigDict(extra="forbid")
    self_reported: SelfReported = SelfReported.SHOWN


def rank(entries: list[BoardEntry], sort: SortKey,
         policy: SelfReported = SelfReported.SHOWN) -> tuple[RankedEntry, ...]:
    """Racers with a completed lap first, by the chosen time (ties: the other time, then who submitted first);
    then racers without one, by average completion. With BELOW_VERIFIED, every verified entry comes first."""
    def key(entry: BoardEntry) -> tuple[Any, ...]:
        tier = 1 if policy is SelfReported.BELOW_VERIFIED and not entry.verified else 0
        primary, secondary = ((entry.best_lap_s, entry.average_lap_s) if sort is SortKey.BEST
                              else (entry.average_lap_s, entry.best_lap_s))
        if primary is None:
            return (tier, 1, -entry.average_completion_pct, 0.0, entry.submitted_at)
        return (tier, 0, primary, secondary or 0.0, entry.submitted_at)
    return tuple(RankedEntry(rank=index, entry=entry) for index, entry in enumerate(sorted(entries, key=key), start=1))


class LeagueStore(Protocol):
    def board(self, track: str) -> dict[str, BoardEntry]: ...
    def record(self, submission: Submission) -> None:
        """Store the submission and its board entry, and claim its evidence digest for its racer; raises
        EvidenceTaken (storing nothing) when another racer claimed the digest first."""
    def evidence_owner(self, digest: str) -> str | None: ...
    def replace(self, submission: Submission) -> bool:
        """Rewrite a stored submission (its verification); its board entry too while it is the racer's latest.
        False when the submission is gone."""
    def policy(self, track: str) -> LeaguePolicy: ...
    def registered_tracks(self) -> dict[str, RegisteredTrack]: ...
    def register_track(self, name: str, track: RegisteredTrack) -> None: ...
    def set_policy(self, track: str, policy: LeaguePolicy) -> None: ...
    def submission(self, track: str, racer: str, submission_id: str) -> Submission | None: ...
    def remove_racer(self, track: str, racer: str) -> int: ...


class EvidenceTaken(Conflict):
    """The evaluation's log content was already pushed by another racer."""

    def __init__(self, owner: str) -> None:
        super().__init__(f"This evaluation's laps were already pushed by {owner}: the same log content counts once, "
                         "for the racer who pushed it first. Push the logs of your own model's evaluation.",
                         field="evaluation")
        self.owner = owner


def utc_now() -> str:
    return datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%S.%fZ")


class LeagueService:
    def __init__(self, store: LeagueStore, tracks: TrackSet | None = None, *,
                 clock: Callable[[], str] = utc_now, boards: LeagueBoardCache[Board] | None = None) -> None:
        """`boards`: the process's ranked boards (domain/league_board_cache.py), dropped by every write made here;
        None reads storage on every board view."""
        self.store = store
        self.tracks = tracks or TrackSet(store)
        self._clock = clock
        self._boards = boards

    def _written(self) -> None:
        if self._boards is not None:
            self._boards.clear()

    def now(self) -> str:
        return self._clock()

    def pusher(self, principal: Principal, racer: str | None) -> str:
        """The racer a push is for: the caller, or (admins only) the racer they name."""
        username = getattr(principal, "username", None)
        if not principal.is_user or not username:
            raise Forbidden("Only signed-in racers push league submissions.")
        racer = racer or username
        if racer != username and Role.ADMIN not in principal.roles:
            raise Forbidden(f"You may push submissions only as yourself ({username}), not as {racer}.")
        return racer

    def track_length_m(self, track: str) -> float:
        """The known track's centre-line length; an unknown name is refused (it never creates a board)."""
        length = self.tracks.length_m(checked_track(track))
        if length is None:
            raise NotFound(f"{track!r} is not a track drem knows. Use the DeepRacer world name of the track (e.g. "
                           f"reinvent_base, Spain_track), or ask the staff to register the track.", field="track")
        return length

    def push(self, principal: Principal, track: str, body: SubmissionInput) -> Submission:
        if body.track != checked_track(track):
            raise InvalidInput(f"The submission is for {body.track!r} but was pushed to {track!r}.", field="track")
        self.pusher(principal, body.racer)
        username = str(getattr(principal, "username", ""))
        check_lap_times(body, self.track_length_m(track))
        owner = self.store.evidence_owner(str(body.evidence_digest))
        if owner is not None and owner != body.racer:
            raise EvidenceTaken(owner)
        if body.model_id is None and self.store.policy(track).self_reported is SelfReported.REFUSED:
            raise Forbidden(f"The {track} league takes only entries drem verifies: push your model with the logs "
                            "(drem league push LOGS MODEL.tar.gz) and drem re-drives it.", field="model")
        submitted_at = self._clock()
        submission = Submission(**body.model_dump(), submitted_at=submitted_at, submitted_by=username,
                                submission_id=submitted_at,
                                verification="pending" if body.model_id else "self_reported")
        try:
            self.store.record(submission)
        finally:
            self._written()
        return submission

    def board(self, track: str, query: BoardQuery) -> Board:
        """The ranked board, as read at most a second ago (and after every write made through this process) when the
        service keeps boards."""
        track = checked_track(track)
        if self._boards is None:
            return self._ranked(track, query)
        return self._boards.get((track, query.model_dump_json()), lambda: self._ranked(track, query))

    def _ranked(self, track: str, query: BoardQuery) -> Board:
        policy = self.store.policy(track).self_reported
        kept = [entry for entry in self.store.board(track).values() if query.keeps(entry) and shown(entry, policy)]
        return Board(track=track, sort=query.sort, entries=rank(kept, query.sort, policy))

    def register_track(self, principal: Principal, track: str, body: RegisteredTrack) -> RegisteredTrack:
        """Staff add a track drem's set lacks (a venue's own layout); drem's own tracks keep their measured length."""
        if Role.ADMIN not in principal.roles:
            raise Forbidden("Only admins register league tracks.")
        if checked_track(track) in DREM_TRACK_LENGTHS_M:
            raise InvalidInput(f"{track} is one of drem's own tracks; its length is drem's.", field="track")
        try:
            self.store.register_track(track, body)
        finally:
            self._written()
        return body

    def set_policy(self, principal: Principal, track: str, policy: LeaguePolicy) -> LeaguePolicy:
        if Role.ADMIN not in principal.roles:
            raise Forbidden("Only admins (the league's organisers) choose what the board does with self-reported "
                            "entries.")
        self.track_length_m(track)
        try:
            self.store.set_policy(track, policy)
        finally:
            self._written()
        return policy

    def record_drive(self, track: str, racer: str, model_id: str, drive: VerifiedDrive | None,
                     failure: str | None = None) -> Submission | None:
        """drem re-drove `model_id` for the racer's latest submission on `track`: store what it measured. None when
        that submission is gone or no longer brings this model (the racer pushed another since)."""
        entry = self.store.board(track).get(racer)
        current = entry and self.store.submission(track, racer, entry.submission_id)
        if not current or current.model_id != model_id:
            return None
        updated = current.with_drive(drive, failure, self._clock())
        try:
            replaced = self.store.replace(updated)
        finally:
            self._written()
        return updated if replaced else None

    def latest(self, track: str, racer: str) -> Submission:
        track, racer = checked_track(track), checked_racer(racer)
        entry = self.store.board(track).get(racer)
        found = entry and self.store.submission(track, racer, entry.submission_id)
        if not found:
            raise NotFound(f"{racer} has no submission on {track}.", field="racer")
        return found

    def delete(self, principal: Principal, track: str, racer: str) -> int:
        if Role.ADMIN not in principal.roles:
            raise Forbidden("Only admins delete league submissions.")
        try:
            removed = self.store.remove_racer(checked_track(track), checked_racer(racer))
        finally:
            self._written()
        if not removed:
            raise NotFound(f"{racer} has no submission on {track}.", field="racer")
        return removed


def shown(entry: BoardEntry, policy: SelfReported) -> bool:
    """Disputed entries never show; under REFUSED only verified ones do."""
    if entry.verification == "disputed":
        return False
    return entry.verified or policy is not SelfReported.REFUSED


def check_lap_times(body: SubmissionInput, track_length_m: float) -> None:
    """No completed lap is faster than the track's centre line driven at the action space's top speed all the way."""
    if body.top_speed_m_s is None or body.evidence_digest is None:
        raise InvalidInput("the submission has no top speed or evidence digest (assemble it from an export)")
    fastest_s = track_length_m / body.top_speed_m_s
    for index, trial in enumerate(body.trials):
        if trial.completed and trial.time_s < fastest_s:
            raise InvalidInput(
                f"trial {trial.trial} claims a {trial.time_s:.3f} s lap, but {body.track} is {track_length_m:.2f} m "
                f"long and the model's top speed is {body.top_speed_m_s:g} m/s: no lap can take less than "
                f"{fastest_s:.3f} s", field=f"trials[{index}].time_s")


def checked_track(track: str) -> str:
    if not isinstance(track, str) or not re.fullmatch(TRACK_PATTERN, track):
        raise InvalidInput(f"{str(track)[:64]!r} is not a track name (letters, digits, _ and -).", field="track")
    return track


def checked_racer(racer: str) -> str:
    if not isinstance(racer, str) or not re.fullmatch(NAME_PATTERN, racer):
        raise NotFound(f"There is no racer {str(racer)[:64]!r}.", field="racer")
    return racer
