"""Scrutineering a racer's model on an event's track: a short simulator test drive before it races.

Console models drive through their ONNX conversion (made at upload, stored beside the untouched archive); drem's own
ONNX models drive as they are. The drive runs synchronously and is bounded (a few laps, ~seconds each); its result
(laps completed, best lap, off-tracks) is stored on the model so the console, the API and the CLI all show it.
"""
from __future__ import annotations

import logging
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol

from pydantic import BaseModel, ConfigDict, Field

from chalicelib import logs
from chalicelib.auth.principals import Principal
from chalicelib.domain.errors import Conflict, NotFound
from chalicelib.domain.racer_models import ModelChanged, ModelRecord, ModelService, ModelStatus, ScrutineerResult
from chalicelib.formats.league_export import ExportLimits, read_tar_gz

MAX_LAPS = 3
DEFAULT_TRACK_TYPE = "REINVENT_2018"
# The event track types drem_sim has a twin for (drem_sim.learn.scrutineer.EVENT_TRACKS); others drive the fallback.
TRACK_TYPES = ("REINVENT_2018", "REINVENT_2019", "ATOZ_SPEEDWAY", "SUMMIT_SPEEDWAY", "FOREVER_RACEWAY")
_MEMBERS = ("model_metadata.json", "model.onnx")
_READ_LIMITS = ExportLimits(max_file_bytes=128 * 1024 * 1024, max_total_read_bytes=160 * 1024 * 1024)


class ScrutineerRequest(BaseModel):
    model_config = ConfigDict(extra="forbid")
    event_id: str | None = Field(default=None, max_length=64, description="drive on this event's track type")
    track_type: str | None = Field(default=None, max_length=40, pattern=r"^[A-Z0-9_]+$",
                                   description="or name the track type (default REINVENT_2018)")
    laps: int = Field(default=1, ge=1, le=MAX_LAPS)


class TrackTypes(Protocol):
    def track_type_of(self, event_id: str) -> str: ...


# drive(model folder holding model_metadata.json + model.onnx, track type, laps) -> a drem_sim ScrutineerReport
Drive = Callable[[Path, str, int], Any]


def simulator_drive(folder: Path, track_type: str, laps: int) -> Any:
    try:
        from drem_sim.learn.scrutineer import scrutineer_for_event
    except ModuleNotFoundError:
        raise Conflict("Scrutineering needs the simulator, which is not installed on this server.") from None
    try:
        return scrutineer_for_event(folder, track_type, laps)
    except Exception as error:  # a racer's graph can fail in ways of its own: say so, never a 500
        logs.log(logging.WARNING, "scrutineering drive failed", error=repr(error)[:300])
        raise Conflict(f"The simulator could not drive this model: {str(error)[:200]}") from None


class ScrutineerService:
    def __init__(self, models: ModelService, tracks: TrackTypes, *, drive: Drive = simulator_drive) -> None:
        self.models = models
        self.tracks = tracks
        self.drive = drive

    def scrutineer(self, principal: Principal, model_id: str, request: ScrutineerRequest) -> ModelRecord:
        record = self.models.get(principal, model_id)  # owner or model staff
        if record.status is not ModelStatus.AVAILABLE or record.s3_key is None:
            raise Conflict(f"Model '{record.name}' is {record.status.value}; only AVAILABLE models can be "
                           "scrutineered.", field="model_id")
        if record.scrutiny == "cannot_scrutineer":
            raise Conflict(f"Model '{record.name}' cannot be scrutineered: {record.scrutiny_reason}. It can still "
                           "race on a stock DeepRacer.", field="model_id")
        track_type = (self.tracks.track_type_of(request.event_id) if request.event_id
                      else request.track_type or DEFAULT_TRACK_TYPE)
        with tempfile.TemporaryDirectory(prefix="scrutineer-") as folder:
            self._model_files(record, Path(folder))
            report = self.drive(Path(folder), track_type, request.laps)
        result = ScrutineerResult(
            verdict=report.verdict, message=report.message, track=report.track, track_type=report.track_type,
            laps=report.laps, laps_completed=report.laps_completed, best_lap_time_s=report.best_lap_time_s,
            mean_lap_time_s=report.mean_lap_time_s, offtrack_count=report.offtrack_count, at=self.models.now())
        return self._store(record, result)

    def _model_files(self, record: ModelRecord, folder: Path) -> None:
        """model_metadata.json from the archive; model.onnx from the archive or, for console models, the conversion."""
        files = self.models.files
        download = files.download_bounded(record.s3_key or "", limit=self.models.max_upload_bytes)
        if download is None or download.too_large:
            raise NotFound(f"The archive of model '{record.name}' is missing.", field="model_id")
        with download.body:
            found, _ = read_tar_gz(download.body, limits=_READ_LIMITS,
                                   wanted=lambda name: name.removeprefix("./") in _MEMBERS)
        found = {name.removeprefix("./"): data for name, data in found.items()}
        if record.converted_key:
            converted = files.download_bounded(record.converted_key, limit=_READ_LIMITS.max_file_bytes)
            if converted is None or converted.too_large:
                raise NotFound(f"The ONNX conversion of model '{record.name}' is missing.", field="model_id")
            with converted.body:
                found["model.onnx"] = converted.body.read()
        for name in _MEMBERS:
            if name in found:
                (folder / name).write_bytes(found[name])

    def _store(self, record: ModelRecord, result: ScrutineerResult) -> ModelRecord:
        for _ in range(3):
            updated = record.model_copy(update={"scrutineer_result": result})
            try:
                self.models.store.replace(updated, expected_status=ModelStatus.AVAILABLE)
                return updated
            except ModelChanged:
                latest = self.models.store.get(record.owner_sub, record.model_id)
                if latest is None or latest.status is not ModelStatus.AVAILABLE:
                    raise Conflict(f"Model '{record.name}' changed while it was scrutineered.") from None
                record = latest
        raise Conflict(f"Model '{record.name}' changed while it was scrutineered.")
