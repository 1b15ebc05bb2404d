"""Model dashboards: the registry of model versions with lineage, evaluations per track and scrutineering results.

Who may call: `/console/models/registry` (every racer's models) admins and operators; `/models/registry` any
signed-in user, showing their own models; a model's detail fragment and its evaluations, the owner or admins and
operators (another racer's model answers 403, via ModelService.get).
"""
from __future__ import annotations

from chalice import Blueprint, Response

from chalicelib import services
from chalicelib.auth.access import ADMIN, OPERATOR, SIGNED_IN, route
from chalicelib.core.principals import User
from chalicelib.domain.model_registry import Evaluation, EvaluationInput
from chalicelib.views.booth_views import racer_name
from chalicelib.views.registry_views import loss_plot, registry_plots, registry_racer_names
from drem_web import render

bp = Blueprint(__name__)


@route(bp, "/console/models/registry", allow={ADMIN, OPERATOR})
def staff_registry(principal: User) -> Response:
    """Every racer's model versions"""
    view = services.registry_service().registry(principal, everyone=True)
    return render.page("registry", view=view, plots=registry_plots(view),
                       racer_names=registry_racer_names(view, services.profile_service().public_by_subs))


@route(bp, "/models/registry", allow=SIGNED_IN)
def my_registry(principal: User) -> Response:
    """Your model versions"""
    view = services.registry_service().registry(principal, everyone=False)
    return render.page("registry", view=view, plots=registry_plots(view))


@route(bp, "/models/registry/{model_id}", allow=SIGNED_IN)
def model_detail(principal: User, model_id: str) -> Response:
    """One model: lineage, loss curve, evaluations (htmx fragment; owner or model staff)"""
    detail = services.registry_service().detail(principal, model_id)
    racer = racer_name(detail.model.owner_sub, detail.model.owner_username, services.profile_service().public_by_subs)
    return render.fragment("registry_model", detail=detail, loss_plot=loss_plot(detail), racer=racer)


@route(bp, "/api/models/{model_id}/evaluations", methods=["POST"], allow=SIGNED_IN, body=EvaluationInput,
       response=Evaluation, status_code=201, tags=("models",))
def record_evaluation(principal: User, model_id: str, body: EvaluationInput) -> Response:
    """Store an evaluation (a `drem sim eval` metrics.json) of your model; admins and operators: of any model"""
    evaluation = services.registry_service().record(principal, model_id, body)
    return Response(body={"evaluation": evaluation.model_dump(mode="json")}, status_code=201)


@route(bp, "/api/models/{model_id}/evaluations", allow=SIGNED_IN, response=list[Evaluation], tags=("models",))
def list_evaluations(principal: User, model_id: str) -> dict:
    """A model's evaluations (owner, admins, operators)"""
    found = services.registry_service().for_model(principal, model_id)
    return {"evaluations": [e.model_dump(mode="json") for e in found]}
