"""Printable labels: QR labels for the cars (operators) and a racer's card at the registration desk.

The card is rendered from the username and temporary password the desk has just shown; the password travels in the
POST body only (never a URL, never stored) and the PDF is served `no-store`.
"""
from __future__ import annotations

from chalice import Blueprint, Response
from pydantic import BaseModel, ConfigDict, Field, field_validator

from chalicelib import services
from chalicelib.auth.access import ADMIN, OPERATOR, REGISTRATION, route
from chalicelib.core.principals import User
from chalicelib.domain.devices import DeviceKind
from chalicelib.domain.names import check_display_name
from chalicelib.formats.labels_pdf import (
    CarLabel,
    LabelFormat,
    RacerCard,
    car_labels_pdf,
    label_headers,
    racer_card_pdf,
)
from chalicelib.routes.console.forms import submitted
from chalicelib.settings import get_settings

bp = Blueprint(__name__)


class CarLabelsQuery(BaseModel):
    model_config = ConfigDict(extra="ignore")
    format: LabelFormat = "avery-l7160"
    fleet_id: str = Field(default="", max_length=64)


class RacerCardForm(BaseModel):
    model_config = ConfigDict(extra="ignore")
    username: str = Field(min_length=1, max_length=128)
    temporary_password: str = Field(min_length=1, max_length=256)
    display_name: str = Field(default="", max_length=200)
    format: LabelFormat = "avery-l7160"

    @field_validator("display_name")
    @classmethod
    def _display_name(cls, value: str) -> str:
        return check_display_name(value) if value.strip() else ""


@route(bp, "/console/cars/labels.pdf", allow={ADMIN, OPERATOR}, query=CarLabelsQuery)
def car_labels(principal: User, query: CarLabelsQuery) -> Response:
    names = {f.fleet_id: f.name for f in services.fleet_service().list_fleets()}
    cars = [CarLabel(device_id=d.device_id, hostname=d.hostname, fleet_name=names.get(d.fleet_id or "", "no fleet"))
            for d in services.device_service().list_devices(fleet_id=query.fleet_id or None)
            if d.kind is DeviceKind.CAR]
    body = car_labels_pdf(cars, query.format, get_settings().public_url)
    return Response(body=body, headers=label_headers(f"car-labels-{query.format}.pdf"))


@route(bp, "/console/registration/card.pdf", methods=["POST"], allow={ADMIN, REGISTRATION})
def racer_card(principal: User) -> Response:
    card = RacerCardForm.model_validate(submitted(bp.current_request, "username", "temporary_password",
                                                  "display_name", "format"))
    body = racer_card_pdf(RacerCard(username=card.username, temporary_password=card.temporary_password,
                                    display_name=card.display_name), card.format, get_settings().public_url)
    return Response(body=body, headers=label_headers(f"racer-card-{card.username}.pdf"))
