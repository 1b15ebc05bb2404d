"""Drawing the label PDFs with fpdf2: QR codes as vector squares and the text of each label.

Kept apart from `labels_pdf` (stocks, URLs, the label models) so the app imports fpdf2 and fontTools, about 0.9 s
of CPU, only when someone prints labels, not at every start of the app.
"""
from __future__ import annotations

from collections.abc import Sequence

import qrcode
from fpdf import FPDF

from chalicelib.formats import pdf_fonts
from chalicelib.formats.labels_pdf import (
    QUIET_ZONE,
    CarLabel,
    LabelStock,
    RacerCard,
    car_status_url,
    racer_sign_in_url,
)


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


def draw_car_labels(sheet: LabelStock, cars: Sequence[CarLabel], public_url: str) -> bytes:
    pdf = _Labels(sheet, "Car labels", [t for c in cars for t in (c.hostname, c.fleet_name)])
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


def draw_racer_card(sheet: LabelStock, card: RacerCard, public_url: str, event_name: str) -> bytes:
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
