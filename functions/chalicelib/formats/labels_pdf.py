"""Printable labels as PDFs: a QR label per car and a racer card from the registration desk.

Two stock formats, both common at events:

- **Avery L7160** (A4 sheet, 21 labels of 63.5 × 38.1 mm in 3 columns × 7 rows; top margin 15.15 mm, left 7.25 mm,
  column pitch 66.04 mm): a sheet of car labels, or one card per sheet in the first position.
- **Brother DK-11202** (62 × 100 mm die-cut labels on a roll, QL label printers): one label per page, the page is the
  label (100 × 62 mm, landscape).

QR codes always point at the app's public URL (`DREM_PUBLIC_URL`, what people's phones can reach), drawn as vector
squares from the `qrcode` matrix with a 4-module quiet zone, so they scan at any print size.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal
from urllib.parse import quote

from pydantic import BaseModel, ConfigDict

from chalicelib.core.errors import InvalidInput

QUIET_ZONE = 4
LabelFormat = Literal["avery-l7160", "brother-dk-11202"]


@dataclass(frozen=True)
class LabelStock:
    name: str
    page: tuple[float, float]  # width, height in mm
    label: tuple[float, float]
    columns: int
    rows: int
    origin: tuple[float, float]  # top-left corner of the first label
    pitch: tuple[float, float]  # distance between label origins

    @property
    def per_page(self) -> int:
        return self.columns * self.rows

    def position(self, index: int) -> tuple[float, float]:
        slot = index % self.per_page
        column, row = slot % self.columns, slot // self.columns
        return self.origin[0] + column * self.pitch[0], self.origin[1] + row * self.pitch[1]


STOCKS: dict[str, LabelStock] = {
    "avery-l7160": LabelStock("Avery L7160", (210, 297), (63.5, 38.1), 3, 7, (7.25, 15.15), (66.04, 38.1)),
    "brother-dk-11202": LabelStock("Brother DK-11202", (100, 62), (100, 62), 1, 1, (0, 0), (100, 62)),
}


class CarLabel(BaseModel):
    model_config = ConfigDict(frozen=True)
    device_id: str
    hostname: str
    fleet_name: str


class RacerCard(BaseModel):
    model_config = ConfigDict(frozen=True)
    username: str
    temporary_password: str
    display_name: str = ""  # whose card it is, in their own script (checked by the caller's form)


def car_status_url(public_url: str, device_id: str) -> str:
    return f"{public_url.rstrip('/')}/console/cars#car-{quote(device_id, safe='')}"


def racer_sign_in_url(public_url: str) -> str:
    """Sign in (a new racer first sets their own password), then straight to uploading models."""
    return f"{public_url.rstrip('/')}/login?next=/console/my-models"


def stock(format_name: str) -> LabelStock:
    found = STOCKS.get(format_name)
    if found is None:
        raise InvalidInput(f"Choose a label format: {', '.join(STOCKS)}.", field="format")
    return found


def car_labels_pdf(cars: Sequence[CarLabel], format_name: str, public_url: str) -> bytes:
    sheet = stock(format_name)
    if not cars:
        raise InvalidInput("There are no cars to label yet; activate a car first.", field="fleet_id")
    from chalicelib.formats.labels_drawing import draw_car_labels  # fpdf2 loads only when labels are printed

    return draw_car_labels(sheet, cars, public_url)


def racer_card_pdf(card: RacerCard, format_name: str, public_url: str, event_name: str = "") -> bytes:
    sheet = stock(format_name)
    from chalicelib.formats.labels_drawing import draw_racer_card  # fpdf2 loads only when labels are printed

    return draw_racer_card(sheet, card, public_url, event_name)


def label_headers(file_name: str) -> dict[str, Any]:
    return {"Content-Type": "application/pdf", "Cache-Control": "no-store",
            "Content-Disposition": f'attachment; filename="{file_name}"'}
