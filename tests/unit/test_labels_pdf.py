"""Printable labels: car QR labels and the registration desk's racer card, on an A4 label sheet (Avery L7160) and a
label roll (Brother DK-11202). The QR codes are decoded from the rendered page with OpenCV, as a phone would."""
from __future__ import annotations

import html
import re
from pathlib import Path

import cv2
import numpy as np
import pytest

from chalicelib.formats.labels_pdf import CarLabel, RacerCard, car_labels_pdf, racer_card_pdf
from tests.unit.pdf_helpers import pdf_pages, pdf_text
from tests.unit.scenario import Scenario

pytestmark = pytest.mark.unit

PUBLIC_URL = "https://race.example.org"
BROWSER_ACCEPT = "text/html,application/xhtml+xml,application/xml;q=0.9,*/*;q=0.8"


def decoded_qr_codes(image) -> list[str]:
    """Every QR code OpenCV finds on a rendered page."""
    pixels = cv2.cvtColor(np.asarray(image), cv2.COLOR_RGB2BGR)
    found, texts, _points, _ = cv2.QRCodeDetector().detectAndDecodeMulti(pixels)
    return sorted(t for t in texts if t) if found else []


def _mm(pixels: int, dpi: int) -> float:
    return pixels / dpi * 25.4


def test_car_labels_fill_avery_l7160_sheets_with_scannable_status_links(tmp_path: Path) -> None:
    cars = [CarLabel(device_id=f"dev{i:02d}", hostname=f"car-{i:02d}", fleet_name="Track 1 fleet") for i in range(23)]
    pdf = car_labels_pdf(cars, "avery-l7160", PUBLIC_URL)
    pages = pdf_pages(pdf, tmp_path, dpi=150)
    assert len(pages) == 2  # 21 labels per sheet
    assert [round(_mm(s, 150)) for s in pages[0].size] == [210, 297]
    text = pdf_text(pdf, tmp_path)
    assert "car-00" in text and "car-22" in text and "Fleet: Track 1 fleet" in text and "dev07" in text
    codes = decoded_qr_codes(pages[1])
    assert codes == [f"{PUBLIC_URL}/console/cars#car-dev21", f"{PUBLIC_URL}/console/cars#car-dev22"]
    first_sheet = decoded_qr_codes(pages[0])
    assert len(first_sheet) == 21 and f"{PUBLIC_URL}/console/cars#car-dev00" in first_sheet


def test_a_car_label_on_the_brother_roll_is_one_62_by_100_mm_page(tmp_path: Path) -> None:
    cars = [CarLabel(device_id="abc123", hostname="deepracer-7", fleet_name="Fleet Ω")]
    pdf = car_labels_pdf(cars, "brother-dk-11202", PUBLIC_URL)
    [page] = pdf_pages(pdf, tmp_path, dpi=200)
    assert [round(_mm(s, 200)) for s in page.size] == [100, 62]
    assert decoded_qr_codes(page) == [f"{PUBLIC_URL}/console/cars#car-abc123"]
    assert "deepracer-7" in pdf_text(pdf, tmp_path) and "Fleet Ω" in pdf_text(pdf, tmp_path)


def test_racer_card_shows_the_credentials_and_a_sign_in_qr(tmp_path: Path) -> None:
    card = RacerCard(username="lea_racer", temporary_password="Zq7-l1O0-pass")
    for stock, dpi in (("avery-l7160", 300), ("brother-dk-11202", 200)):
        pdf = racer_card_pdf(card, stock, PUBLIC_URL)
        folder = tmp_path / stock
        folder.mkdir()
        [page] = pdf_pages(pdf, folder, dpi=dpi)
        assert decoded_qr_codes(page) == [f"{PUBLIC_URL}/login?next=/console/my-models"], stock
        text = pdf_text(pdf, tmp_path)
        assert "lea_racer" in text and "Zq7-l1O0-pass" in text and "Temporary password" in text


def test_unknown_label_format_is_a_clear_error() -> None:
    from chalicelib.core.errors import InvalidInput

    with pytest.raises(InvalidInput, match="avery-l7160"):
        car_labels_pdf([CarLabel(device_id="x", hostname="x", fleet_name="f")], "dymo", PUBLIC_URL)


def test_operators_print_car_labels_pointing_at_the_public_url(console, monkeypatch, tmp_path: Path) -> None:
    from chalicelib.settings import get_settings

    monkeypatch.setenv("DREM_PUBLIC_URL", PUBLIC_URL)
    get_settings.cache_clear()
    scenario = Scenario(console.desk).add_fleet("Pit lane")
    device_id = scenario.add_car("car-blue")
    scenario.add_timer("timer-1")
    web = console.sign_in("op-web", "operator")
    page = web.get("/console/cars").body.decode()
    link = html.unescape(re.search(r'href="([^"]+)" data-testid="labels-roll"', page).group(1))
    reply = web.get(link, headers={"Accept": BROWSER_ACCEPT})
    assert reply.status_code == 200 and reply.headers["Content-Type"] == "application/pdf"
    [label] = pdf_pages(reply.body, tmp_path, dpi=200)  # the timer gets no label
    assert decoded_qr_codes(label) == [f"{PUBLIC_URL}/console/cars#car-{device_id}"]
    assert "car-blue" in pdf_text(reply.body, tmp_path) and "Pit lane" in pdf_text(reply.body, tmp_path)


def test_registration_desk_prints_the_new_racers_card(console, monkeypatch, tmp_path: Path) -> None:
    from chalicelib.settings import get_settings

    monkeypatch.setenv("DREM_PUBLIC_URL", PUBLIC_URL)
    get_settings.cache_clear()
    console.sign_in("desk-web", "registration")
    desk = console.post("/console/registration", {"username": "new_racer", "email": "new@example.test",
                                                   "country_code": "SE", "display_name": "김민준"})
    assert desk.status_code == 201
    page = desk.body.decode()
    password = html.unescape(re.search(r'data-testid="temporary-password">([^<]+)<', page).group(1))
    card_form = re.search(r'<form[^>]*data-testid="racer-card-form".*?</form>', page, re.S).group(0)
    fields = {name: html.unescape(value) for name, value in
              re.findall(r'<input type="hidden" name="(\w+)" value="([^"]*)"', card_form)}
    assert fields["username"] == "new_racer" and fields["temporary_password"] == password
    reply = console.web.post("/console/registration/card.pdf", {**fields, "format": "avery-l7160"},
                             headers={"Accept": BROWSER_ACCEPT})
    assert reply.status_code == 200 and reply.headers["Cache-Control"] == "no-store"
    text = pdf_text(reply.body, tmp_path)
    assert "new_racer" in text and password in text
    assert "김민준" in text  # whose card it is, in their own script (Hangul from the Korean fallback font)
    [sheet] = pdf_pages(reply.body, tmp_path, dpi=300)
    assert decoded_qr_codes(sheet) == [f"{PUBLIC_URL}/login?next=/console/my-models"]

    # Without the desk's CSRF token the card is refused (a forged cross-site post cannot print one).
    forged = console.web.post("/console/registration/card.pdf", {"username": "x", "temporary_password": "y"},
                              headers={"Accept": BROWSER_ACCEPT})
    assert forged.status_code == 403
