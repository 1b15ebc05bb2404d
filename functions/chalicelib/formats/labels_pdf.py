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

import qrcode
from fpdf import FPDF
from pydantic import BaseModel, ConfigDict

from chalicelib.core.errors import InvalidInput
from chalicelib.formats import pdf_fonts

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


def draw_qr(pdf: FPDF, data: str, x: float, y: float, size: float) -> None:
    """A QR code of `data` filling a `size` mm square (quiet zone included), dark modules as merged row runs."""
    code = qrcode.QRCode(border=QUIET_ZONE, error_correction=qrcode.constants.ERROR_CORRECT_M)
    code.add_data(data)
    code.make(fit=True)
    matrix = code.get_matrix()
    module = size / len(matrix)
    pdf.set_fill_color(255, 255, 255)
    pdf.rect(x, y, size, size, style="F")
    pdf.set_fill_color(0, 0, 0)
    for row_index, row in enumerate(matrix):
        column = 0
        while column < len(row):
            if not row[column]:
                column += 1
                continue
            start = column
            while column < len(row) and row[column]:
                column += 1
            # A hair of overlap so no white seam shows between modules in any renderer.
            pdf.rect(x + start * module, y + row_index * module, (column - start) * module + 0.01, module + 0.01,
                     style="F")


class _Labels(FPDF):
    def __init__(self, sheet: LabelStock, title: str, texts: Sequence[str]) -> None:
        super().__init__(unit="mm", format=sheet.page)
        self.sheet = sheet
        self.set_title(title)
        self.set_creator("drem")
        self.set_margins(0, 0, 0)
        self.set_auto_page_break(False)
        pdf_fonts.install(self, texts)
        self.set_text_shaping(any(pdf_fonts.needs_shaping(t) for t in texts))

    def slot(self, index: int) -> tuple[float, float]:
        if index % self.sheet.per_page == 0:
            self.add_page()
        return self.sheet.position(index)

    def text_line(self, x: float, y: float, width: float, height: float, text: str, size: float,
                  style: str = "") -> None:
        self.set_font(pdf_fonts.MAIN, style=style, size=size)
        while self.get_string_width(text) > width and size > 6:
            size -= 0.5
            self.set_font(pdf_fonts.MAIN, style=style, size=size)
        self.set_xy(x, y)
        self.cell(width, height, text)


def car_labels_pdf(cars: Sequence[CarLabel], format_name: str, public_url: str) -> bytes:
    sheet = stock(format_name)
    pdf = _Labels(sheet, "Car labels", [t for c in cars for t in (c.hostname, c.fleet_name)])
    if not cars:
        raise InvalidInput("There are no cars to label yet; activate a car first.", field="fleet_id")
    for index, car in enumerate(cars):
        x, y = pdf.slot(index)
        width, height = sheet.label
        pad = height * 0.08
        qr = height - 2 * pad
        draw_qr(pdf, car_status_url(public_url, car.device_id), x + pad, y + pad, qr)
        text_x, text_w = x + qr + 2 * pad, width - qr - 3 * pad
        scale = height / 38.1
        pdf.set_text_color(0, 0, 0)
        pdf.text_line(text_x, y + pad, text_w, 7 * scale, car.hostname, 12 * scale, "B")
        pdf.set_text_color(80, 80, 80)
        pdf.text_line(text_x, y + pad + 8 * scale, text_w, 5 * scale, f"Fleet: {car.fleet_name}", 8 * scale)
        pdf.text_line(text_x, y + pad + 14 * scale, text_w, 5 * scale, car.device_id, 6.5 * scale)
        pdf.text_line(text_x, y + height - pad - 5 * scale, text_w, 5 * scale, "Scan for this car's status",
                      6.5 * scale)
    return bytes(pdf.output())


def racer_card_pdf(card: RacerCard, format_name: str, public_url: str, event_name: str = "") -> bytes:
    sheet = stock(format_name)
    pdf = _Labels(sheet, "Racer card", [card.username, event_name, card.display_name])
    x, y = pdf.slot(0)
    width, height = sheet.label
    pad = height * 0.08
    qr = height - 2 * pad
    scale = height / 38.1
    draw_qr(pdf, racer_sign_in_url(public_url), x + width - pad - qr, y + pad, qr)
    text_w = width - qr - 3 * pad
    pdf.set_text_color(80, 80, 80)
    pdf.text_line(x + pad, y + pad, text_w, 4 * scale, card.display_name or event_name or "DeepRacer", 6.5 * scale)
    pdf.set_text_color(0, 0, 0)
    pdf.text_line(x + pad, y + pad + 4.5 * scale, text_w, 4 * scale, "Sign-in name", 6 * scale)
    pdf.text_line(x + pad, y + pad + 8.5 * scale, text_w, 6 * scale, card.username, 11 * scale, "B")
    pdf.text_line(x + pad, y + pad + 15.5 * scale, text_w, 4 * scale, "Temporary password", 6 * scale)
    size = 10 * scale
    pdf.set_font("Courier", style="B", size=size)  # a fixed-width face: 0/O and l/1 stay apart
    while pdf.get_string_width(card.temporary_password) > text_w and size > 5:
        size -= 0.5
        pdf.set_font("Courier", style="B", size=size)
    pdf.set_xy(x + pad, y + pad + 19.5 * scale)
    pdf.cell(text_w, 6 * scale, card.temporary_password)
    pdf.set_text_color(80, 80, 80)
    pdf.text_line(x + pad, y + height - pad - 4 * scale, text_w, 4 * scale, "Scan to sign in and upload", 6 * scale)
    return bytes(pdf.output())


def label_headers(file_name: str) -> dict[str, Any]:
    return {"Content-Type": "application/pdf", "Cache-Control": "no-store",
            "Content-Disposition": f'attachment; filename="{file_name}"'}
