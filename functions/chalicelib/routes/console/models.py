"""Every racer's models (HTML, operators and admins): filter by racer and status, give models to a car, and watch
each car download, verify and load them (a polling fragment). Same services as /api/models and
/api/cars/{device_id}/models; only AVAILABLE models can be given to a car (the assignment service says so)."""
from __future__ import annotations

from collections.abc import Sequence

from chalice import Blueprint, Response
from pydantic import BaseModel, ConfigDict, Field

from chalicelib import services
from chalicelib.auth.access import ADMIN, OPERATOR, SIGNED_IN, route
from chalicelib.core.errors import InvalidInput
from chalicelib.core.principals import User
from chalicelib.domain.assignments import AssignedModel, Assignment
from chalicelib.domain.devices import DeviceKind
from chalicelib.domain.model_scrutiny import TRACK_TYPES, ScrutineerRequest
from chalicelib.domain.racer_models import MODEL_STAFF as MODEL_STAFF_ROLES
from chalicelib.domain.racer_models import ListQuery, ModelRecord, ModelStatus
from chalicelib.routes.console.forms import SHOWN_ON_FORM, error_status, field_errors, submitted, submitted_list
from chalicelib.views.racer_names import shown_racer_names
from drem_leaderboard.names import name_key
from drem_web import render

bp = Blueprint(__name__)

MODEL_STAFF = {ADMIN, OPERATOR}
STATUSES = [s.value for s in ModelStatus if s is not ModelStatus.DELETED]
_LISTED = 100


class ModelFilter(BaseModel):
    model_config = ConfigDict(extra="ignore")
    racer: str = Field(default="", max_length=128)
    status: ModelStatus | None = None

    def keeps(self, model: ModelRecord, shown_name: str) -> bool:
        """The racer box matches the start of the name the page shows ("Björn", "山田") or of the sign-in name."""
        racer = name_key(self.racer.strip())
        return ((not racer or any(name_key(name).startswith(racer) for name in (shown_name, model.owner_username)))
                and (self.status is None or model.status is self.status))


@route(bp, "/console/models", allow=MODEL_STAFF)
def models_page(principal: User) -> Response:
    listed = _listed(principal)
    racer_names = _racer_names(listed)
    query, errors, models = _filtered(listed, racer_names)
    return render.page("console/models", status=400 if errors else 200, query=query, errors=errors, models=models,
                       statuses=STATUSES, cars=_cars(), track_types=TRACK_TYPES, show_scrutiny_detail=True,
                       assignable=[m for m in listed if m.status is ModelStatus.AVAILABLE], racer_names=racer_names)


@route(bp, "/console/models/rows", allow=MODEL_STAFF)
def model_rows(principal: User) -> Response:
    listed = _listed(principal)
    racer_names = _racer_names(listed)
    query, errors, models = _filtered(listed, racer_names)
    return render.fragment("console/model_rows", status=400 if errors else 200, errors=errors, models=models,
                           track_types=TRACK_TYPES, show_scrutiny_detail=True, racer_names=racer_names)


@route(bp, "/console/models/{model_id}/check", methods=["POST"], allow=MODEL_STAFF)
def check_model_again(principal: User, model_id: str) -> Response:
    """Staff start a check a crash cut short at once (the scrutineering worker would within a few minutes)."""
    errors: dict[str, str] = {}
    try:
        services.model_service().complete(principal, model_id)
    except SHOWN_ON_FORM as exc:
        errors = field_errors(exc, "model_id")
    listed = _listed(principal)
    racer_names = _racer_names(listed)
    query, filter_errors, models = _filtered(listed, racer_names)
    return render.fragment("console/model_rows", status=200, errors=errors or filter_errors, models=models,
                           track_types=TRACK_TYPES, racer_names=racer_names)


@route(bp, "/console/models/assign", methods=["POST"], allow=MODEL_STAFF)
def assign_models(principal: User) -> Response:
    request = bp.current_request
    values = submitted(request, "device_id", "confirmed")
    device_id, model_ids = values.get("device_id", ""), submitted_list(request, "model_ids")
    asked = values.get("confirmed") != "yes"
    doubts = services.scrutineer_service().doubts(model_ids, _racer_names_of) if asked else []
    if device_id and doubts:  # asked, not refused: staff may still send a model that did not pass
        return render.fragment("console/car_status", assignment=None, device_id=device_id, errors={},
                               notice="", doubts=doubts, model_ids=model_ids)
    service = services.assignment_service()
    try:
        assignment = service.assign(principal, _chosen_car(device_id), model_ids)
    except SHOWN_ON_FORM as exc:
        # A car deregistered meanwhile: said in the status box, not as a 404 page swapped into it.
        errors = field_errors(exc, "model_ids", missing_object_field="device_id")
        return _car_status(None, device_id, errors, error_status(exc))
    return _car_status(assignment, device_id, {}, 200, notice="Models sent to the car.")


@route(bp, "/console/models/car-status", allow=MODEL_STAFF)
def car_status(principal: User) -> Response:
    device_id = ((bp.current_request.query_params or {}).get("device_id") or "").strip()
    assignment = services.assignment_service().for_staff(device_id) if device_id else None
    return _car_status(assignment, device_id, {}, 200)


def _car_status(assignment: Assignment | None, device_id: str, errors: dict[str, str], status: int,
                notice: str = "") -> Response:
    racer_names = _racer_names(assignment.models) if assignment else {}
    return render.fragment("console/car_status", status=status, assignment=assignment, device_id=device_id,
                           errors=errors, notice=notice, racer_names=racer_names)


def _chosen_car(device_id: str) -> str:
    if not device_id:
        raise InvalidInput("Choose a car.", field="device_id")
    return device_id


def _listed(principal: User) -> list[ModelRecord]:
    return services.model_service().list_models(principal, ListQuery(limit=_LISTED)).models


def _racer_names(models: Sequence[ModelRecord | AssignedModel]) -> dict[str, str]:
    """{owner sub: display name}, told apart among the racers the table lists (one batch profile read)."""
    return shown_racer_names([(m.owner_sub, m.owner_username) for m in models],
                             services.profile_service().public_by_subs)


def _racer_names_of(owners: list[tuple[str, str]]) -> dict[str, str]:
    """The scrutineering warning names racers as the Models page does (one batch profile read)."""
    return shown_racer_names(owners, services.profile_service().public_by_subs)


def _filtered(listed: list[ModelRecord], racer_names: dict[str, str]
              ) -> tuple[dict[str, str], dict[str, str], list[ModelRecord]]:
    raw = {k: v for k, v in (bp.current_request.query_params or {}).items() if k in ("racer", "status") and v}
    query = {"racer": raw.get("racer", ""), "status": raw.get("status", "")}
    try:
        wanted = ModelFilter.model_validate(raw)
    except SHOWN_ON_FORM as exc:
        return query, field_errors(exc, "status"), []
    return query, {}, [m for m in listed if wanted.keeps(m, racer_names.get(m.owner_sub, m.owner_username))]


def _cars() -> list:
    return [d for d in services.device_service().list_devices() if d.kind is DeviceKind.CAR]


# --- scrutineering (owner or model staff: the service decides, another racer's model answers 403) ----------------

@route(bp, "/console/models/{model_id}/scrutiny", allow=SIGNED_IN)
def model_scrutiny(principal: User, model_id: str) -> Response:
    """The scrutineering box alone: the page polls it while the background drive is queued or driving."""
    return render.fragment("console/model_scrutiny", model=services.model_service().get(principal, model_id),
                           track_types=TRACK_TYPES, show_scrutiny_detail=_is_model_staff(principal))


@route(bp, "/console/models/{model_id}/scrutineer", methods=["POST"], allow=SIGNED_IN)
def scrutineer_model(principal: User, model_id: str) -> Response:
    values = submitted(bp.current_request, "track_type", "event_id", "laps")
    error, status = "", 200
    try:
        request = ScrutineerRequest.model_validate({key: value for key, value in values.items() if value})
        model = services.scrutineer_service().scrutineer(principal, model_id, request)
    except SHOWN_ON_FORM as exc:
        model = services.model_service().get(principal, model_id)
        error, status = " ".join(field_errors(exc, "model_id").values()), error_status(exc)
    return render.fragment("console/model_scrutiny", status=status, model=model, scrutiny_error=error,
                           track_types=TRACK_TYPES, show_scrutiny_detail=_is_model_staff(principal))


def _is_model_staff(principal: User) -> bool:
    """Staff see what the software said when a test drive stopped; racers see the sentence only."""
    return bool(principal.roles & MODEL_STAFF_ROLES)
