"""Manual drive in the app: a signed-in racer drives a track from the browser; the simulator steps on the server.

Each control message the page sends (`{"steering": -1..1, "throttle": -1..1}`, 15 a second) is exactly one 1/15 s
decision of `drem_sim.env.RaceEnv`, so the recorded run depends only on the sequence of controls, never on network
jitter; the answer carries the camera frame the driver sees next. Every decision is recorded with
`drem_sim.runs.RunRecorder` (the demonstrator's own format); finishing uploads the run folder to the runs bucket and
finalises the run (metrics, top-down picture), so it appears in "my runs".

Live sessions are held by the app process (`LiveDrives`): this needs a long-lived server (the local stack); on AWS
Lambda a drive would need a sticky process (see docs/deploy.md). At most `MAX_LIVE` drive at once (each costs a
simulator's CPU) and each racer drives one car: starting again saves the racer's earlier drive, and a session nobody
has steered for `IDLE_S` is finished by the next start, so its run is kept.

Every answered decision is on disk before its answer leaves (one controls row handed to the OS per decision, the frame
written first). With a drive folder (`drive_dir`, the local stack's state dir) a drive the app lost, because it was
killed or restarted, is still saved: **Finish** saves what was recorded, and the next start saves every such drive.
The folder is `{drive_dir}/{run_id}/`: one app process per state dir (drem up refuses a second), so a folder without a
live session in this process belongs to a drive the process lost.
"""
from __future__ import annotations

import base64
import logging
import re
import shutil
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict, Field

from chalicelib import logs
from chalicelib.core.errors import Conflict, DremError, Forbidden, NotFound, RateLimited, ServiceUnavailable
from chalicelib.core.principals import Principal
from chalicelib.domain.booth_runs import RUN_ID_PATTERN, NewRun, RunMode, RunRecord, RunService, RunStatus, crossing_s
from chalicelib.domain.booth_tracks import TRACK_ID_PATTERN

MAX_LIVE = 6
IDLE_S = 120.0
MAX_FRAMES = 15 * 60 * 5  # five minutes of driving
FULL_THROTTLE_SPEED = 3.0  # m/s, as `drem sim drive`
UPLOAD_THREADS = 4
RUN_FOLDER = re.compile(RUN_ID_PATTERN)  # a run id: the only names made in drive_dir
# Starting a drive (which saves lost ones) and saving a lost one run one at a time, so a folder that is being made for
# a new drive, or being saved by one request, is never taken for a lost drive by another.
_FOLDERS = threading.Lock()


class StartDrive(BaseModel):
    model_config = ConfigDict(extra="forbid")
    track_id: str = Field(pattern=TRACK_ID_PATTERN)


class DriveControl(BaseModel):
    model_config = ConfigDict(extra="forbid")
    steering: float = Field(default=0.0, ge=-1.0, le=1.0, allow_inf_nan=False, description="+1 full left")
    throttle: float = Field(default=0.0, ge=-1.0, le=1.0, allow_inf_nan=False, description="-1 brake, +1 full speed")


class LiveDrive:
    """One racer's car on one track, recording every decision into a run folder on local disk."""

    def __init__(self, record: RunRecord, drive_dir: Path | None = None) -> None:
        try:
            from drem_leaderboard.laps import LapAttempts
            from drem_sim.env import RaceEnv
            from drem_sim.runs import RunRecorder
            from drem_sim.tracks import load_track
        except ModuleNotFoundError:
            raise ServiceUnavailable("The simulator (drem_sim) is not installed on this server.") from None
        self.record = record
        self.lock = threading.Lock()
        self.last_used = time.monotonic()
        if drive_dir is None:
            self.folder = Path(tempfile.mkdtemp(prefix="drem-drive-"))
        else:
            self.folder = drive_dir / record.run_id
            self.folder.mkdir(parents=True, mode=0o700)
        self.env = RaceEnv(load_track(record.track_id))
        self.obs, info = self.env.reset(seed=0)
        self.laps = LapAttempts()  # the run's laps and attempts as its metrics will count them (drem_leaderboard.laps)
        self.params = info["params"]
        assert self.env.camera is not None, "RaceEnv observes by default"
        self.recorder = RunRecorder(self.folder, record.track_id, direction="forward", driver="human", seed=0,
                                    camera=self.env.camera.config, run_id=record.run_id,
                                    extra={"track_direction": self.env.track.direction, "decision_hz": 15},
                                    row_by_row=True)

    def step(self, control: DriveControl) -> dict[str, Any]:
        with self.lock:
            if self.recorder.frames >= MAX_FRAMES:
                raise Conflict("This run is full (five minutes of driving): finish it.", field="run_id")
            self.last_used = time.monotonic()
            action = {"steering_angle": control.steering * self.env.physics.spec.max_steering_deg,
                      "speed": max(0.0, control.throttle) * FULL_THROTTLE_SPEED}
            t_ms, lap, seen, obs = round(self.env.sim_time * 1000), self.env.laps, self.params, self.obs
            self.obs, self.params, _, _, _ = self.env.step(action)
            self._count_laps(t_ms, lap, float(seen["progress"]))
            assert obs is not None
            self.recorder.add(obs, action, seen, t_ms=t_ms, lap=lap, offtrack=bool(self.params["is_offtrack"]),
                              car_speed=self.env.car_state()["speed"])
            return self.state(frame=True)

    def _count_laps(self, t_ms: int, lap: int, progress: float) -> None:
        """The whole-lap rule, live, exactly as the finished run's metrics will count the same rows."""
        before, reached = 100.0 * lap + progress, 100.0 * self.env.laps + float(self.params["progress"])
        self.laps.moved(reached)
        if self.params["is_offtrack"]:
            self.laps.left_track()
        elif self.env.laps > lap:
            self.laps.crossed(crossing_s(t_ms, before, round(self.env.sim_time * 1000), reached, self.env.laps),
                              100.0 * self.env.laps)

    def state(self, *, frame: bool = False) -> dict[str, Any]:
        env, params, laps = self.env, self.params, self.laps
        answer: dict[str, Any] = {
            "run_id": self.record.run_id, "track_id": self.record.track_id, "frames": self.recorder.frames,
            "laps": env.laps, "laps_completed": laps.laps_completed,
            "attempts": len(laps.ended()),
            "lap_times_s": [round(t, 3) for t in laps.lap_times_s], "resets": env.resets,
            "progress": round(float(params["progress"]), 1), "speed": round(env.car_state()["speed"], 2),
            "steering_angle": round(float(params["steering_angle"]), 1), "offtrack": bool(params["is_offtrack"]),
            "x": round(float(params["x"]), 3), "y": round(float(params["y"]), 3)}  # for the page's top-down map
        if frame:
            import cv2

            assert self.obs is not None  # the env has a camera
            ok, data = cv2.imencode(".png", self.obs)
            answer["frame"] = "data:image/png;base64," + base64.b64encode(data.tobytes()).decode() if ok else None
        return answer

    def close(self) -> Path:
        with self.lock:
            from drem_sim.runs import whole_lap_figures

            return self.recorder.close(**whole_lap_figures(self.env))  # finalising writes the authoritative one


class LiveDrives:
    """The app process's live sessions, by run id (thread-safe; one lock for the table, one per session)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._sessions: dict[str, LiveDrive] = {}

    def add(self, drive: LiveDrive) -> None:
        with self._lock:
            self._sessions[drive.record.run_id] = drive

    def get(self, run_id: str) -> LiveDrive | None:
        with self._lock:
            return self._sessions.get(run_id)

    def pop(self, run_id: str) -> LiveDrive | None:
        with self._lock:
            return self._sessions.pop(run_id, None)

    def of(self, owner_sub: str) -> list[LiveDrive]:
        with self._lock:
            return [d for d in self._sessions.values() if d.record.owner_sub == owner_sub]

    def idle(self, older_than_s: float) -> list[LiveDrive]:
        now = time.monotonic()
        with self._lock:
            return [d for d in self._sessions.values() if now - d.last_used > older_than_s]

    def __len__(self) -> int:
        with self._lock:
            return len(self._sessions)


class DriveService:
    def __init__(self, live: LiveDrives, runs: RunService, drive_dir: Path | None = None) -> None:
        self.live = live
        self.runs = runs
        self.drive_dir = drive_dir

    def start(self, principal: Principal, request: StartDrive) -> dict[str, Any]:
        earlier = self.live.of(principal.sub or "")  # one car per racer: a new start saves the drive before it
        for stale in [*earlier, *(d for d in self.live.idle(IDLE_S) if d not in earlier)]:  # abandoned tabs too
            self._finish_quietly(stale)
        with _FOLDERS:
            self._save_lost_drives()
            if len(self.live) >= MAX_LIVE:
                raise RateLimited(f"{MAX_LIVE} people are driving already; try again in a minute.", field="track_id")
            record = self.runs.create(principal, NewRun(track_id=request.track_id, mode=RunMode.MANUAL))
            drive = LiveDrive(record, self.drive_dir)
            self.live.add(drive)
        return drive.state(frame=True)

    def step(self, principal: Principal, run_id: str, control: DriveControl) -> dict[str, Any]:
        return self._mine(principal, run_id).step(control)

    def finish(self, principal: Principal, run_id: str) -> RunRecord:
        with _FOLDERS:
            if self.live.get(run_id) is None and (folder := self._lost_folder(run_id)) is not None:
                record = self.runs.get(principal, run_id)  # 403 for another racer's run, as for a live one
                if record.owner_sub != principal.sub:
                    raise Forbidden("This drive belongs to another user.")
                return self._save_lost(record, folder)
        drive = self._mine(principal, run_id)
        return self._finish(drive)

    # -- drives the process lost (killed or restarted app) ----------------------------------------------------------

    def _lost_folder(self, run_id: str) -> Path | None:
        if self.drive_dir is None or not RUN_FOLDER.fullmatch(run_id or ""):
            return None
        folder = self.drive_dir / run_id
        return folder if folder.is_dir() else None

    def _save_lost_drives(self) -> None:
        if self.drive_dir is None or not self.drive_dir.is_dir():
            return
        for folder in sorted(self.drive_dir.iterdir()):
            if not RUN_FOLDER.fullmatch(folder.name) or self.live.get(folder.name) is not None:
                continue
            record = self.runs.store.get_run(folder.name)
            try:
                if record is None:  # its run record was never written: nothing to save it under
                    shutil.rmtree(folder, ignore_errors=True)
                else:
                    self._save_lost(record, folder)
            except DremError as error:
                logs.log(logging.WARNING, "lost drive not saved", run_id=folder.name, error=error.message)

    def _save_lost(self, record: RunRecord, folder: Path) -> RunRecord:
        """Upload what the lost drive recorded, up to its last whole controls row, and finalise it like a finish."""
        try:
            if record.status is not RunStatus.RECORDING:
                return record  # saved already (a finish that crashed after finalising)
            found = sorted(folder.rglob("controls.jsonl"))
            data = found[0].read_bytes() if found else b""
            whole = data[:data.rfind(b"\n") + 1]  # a row cut by the kill is not a decision anyone saw answered
            if not whole:
                return self.runs.mark(record, RunStatus.FAILED, "nothing was driven")
            self._upload(record, found[0].parent, whole)
            return self.runs.finalise_record(record)
        finally:
            shutil.rmtree(folder, ignore_errors=True)

    def _upload(self, record: RunRecord, folder: Path, controls: bytes | None = None) -> None:
        """The controls (`controls`: a lost drive's whole rows), the frames they name as one bundle and the first
        frame: three objects however long the drive."""
        from drem_sim.runs import run_objects

        objects = run_objects(folder, controls)
        with ThreadPoolExecutor(UPLOAD_THREADS) as pool:
            list(pool.map(lambda item: self.runs.files.put(record.prefix + item[0], item[1]), objects.items()))

    def _finish_quietly(self, drive: LiveDrive) -> None:
        try:
            self._finish(drive)
        except DremError as error:  # a drive that cannot be saved (nothing driven, bad upload) must not block a start
            logs.log(logging.WARNING, "abandoned drive not saved", run_id=drive.record.run_id, error=error.message)

    def _finish(self, drive: LiveDrive) -> RunRecord:
        if self.live.pop(drive.record.run_id) is None:
            raise Conflict("This drive has already finished.", field="run_id")
        try:
            if drive.recorder.frames == 0:
                drive.close()
                return self.runs.mark(drive.record, RunStatus.FAILED, "nothing was driven")
            self._upload(drive.record, drive.close())
            return self.runs.finalise_record(drive.record)
        finally:
            shutil.rmtree(drive.folder, ignore_errors=True)

    def _mine(self, principal: Principal, run_id: str) -> LiveDrive:
        drive = self.live.get(run_id)
        if drive is None and self._lost_folder(run_id) is not None:
            raise NotFound("This drive was interrupted (the server restarted): press Finish to save what you drove.",
                           field="run_id")
        if drive is None:
            raise NotFound("There is no live drive with this run id (finished, or the server restarted).",
                           field="run_id")
        if drive.record.owner_sub != principal.sub:
            raise Forbidden("This drive belongs to another user.")
        return drive
