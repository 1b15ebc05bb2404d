"""Printed results: the race summary, podium sheet and certificates, read back the way a person reads them
(pdftotext for the words, pdftoppm for the page, pdffonts for the embedded fonts)."""
from __future__ import annotations

import json
import re
from datetime import date
from pathlib import Path

import pytest

from chalicelib.domain.results import EventResults, ResultEntry, ResultsBoard
from chalicelib.formats.avatars import identicon_cells
from chalicelib.views.results_pdf import certificates_pdf, podium_pdf, render_document, summary_pdf
from tests.unit.pdf_helpers import embedded_fonts, pdf_pages, pdf_text, pixels_of, words
from tests.unit.race_helpers import Desk
from tests.unit.scenario import Scenario

pytestmark = pytest.mark.unit

PDF = {"Accept": "application/pdf"}  # API Gateway (and Chalice) return binary bodies only to a matching Accept
BIDI_MARKS = dict.fromkeys(map(ord, "\u202a\u202b\u202c\u200e\u200f"))


def _entry(position: int, name: str, colour: str, time: str = "0:08.838", *, avatar: bool = True,
           dnf: bool = False) -> ResultEntry:
    return ResultEntry(position=position, username=name, country_code="SE", colour=colour,
                       avatar_cells=tuple(identicon_cells(name)) if avatar else None,
                       time="DNF" if dnf else time, gap="", best_lap="DNF" if dnf else time,
                       valid_laps=0 if dnf else 5, is_dnf=dnf)


MIXED = ResultsBoard(track_id="1", title="Track 1", ranking="Fastest lap", entries=(
    _entry(1, "Zoë Müller", "#ff8200", "0:08.838"),
    _entry(2, "山田太郎", "#0000ff", "0:09.120"),
    _entry(3, "محمد علي", "#7cfc00", "0:10.004", avatar=False),
    _entry(4, "Łukasz Żółć", "#ff00ff", "1:02.345"),
    _entry(5, "late_starter", "#9e9e9e", dnf=True)))
RESULTS = EventResults(event_id="ev", event_name="Summit Stockholm 2026", event_date=date(2026, 5, 14),
                       country_code="SE", sponsor="Acme Robotics", boards=(MIXED,))


def _plain(text: str) -> str:
    return text.translate(BIDI_MARKS)


def _table_rows(text: str) -> list[list[str]]:
    """The summary's result rows: a position first, then a time (m:ss.mmm) or DNF somewhere in the row."""
    return [row for row in words(_plain(text)) if row[0].isdigit()
            and any(re.fullmatch(r"\d+:\d\d\.\d{3}", w) or w == "DNF" for w in row)]


def test_summary_lists_every_racer_in_order_with_time_in_any_script(tmp_path: Path) -> None:
    pdf = summary_pdf(RESULTS, [MIXED])
    rows = _table_rows(pdf_text(pdf, tmp_path))
    assert [row[0] for row in rows] == ["1", "2", "3", "4", "5"]
    assert "Zoë Müller" in " ".join(rows[0]) and "0:08.838" in rows[0]
    assert "山田太郎" in rows[1] and "0:09.120" in rows[1]
    assert "محمد" in rows[2] and "علي" in rows[2] and "0:10.004" in rows[2]
    assert "Łukasz Żółć" in " ".join(rows[3]) and "1:02.345" in rows[3]
    assert "late_starter" in rows[4] and "DNF" in rows[4]
    fonts = embedded_fonts(pdf, tmp_path)
    assert "+NotoSans " in fonts and "+NotoSansArabic" in fonts and "+DroidSansFallback" in fonts


def test_summary_page_shows_each_racers_colour_and_avatar(tmp_path: Path) -> None:
    [page] = pdf_pages(summary_pdf(RESULTS, [MIXED]), tmp_path)
    for colour in ("#ff8200", "#0000ff", "#7cfc00", "#ff00ff"):
        assert pixels_of(page, colour) > 20, colour  # the colour stripe and the identicon/disc
    assert page.size == (414, 585)  # A4 portrait at 50 dpi


def test_latin_only_results_embed_no_fallback_fonts(tmp_path: Path) -> None:
    latin = MIXED.model_copy(update={"entries": (MIXED.entries[0], MIXED.entries[3])})
    fonts = embedded_fonts(summary_pdf(RESULTS, [latin]), tmp_path)
    assert "+NotoSans " in fonts and "Arabic" not in fonts and "Droid" not in fonts


def test_podium_sheet_puts_the_top_three_on_their_steps(tmp_path: Path) -> None:
    pdf = podium_pdf(RESULTS, [MIXED])
    text = _plain(pdf_text(pdf, tmp_path))
    for needle in ("1st", "2nd", "3rd", "Zoë Müller", "山田太郎", "0:08.838", "0:09.120", "0:10.004"):
        assert needle in text, needle
    assert "Łukasz" not in text  # 4th is not on the podium
    [page] = pdf_pages(pdf, tmp_path)
    assert page.size[0] > page.size[1]  # landscape
    assert pixels_of(page, "#d4af37") > 1000  # the gold step


def test_one_certificate_per_racer_with_their_place(tmp_path: Path) -> None:
    pdf = certificates_pdf(RESULTS, [MIXED])
    pages = pdf_pages(pdf, tmp_path)
    assert len(pages) == 5
    text = _plain(pdf_text(pdf, tmp_path))
    certificates = text.split("\f")
    assert "Zoë Müller" in certificates[0] and "finished 1st of 5" in certificates[0]
    assert "0:08.838" in certificates[0]
    assert "محمد علي" in certificates[2] and "finished 3rd of 5" in certificates[2]
    assert "late_starter" in certificates[4] and "took part in" in certificates[4] and "DNF" not in certificates[4]
    assert pixels_of(pages[0], "#ff8200") > 2000  # the frame in the racer's colour


def test_unknown_document_or_board_is_a_clear_error() -> None:
    from chalicelib.core.errors import InvalidInput

    with pytest.raises(InvalidInput, match="summary.pdf"):
        render_document(RESULTS, "secrets.pdf", None)
    with pytest.raises(InvalidInput, match="no board"):
        render_document(RESULTS, "podium.pdf", "9")


def test_staff_download_the_event_results_through_the_api(desk: Desk, scenario: Scenario, tmp_path: Path) -> None:
    eid = scenario.add_racers("lea", "max", "kim").add_event(name="Tokyo 東京 Cup").event_id
    scenario.submitted_race("lea", [9_120, 8_838])
    scenario.submitted_race("max", [10_004])
    scenario.submitted_race("kim", [12_500, 11_000])

    reply = desk.call("GET", f"/api/events/{eid}/results/summary.pdf", headers=PDF)
    assert reply.status_code == 200, reply.body
    assert reply.headers["Content-Type"] == "application/pdf"
    assert "attachment" in reply.headers["Content-Disposition"]
    text = pdf_text(reply.body, tmp_path)
    assert "Tokyo 東京 Cup" in text
    rows = _table_rows(text)
    # position, racer, result (these racers gave no country)
    assert [(r[0], r[1], r[2]) for r in rows] == [("1", "lea", "0:08.838"), ("2", "max", "0:10.004"),
                                                  ("3", "kim", "0:11.000")]

    certificates = desk.call("GET", f"/api/events/{eid}/results/certificates.pdf?track=1", headers=PDF)
    assert certificates.status_code == 200
    pages = pdf_text(certificates.body, tmp_path).split("\f")
    assert [p for p in pages if p.strip()] == pages[:3]  # one page per racer
    assert "max" in pages[1] and "finished 2nd of 3" in pages[1] and "0:10.004" in pages[1]

    desk.token("racer_z", "racer")
    assert desk.call("GET", f"/api/events/{eid}/results/summary.pdf", as_user="racer_z").status_code == 403
    bad = desk.call("GET", f"/api/events/{eid}/results/everything.zip")
    assert bad.status_code == 400 and "summary.pdf" in json.loads(bad.body)["error"]["message"]
    assert desk.call("GET", f"/api/events/{eid}/results/podium.pdf?track=7").status_code == 400
    assert desk.call("GET", "/api/events/nope/results/podium.pdf").status_code == 404
