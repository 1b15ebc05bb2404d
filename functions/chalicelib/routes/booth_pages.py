"""The learning booth's pages: drive a track, train on your runs, watch the job, inspect a run.

Who may call: every page needs a signed-in user and shows the caller's own runs, jobs and versions; admins and
operators get every racer's runs and jobs with `/booth?everyone=true`. A run's inspection page is the owner's or model
staff's (another racer's run answers 403, via RunService.get).
"""
from __future__ import annotations

from chalice import Blueprint, Response
from pydantic import BaseModel, ConfigDict, Field

from chalicelib import services
from chalicelib.auth.access import SIGNED_IN, route
from chalicelib.core.principals import User
from chalicelib.domain.booth_runs import ListRunsQuery
from chalicelib.domain.booth_training import DEFAULT_EPOCHS, MAX_EPOCHS
from chalicelib.domain.racer_models import MODEL_STAFF
from chalicelib.views import booth_views
from chalicelib.views.track_map import track_map
from drem_web import render

bp = Blueprint(__name__)


class TrainForm(BaseModel):
    model_config = ConfigDict(extra="ignore")
    epochs: int = Field(default=DEFAULT_EPOCHS, ge=1, le=MAX_EPOCHS)


class TrainActionQuery(BaseModel):
    model_config = ConfigDict(extra="forbid")
    epochs: str = Field(default=str(DEFAULT_EPOCHS), max_length=12, description="as the Train form's field holds it")


class JobsQuery(TrainActionQuery):
    """The jobs list's poll; it brings the epochs field along, so the Train button it also answers fits them."""
    everyone: bool = Field(default=False, description="admins and operators: every racer's jobs")


@route(bp, "/booth", allow=SIGNED_IN, query=ListRunsQuery)
def booth(principal: User, query: ListRunsQuery) -> Response:
    """The booth: tracks to drive, your runs, training jobs and model versions"""
    view = booth_views.booth_view(principal, services.run_service(), services.training_service(),
                                  services.track_service(), services.device_service(),
                                  services.profile_service().public_by_subs, everyone=query.everyone)
    return render.page("booth", view=view)


@route(bp, "/booth/jobs", allow=SIGNED_IN, query=JobsQuery)
def booth_jobs(principal: User, query: JobsQuery) -> Response:
    """Your training jobs (htmx fragment, polled while one is queued or running), with the Train button as it is now
    and, once no job is busy, your versions"""
    everyone, training = query.everyone and bool(principal.roles & MODEL_STAFF), services.training_service()
    jobs = booth_views.jobs_view(principal, training, everyone=query.everyone)
    names = booth_views.job_racer_names(jobs, services.profile_service().public_by_subs) if everyone else {}
    return render.fragment("booth_jobs", jobs=jobs, everyone=everyone, job_names=names,
                           train_action=booth_views.train_action(principal, training, query.epochs),
                           **booth_views.versions_when_idle(principal, training, jobs))


@route(bp, "/booth/train", methods=["POST"], allow=SIGNED_IN, body=TrainForm)
def booth_train(principal: User, body: TrainForm) -> Response:
    """Queue a training job on all your finished manual runs (htmx; answers the jobs fragment and the Train button,
    off while the job waits)"""
    training = services.training_service()
    training.train_on_my_runs(principal, epochs=body.epochs)
    return render.fragment("booth_jobs", jobs=booth_views.jobs_view(principal, training),
                           train_action=booth_views.train_action(principal, training, str(body.epochs)))


@route(bp, "/booth/train-action", allow=SIGNED_IN, query=TrainActionQuery)
def booth_train_action(principal: User, query: TrainActionQuery) -> Response:
    """The Train button and why it is off, for these epochs (htmx: the epochs field asks as it changes)"""
    action = booth_views.train_action(principal, services.training_service(), query.epochs)
    return render.fragment("booth_train_action", action=action)


@route(bp, "/booth/drive/{track_id}", allow=SIGNED_IN)
def booth_drive(principal: User, track_id: str) -> Response:
    """Drive a track in the browser (keyboard, gamepad, touch); the run lands in your runs"""
    track = services.track_service().get(track_id)
    return render.page("booth_drive", track=track, track_map=track_map(track, testid="drive-map"))


@route(bp, "/booth/runs/{run_id}", allow=SIGNED_IN)
def booth_run(principal: User, run_id: str) -> Response:
    """One run: top-down picture, metrics, controls and links to its artifacts"""
    runs = services.run_service()
    run, rows = runs.get(principal, run_id), runs.controls(principal, run_id)
    inspection = booth_views.run_inspection(run, rows)
    racer = booth_views.racer_name(run.owner_sub, run.owner_username, services.profile_service().public_by_subs)
    return render.page("booth_run", run=run, inspection=inspection, racer=racer,
                       track_map=booth_views.run_map(services.track_service(), run, rows))


@route(bp, "/booth/versions/{model_id}/active", methods=["POST"], allow=SIGNED_IN)
def booth_make_active(principal: User, model_id: str) -> Response:
    """Mark one of your versions active (htmx; answers the booth page)"""
    services.training_service().set_active(principal, model_id)
    view = booth_views.booth_view(principal, services.run_service(), services.training_service(),
                                  services.track_service(), services.device_service(),
                                  services.profile_service().public_by_subs, everyone=False)
    return render.page("booth", view=view)
