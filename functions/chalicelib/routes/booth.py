"""The learning booth's JSON API: tracks, runs (with artifacts, live manual drive and metrics), training jobs and the
active model version.

Who may call: tracks are public (the simulator's canonical track configs). Everything else needs a signed-in user; per
object (chalicelib.domain.booth_runs / booth_training) a racer sees, drives and trains on their own runs only (another
racer's run or job answers 403) and admins and operators see every racer's (`?everyone=true`).
"""
from __future__ import annotations

from chalice import Blueprint, Response

from chalicelib import services
from chalicelib.auth.access import PUBLIC, SIGNED_IN, body_bytes, route
from chalicelib.core.principals import Principal, User
from chalicelib.domain.booth_drive import DriveControl, StartDrive
from chalicelib.domain.booth_runs import ListRunsQuery, NewRun, RunRecord
from chalicelib.domain.booth_tracks import TrackDetail, TrackInfo
from chalicelib.domain.booth_training import NewJob

bp = Blueprint(__name__)
ARTIFACT_TYPES = ["application/octet-stream", "image/png", "application/x-ndjson", "application/jsonl",
                  "application/json", "application/x-tar"]


@route(bp, "/api/tracks", allow=PUBLIC, response=list[TrackInfo], tags=("booth",))
def list_tracks(principal: Principal) -> dict:
    """The tracks the simulator can drive (closed loops)"""
    return {"tracks": [t.model_dump() for t in services.track_service().all_tracks()]}


@route(bp, "/api/tracks/{track_id}", allow=PUBLIC, response=TrackDetail, tags=("booth",))
def get_track(principal: Principal, track_id: str) -> dict:
    """One track with its centre line (metres)"""
    return {"track": services.track_service().get(track_id).model_dump()}


@route(bp, "/api/runs", methods=["POST"], allow=SIGNED_IN, body=NewRun, response=RunRecord, status_code=201,
       tags=("booth",))
def create_run(principal: User, body: NewRun) -> Response:
    """Start a run: manual (then upload its artifacts and finalise it) or autonomous (the booth worker drives it)"""
    return Response(body={"run": services.run_service().create(principal, body).public()}, status_code=201)


@route(bp, "/api/runs", allow=SIGNED_IN, query=ListRunsQuery, response=list[RunRecord], tags=("booth",))
def list_runs(principal: User, query: ListRunsQuery) -> dict:
    """Your runs, newest first (admins and operators: `everyone=true` for every racer's)"""
    return {"runs": [r.public() for r in services.run_service().list_runs(principal, query)]}


@route(bp, "/api/metrics/runs", allow=SIGNED_IN, query=ListRunsQuery, tags=("booth",))
def run_aggregates(principal: User, query: ListRunsQuery) -> dict:
    """Metrics aggregated per track and driver (a person or a model version) over the runs you may see"""
    return {"aggregates": services.run_service().aggregates(principal, query)}


@route(bp, "/api/runs/{run_id}", allow=SIGNED_IN, response=RunRecord, tags=("booth",))
def get_run(principal: User, run_id: str) -> dict:
    """One run with its metrics (owner, admins, operators)"""
    return {"run": services.run_service().get(principal, run_id).public()}


@route(bp, "/api/runs/{run_id}/artifacts/{name}", methods=["PUT"], allow=SIGNED_IN, content_types=ARTIFACT_TYPES,
       tags=("booth",))
def put_artifact(principal: User, run_id: str, name: str) -> dict:
    """Upload `controls.jsonl`, `frames.tar` (every frame in one tar) or `frame-NNNNNN.png` of your RECORDING run"""
    data = body_bytes(bp.current_request)
    return {"stored": services.run_service().put_artifact(principal, run_id, name, data)}


@route(bp, "/api/runs/{run_id}/artifacts/{name}", allow=SIGNED_IN, tags=("booth",))
def get_artifact(principal: User, run_id: str, name: str) -> Response:
    """Redirect to a 5-minute link of an artifact: controls.jsonl, metadata.json, topdown.png, frames.tar, the first
    frame (frame-000000.png)"""
    url = services.run_service().artifact_url(principal, run_id, name)
    return Response(body="", status_code=302, headers={"Location": url, "Cache-Control": "no-store"})


@route(bp, "/api/runs/{run_id}/finalise", methods=["POST"], allow=SIGNED_IN, response=RunRecord, tags=("booth",))
def finalise_run(principal: User, run_id: str) -> dict:
    """Finish your uploaded run: metrics, metadata.json and the top-down picture"""
    return {"run": services.run_service().finalise(principal, run_id).public()}


@route(bp, "/api/drive", methods=["POST"], allow=SIGNED_IN, body=StartDrive, status_code=201, tags=("booth",))
def start_drive(principal: User, body: StartDrive) -> Response:
    """Start driving a track live: a manual run, recorded on the server; answers the first camera frame"""
    return Response(body=services.drive_service().start(principal, body), status_code=201)


@route(bp, "/api/runs/{run_id}/drive", methods=["POST"], allow=SIGNED_IN, body=DriveControl, tags=("booth",))
def drive_step(principal: User, run_id: str, body: DriveControl) -> dict:
    """One decision (1/15 s) of your live drive with this control; answers the next frame and the car's state"""
    return services.drive_service().step(principal, run_id, body)


@route(bp, "/api/runs/{run_id}/drive/finish", methods=["POST"], allow=SIGNED_IN, response=RunRecord, tags=("booth",))
def finish_drive(principal: User, run_id: str) -> dict:
    """Stop driving: the run is uploaded to the runs bucket and finalised"""
    return {"run": services.drive_service().finish(principal, run_id).public()}


@route(bp, "/api/training-jobs", methods=["POST"], allow=SIGNED_IN, body=NewJob, status_code=201, tags=("booth",))
def create_job(principal: User, body: NewJob) -> Response:
    """Queue a training job on a set of your finished manual runs"""
    return Response(body={"job": services.training_service().create(principal, body).public()}, status_code=201)


@route(bp, "/api/training-jobs", allow=SIGNED_IN, query=ListRunsQuery, tags=("booth",))
def list_jobs(principal: User, query: ListRunsQuery) -> dict:
    """Your training jobs with queue position, progress and loss (admins and operators: `everyone=true`)"""
    jobs = services.training_service().list_jobs(principal, everyone=query.everyone)
    return {"jobs": [j.public() for j in jobs]}


@route(bp, "/api/training-jobs/{job_id}", allow=SIGNED_IN, tags=("booth",))
def get_job(principal: User, job_id: str) -> dict:
    """One training job: queued (position), running (progress, loss), done (model version) or failed (reason)"""
    return {"job": services.training_service().get(principal, job_id).public()}


@route(bp, "/api/models/{model_id}/active", methods=["POST"], allow=SIGNED_IN, tags=("booth",))
def mark_active(principal: User, model_id: str) -> dict:
    """Mark one of your AVAILABLE model versions as your active one"""
    return {"active": services.training_service().set_active(principal, model_id).public()}
