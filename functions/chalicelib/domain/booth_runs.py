"""Runs of the learning booth: a person (manual) or a model version (autonomous) driving a track in the simulator.

A run's artifacts are a `drem_sim` run folder in the runs bucket (`runs/{track}/{date}/{runId}/`: `frames.tar`, all
the frames in one object, or `frames/*.png` one by one; `controls.jsonl`, `metadata.json`) plus `topdown.png`, the
driven path on the track map; its record and metrics live in the booth table. Lifecycle: RECORDING (manual:
artifacts may be uploaded) or QUEUED (autonomous: waiting for the booth worker) → RUNNING (the worker drives) →
FINALISED (metrics computed) | FAILED (with the reason).

Finalising reads `controls.jsonl` (bounded, every row checked: hostile input), computes the metrics and writes the
authoritative `metadata.json` and the picture. A racer sees only their own runs; admins and operators see all.
"""
from __future__ import annotations

import json
import math
import re
import secrets
from collections.abc import Callable
from datetime import UTC, datetime, timedelta
from enum import StrEnum
from typing import Any, Protocol

from pydantic import BaseModel, ConfigDict, Field, model_validator

from chalicelib.core.errors import Conflict, InvalidInput, NotFound, PayloadTooLarge, RateLimited
from chalicelib.core.principals import Principal
from chalicelib.domain.booth_tracks import TRACK_ID_PATTERN, TrackService
from chalicelib.domain.ownership import require_owner_or_role
from chalicelib.domain.racer_models import MODEL_STAFF, DownloadLike, ModelService, ModelStatus, utc_now
from drem_leaderboard.laps import LapAttempts

RUN_ID_PATTERN = r"^[a-f0-9]{12,40}$"
MAX_CONTROLS_BYTES = 16 * 1024 * 1024
MAX_ARTIFACT_BYTES = 1024 * 1024  # one frame or the controls of a long run; frames are ~10 KB
MAX_ROWS = 50_000  # an hour at 15 Hz
MAX_AUTONOMOUS_LAPS = 5
# Runs a racer may have open (RECORDING or QUEUED) that were started within OPEN_WINDOW_S: each open run is storage
# and, when autonomous, the worker's time. Older open runs (a drive lost to a restart) no longer count.
MAX_OPEN_RUNS = 10
OPEN_WINDOW_S = 3600
FRAME_ARTIFACT = re.compile(r"^frame-(\d{6})\.png$")
# frames.tar: a five-minute drive (4,500 frames of ~2 KB, each in 512-byte tar blocks) is ~11 MB; the app's body limit
# is 20 MiB (drem_local.http_front)
MAX_FRAMES_BUNDLE_BYTES = 18 * 1024 * 1024
UPLOADABLE = ("controls.jsonl", "frames.tar")
READABLE = ("controls.jsonl", "metadata.json", "topdown.png", "frames.tar")


class RecordChanged(Exception):
    """A conditional write lost: someone else changed the run or job first (the store raises it)."""


class RunMode(StrEnum):
    MANUAL = "manual"
    AUTONOMOUS = "autonomous"


class RunStatus(StrEnum):
    RECORDING = "RECORDING"
    QUEUED = "QUEUED"
    RUNNING = "RUNNING"
    FINALISED = "FINALISED"
    FAILED = "FAILED"


class RunMetrics(BaseModel):
    """What a run shows about the driver: completion, off-tracks, stability (and pace)."""
    model_config = ConfigDict(frozen=True)
    frames: int
    attempts: int
    laps_completed: int
    completion_pct: float
    offtrack_count: int
    stability_deg: float = Field(description="steering jitter: std of frame-to-frame steering changes (lower is "
                                             "steadier)")
    mean_speed: float
    lap_times_s: list[float]
    best_lap_s: float | None
    mean_lap_s: float | None
    seconds: float


class NewRun(BaseModel):
    model_config = ConfigDict(extra="forbid")
    track_id: str = Field(pattern=TRACK_ID_PATTERN)
    mode: RunMode = RunMode.MANUAL
    model_id: str | None = Field(default=None, max_length=80, description="the model version (autonomous runs)")
    laps: int = Field(default=1, ge=1, le=MAX_AUTONOMOUS_LAPS, description="lap attempts (autonomous runs)")

    @model_validator(mode="after")
    def _model_for_autonomous(self) -> NewRun:
        if (self.mode is RunMode.AUTONOMOUS) != (self.model_id is not None):
            raise ValueError("an autonomous run names its model_id; a manual run has none")
        return self


class RunRecord(BaseModel):
    model_config = ConfigDict(frozen=True)
    run_id: str
    owner_sub: str
    owner_username: str
    track_id: str
    mode: RunMode
    status: RunStatus
    created_at: str
    prefix: str
    model_id: str | None = None
    model_name: str | None = None
    laps_requested: int = 1
    finalised_at: str | None = None
    reason: str | None = None
    metrics: RunMetrics | None = None
    job_id: str | None = None  # the training job whose model drove it (autonomous runs made by the worker)

    def public(self) -> dict[str, Any]:
        return self.model_dump(mode="json", exclude={"prefix"})


class ListRunsQuery(BaseModel):
    model_config = ConfigDict(extra="forbid")
    everyone: bool = Field(default=False, description="admins and operators: every racer's runs")
    track_id: str | None = Field(default=None, pattern=TRACK_ID_PATTERN)


class RunStore(Protocol):
    def create_run(self, run: RunRecord) -> None: ...
    def replace_run(self, run: RunRecord, *, expected_status: str) -> None: ...
    def get_run(self, run_id: str) -> RunRecord | None: ...
    def runs_of(self, owner_sub: str) -> list[RunRecord]: ...
    def all_runs(self) -> list[RunRecord]: ...


class RunFiles(Protocol):
    def put(self, key: str, data: bytes) -> None: ...
    def download_bounded(self, key: str, *, limit: int) -> DownloadLike | None: ...
    def presign_download(self, key: str, *, expires_s: int) -> str: ...


# (track_id, driven path in metres) -> PNG bytes of the top-down picture, or None when it cannot be drawn
Picture = Callable[[str, list[tuple[float, float]]], bytes | None]


def simulator_picture(track_id: str, path: list[tuple[float, float]]) -> bytes | None:
    try:
        import cv2

        from drem_sim.render import track_map
        from drem_sim.tracks import load_track
    except ModuleNotFoundError:
        return None  # no simulator on this server: the run keeps its metrics, only the picture is missing
    ok, data = cv2.imencode(".png", track_map(load_track(track_id), path, px_per_m=40.0))
    return data.tobytes() if ok else None


def new_record_id() -> str:
    """Time first, so ids sort by creation; 12 random bits more than a model id."""
    return f"{int(datetime.now(UTC).timestamp() * 1000):012x}{secrets.token_hex(8)}"


class RunService:
    def __init__(self, store: RunStore, files: RunFiles, tracks: TrackService, models: ModelService, *,
                 picture: Picture = simulator_picture, clock: Callable[[], str] = utc_now,
                 new_id: Callable[[], str] = new_record_id) -> None:
        self.store = store
        self.files = files
        self.tracks = tracks
        self.models = models
        self.picture = picture
        self._clock = clock
        self._new_id = new_id

    def now(self) -> str:
        return self._clock()

    # -- creating and reading ----------------------------------------------------------------------------------------

    def create(self, principal: Principal, request: NewRun, *, job_id: str | None = None) -> RunRecord:
        owner_sub, username = _user_of(principal)
        track_id = self.tracks.require(request.track_id)
        model_name = None
        if request.mode is RunMode.AUTONOMOUS:
            model = self.models.get(principal, request.model_id or "")  # 404 unknown, 403 another racer's
            if model.owner_sub != owner_sub:
                raise InvalidInput("An autonomous run drives one of your own model versions.", field="model_id")
            if model.status is not ModelStatus.AVAILABLE:
                raise Conflict(f"Model '{model.name}' is {model.status.value}; only AVAILABLE models drive.",
                               field="model_id")
            model_name = model.name
        now, run_id = self._clock(), self._new_id()
        self._require_room(owner_sub, now)
        record = RunRecord(run_id=run_id, owner_sub=owner_sub, owner_username=username, track_id=track_id,
                           mode=request.mode, created_at=now, prefix=f"runs/{track_id}/{now[:10]}/{run_id}/",
                           status=RunStatus.RECORDING if request.mode is RunMode.MANUAL else RunStatus.QUEUED,
                           model_id=request.model_id, model_name=model_name, laps_requested=request.laps,
                           job_id=job_id)
        self.store.create_run(record)
        return record

    def _require_room(self, owner_sub: str, now: str) -> None:
        since = (datetime.fromisoformat(now.replace("Z", "+00:00")) - timedelta(seconds=OPEN_WINDOW_S)).isoformat()
        since = since.replace("+00:00", "Z")
        open_runs = [r for r in self.store.runs_of(owner_sub)
                     if r.status in (RunStatus.RECORDING, RunStatus.QUEUED) and r.created_at >= since]
        if len(open_runs) >= MAX_OPEN_RUNS:
            raise RateLimited(f"You have {len(open_runs)} runs started in the last hour that are not finished yet: "
                              "finish (or finalise) one before starting another.", field="track_id")

    def list_runs(self, principal: Principal, query: ListRunsQuery) -> list[RunRecord]:
        if query.everyone and principal.roles & MODEL_STAFF:
            runs = self.store.all_runs()
        else:
            runs = self.store.runs_of(_user_of(principal)[0])
        return [r for r in runs if query.track_id in (None, r.track_id)]

    def get(self, principal: Principal, run_id: str) -> RunRecord:
        record = self.store.get_run(_checked_id(run_id))
        if record is None:
            raise NotFound(f"There is no run {run_id[:40]!r}.", field="run_id")
        require_owner_or_role(principal, record.owner_sub, MODEL_STAFF)
        return record

    def artifact_url(self, principal: Principal, run_id: str, name: str) -> str:
        record = self.get(principal, run_id)
        return self.files.presign_download(record.prefix + _readable_key(name), expires_s=300)

    def controls(self, principal: Principal, run_id: str) -> list[dict[str, Any]]:
        """The run's recorded controls (for its inspection page); empty until they are uploaded and finalised."""
        record = self.get(principal, run_id)
        if record.status is not RunStatus.FINALISED:
            return []
        download = self.files.download_bounded(record.prefix + "controls.jsonl", limit=MAX_CONTROLS_BYTES)
        if download is None or download.too_large:
            return []
        with download.body:
            return parse_controls(download.body.read())

    # -- uploading and finalising ------------------------------------------------------------------------------------

    def put_artifact(self, principal: Principal, run_id: str, name: str, data: bytes) -> str:
        record = self.get(principal, run_id)
        if record.owner_sub != principal.sub:
            raise InvalidInput("Only the driver uploads a run's artifacts.", field="run_id")
        if record.status is not RunStatus.RECORDING:
            raise Conflict(f"This run is {record.status.value}; artifacts are uploaded while it is RECORDING.")
        key = _uploadable_key(name)
        limits = {"controls.jsonl": MAX_CONTROLS_BYTES, "frames.tar": MAX_FRAMES_BUNDLE_BYTES}
        if len(data) > limits.get(key, MAX_ARTIFACT_BYTES):
            raise PayloadTooLarge(f"{name} is larger than this artifact may be.", field="body")
        if key.endswith(".png") and not data.startswith(b"\x89PNG\r\n\x1a\n"):
            raise InvalidInput(f"{name} is not a PNG image.", field="body")
        if key == "frames.tar":
            _check_frames_bundle(data)
        self.files.put(record.prefix + key, data)
        return key

    def finalise(self, principal: Principal, run_id: str) -> RunRecord:
        record = self.get(principal, run_id)
        if record.status is RunStatus.FINALISED:
            return record
        if record.status is not RunStatus.RECORDING:
            raise Conflict(f"This run is {record.status.value}; only a RECORDING run is finalised by its driver.")
        return self.finalise_record(record)

    def finalise_record(self, record: RunRecord) -> RunRecord:
        """Metrics, metadata.json and the top-down picture from the uploaded controls (the worker calls it too)."""
        download = self.files.download_bounded(record.prefix + "controls.jsonl", limit=MAX_CONTROLS_BYTES)
        if download is None:
            raise Conflict("This run has no controls.jsonl yet: upload it before finalising.", field="run_id")
        with download.body:
            if download.too_large:
                raise PayloadTooLarge("controls.jsonl is too large.", field="controls.jsonl")
            rows = parse_controls(download.body.read())
        metrics = compute_metrics(rows)
        picture = self.picture(record.track_id, [(r["x"], r["y"]) for r in rows])
        if picture is not None:
            self.files.put(record.prefix + "topdown.png", picture)
        finished = record.model_copy(update={"status": RunStatus.FINALISED, "finalised_at": self._clock(),
                                             "metrics": metrics})
        self.files.put(record.prefix + "metadata.json", json.dumps(_metadata(finished, rows), indent=2).encode())
        self._replace(finished, record.status)
        return finished

    def mark(self, record: RunRecord, status: RunStatus, reason: str | None = None) -> RunRecord:
        changed = record.model_copy(update={"status": status, "reason": reason})
        self._replace(changed, record.status)
        return changed

    def _replace(self, record: RunRecord, expected: RunStatus) -> None:
        try:
            self.store.replace_run(record, expected_status=expected.value)
        except RecordChanged:
            raise Conflict("This run changed meanwhile; reload it.", field="run_id") from None

    # -- aggregates --------------------------------------------------------------------------------------------------

    def aggregates(self, principal: Principal, query: ListRunsQuery) -> list[dict[str, Any]]:
        """Per track and driver (a person or a model version): runs, mean completion, off-tracks, stability, best
        lap."""
        groups: dict[tuple[str, str], list[RunMetrics]] = {}
        for run in self.list_runs(principal, query):
            if run.metrics is not None:
                driver = run.model_name or "" if run.mode is RunMode.AUTONOMOUS else f"{run.owner_username} (manual)"
                groups.setdefault((run.track_id, driver), []).append(run.metrics)
        rows = []
        for (track_id, driver), found in sorted(groups.items()):
            laps = [m.best_lap_s for m in found if m.best_lap_s is not None]
            rows.append({"track_id": track_id, "driver": driver, "runs": len(found),
                         "completion_pct": round(sum(m.completion_pct for m in found) / len(found), 2),
                         "offtrack_per_run": round(sum(m.offtrack_count for m in found) / len(found), 2),
                         "stability_deg": round(sum(m.stability_deg for m in found) / len(found), 3),
                         "best_lap_s": min(laps) if laps else None})
        return rows


def parse_controls(data: bytes) -> list[dict[str, Any]]:
    """The rows of a controls.jsonl, every field the metrics and the picture use checked (numbers, finite)."""
    try:
        lines = data.decode("utf-8").splitlines()
    except UnicodeDecodeError:
        raise InvalidInput("controls.jsonl is not UTF-8 text.", field="controls.jsonl") from None
    rows: list[dict[str, Any]] = []
    for number, line in enumerate((ln for ln in lines if ln.strip()), start=1):
        if len(rows) >= MAX_ROWS:
            raise PayloadTooLarge(f"controls.jsonl has more than {MAX_ROWS} rows.", field="controls.jsonl")
        try:
            row = json.loads(line)
        except (ValueError, RecursionError):
            raise InvalidInput(f"controls.jsonl line {number} is not JSON.", field="controls.jsonl") from None
        if not isinstance(row, dict):
            raise InvalidInput(f"controls.jsonl line {number} is not an object.", field="controls.jsonl")
        for key in ("t_ms", "steering_angle", "speed", "progress", "x", "y", "lap"):
            value = row.get(key)
            if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
                raise InvalidInput(f"controls.jsonl line {number}: {key} must be a number.", field="controls.jsonl")
        rows.append({"t_ms": float(row["t_ms"]), "steering_angle": float(row["steering_angle"]),
                     "speed": float(row["speed"]), "progress": float(row["progress"]), "x": float(row["x"]),
                     "y": float(row["y"]), "lap": int(row["lap"]), "offtrack": row.get("offtrack") is True})
        car_speed = row.get("car_speed")  # a person's drive: the speed the car really went
        if not isinstance(car_speed, bool) and isinstance(car_speed, int | float) and math.isfinite(car_speed):
            rows[-1]["car_speed"] = float(car_speed)
    if not rows:
        raise InvalidInput("controls.jsonl has no rows: the run recorded nothing.", field="controls.jsonl")
    return rows


def compute_metrics(rows: list[dict[str, Any]]) -> RunMetrics:
    """Lap attempts and laps by the whole-lap rule every figure uses (`drem_leaderboard.laps`, as `drem sim eval` and
    scrutineering count): a lap is driven whole from a timing-line crossing (or the standing start) to the next
    without an off-track; the stretch from where the car was put back to the line is no attempt.

    A row is the state the driver saw (its lap, progress and time) and whether what it did ended off the track; the
    next row is where that decision took the car. A crossing is timed where the line lies between the two."""
    laps = LapAttempts(start_s=rows[0]["t_ms"] / 1000.0)
    for row, after in zip(rows, [*rows[1:], None], strict=True):
        before = 100.0 * row["lap"] + row["progress"]
        reached = before if after is None else 100.0 * after["lap"] + after["progress"]
        if after is not None:  # where the last row's decision took the car was never recorded
            laps.moved(reached)
        if row["offtrack"]:
            laps.left_track()
        elif after is not None and after["lap"] > row["lap"]:
            laps.crossed(crossing_s(row["t_ms"], before, after["t_ms"], reached, after["lap"]), 100.0 * after["lap"])
    attempts = laps.ended()  # the attempt under way when the run stopped counts with what it reached
    lap_times = [round(t, 3) for t in laps.lap_times_s]
    steering = [r["steering_angle"] for r in rows]
    changes = [b - a for a, b in zip(steering, steering[1:], strict=False)]
    mean_change = sum(changes) / len(changes) if changes else 0.0
    jitter = math.sqrt(sum((c - mean_change) ** 2 for c in changes) / len(changes)) if changes else 0.0
    return RunMetrics(
        frames=len(rows), attempts=len(attempts), laps_completed=len(lap_times),
        completion_pct=round(sum(attempts) / len(attempts), 2) if attempts else 0.0,
        offtrack_count=sum(1 for r in rows if r["offtrack"]), stability_deg=round(jitter, 3),
        mean_speed=round(sum(r.get("car_speed", r["speed"]) for r in rows) / len(rows), 3), lap_times_s=lap_times,
        best_lap_s=min(lap_times) if lap_times else None,
        mean_lap_s=round(sum(lap_times) / len(lap_times), 3) if lap_times else None,
        seconds=round((rows[-1]["t_ms"] - rows[0]["t_ms"]) / 1000.0, 2))


def crossing_s(t_ms: float, before: float, after_t_ms: float, reached: float, lap: int) -> float:
    """When a decision that took the car from `before` to `reached` (laps × 100 + progress) crossed into `lap`: where
    the line lies between the two, in time."""
    share = (100.0 * lap - before) / (reached - before) if reached > before else 1.0
    return (t_ms + min(max(share, 0.0), 1.0) * (after_t_ms - t_ms)) / 1000.0


def _metadata(record: RunRecord, rows: list[dict[str, Any]]) -> dict[str, Any]:
    """The run folder's metadata.json (drem_sim.runs format): its presence marks a complete run."""
    metrics = record.metrics
    assert metrics is not None
    return {"run_id": record.run_id, "track_id": record.track_id, "direction": "forward", "source": "sim",
            "driver": "human" if record.mode is RunMode.MANUAL else f"model:{record.model_name}",
            "seed": None, "decision_hz": 15, "started_at": record.created_at, "ended_at": record.finalised_at,
            "frames": len(rows), "laps": rows[-1]["lap"] - rows[0]["lap"],
            "lap_times_ms": [round(t * 1000) for t in metrics.lap_times_s], "resets": metrics.offtrack_count}


def _check_frames_bundle(data: bytes) -> None:
    from drem_sim.runs import RunError, read_frames  # the run store's own reader: one rule for what a bundle holds

    try:
        for _ in read_frames(data):
            pass
    except RunError as error:
        raise InvalidInput(str(error), field="body") from None


def _uploadable_key(name: str) -> str:
    frame = FRAME_ARTIFACT.match(name)
    if frame:
        return f"frames/{frame.group(1)}.png"
    if name in UPLOADABLE:
        return name
    raise InvalidInput(f"{name[:40]!r} is not a run artifact: upload controls.jsonl and frames.tar (or "
                       "frame-NNNNNN.png one by one); metadata.json and topdown.png are written when the run is "
                       "finalised.", field="name")


def _readable_key(name: str) -> str:
    frame = FRAME_ARTIFACT.match(name)
    if frame:
        return f"frames/{frame.group(1)}.png"
    if name in READABLE:
        return name
    raise NotFound(f"A run has no artifact {name[:40]!r}.", field="name")


def _user_of(principal: Principal) -> tuple[str, str]:
    sub, username = getattr(principal, "sub", None), getattr(principal, "username", None)
    if not principal.is_user or not sub or not username:
        raise InvalidInput("Only signed-in users drive runs.")
    return sub, username


def _checked_id(run_id: str) -> str:
    if not re.fullmatch(RUN_ID_PATTERN, run_id or ""):
        raise NotFound(f"There is no run {str(run_id)[:40]!r}.", field="run_id")
    return run_id
