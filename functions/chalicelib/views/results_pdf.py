"""Printed results as PDFs (fpdf2): the organiser's race summary, the podium sheet and per-racer certificates.

Each racer appears with their highlight colour and their identicon (the same cells `avatars.identicon_svg` draws, as
vector squares), or a plain colour disc when they chose no avatar. Every text is a real text run (selectable, found by
pdftotext), in the fonts of `pdf_fonts`. Why fpdf2, and what else was measured: docs/results.md.
"""
from __future__ import annotations

from collections.abc import Iterable, Sequence
from datetime import date
from typing import Any

from fpdf import FPDF

from chalicelib.core.errors import InvalidInput
from chalicelib.domain.results import EventResults, ResultEntry, ResultsBoard
from chalicelib.formats import pdf_fonts
from drem_leaderboard.ranking import COMBINED_TRACK_ID

INK = (33, 33, 33)
MUTED = (110, 110, 110)
RULE = (210, 210, 210)
ZEBRA = (245, 245, 245)
PODIUM_FILL = {1: (212, 175, 55), 2: (192, 192, 192), 3: (205, 127, 50)}
MIN_FONT_PT = 7.0
SUMMARY_ROW_MM = 8.0


def hex_rgb(colour: str) -> tuple[int, int, int]:
    value = colour.lstrip("#")
    if len(value) == 3:
        value = "".join(c * 2 for c in value)
    return int(value[0:2], 16), int(value[2:4], 16), int(value[4:6], 16)


def ordinal(n: int) -> str:
    suffix = "th" if 10 <= n % 100 <= 20 else {1: "st", 2: "nd", 3: "rd"}.get(n % 10, "th")
    return f"{n}{suffix}"


def long_date(day: date) -> str:
    return f"{day.day} {day.strftime('%B %Y')}"


class _Document(FPDF):
    """A4 with drem's fonts and a footer naming the event and the page."""

    def __init__(self, results: EventResults, orientation: str, title: str, texts: Iterable[str], *,
                 page_footer: bool = True) -> None:
        super().__init__(orientation=orientation, unit="mm", format="A4")
        self.results = results
        self.page_footer = page_footer
        self.shaping = False
        self.set_title(f"{title} - {results.event_name}")
        self.set_creator("drem")
        self.set_margins(15, 15, 15)
        self.set_auto_page_break(False)
        pdf_fonts.install(self, [results.event_name, results.sponsor, *texts])
        self.alias_nb_pages()

    def shape_for(self, text: str) -> None:
        """HarfBuzz shaping only for the texts that need it (it is the slowest part of a page)."""
        wanted = pdf_fonts.needs_shaping(text)
        if wanted != self.shaping:
            self.set_text_shaping(wanted)
            self.shaping = wanted

    def cell(self, w: float | None = None, h: float | None = None, text: str = "", *args: Any,
             **kwargs: Any) -> Any:
        self.shape_for(text)
        return super().cell(w, h, text, *args, **kwargs)

    def get_string_width(self, s: str, *args: Any, **kwargs: Any) -> float:
        self.shape_for(s)
        return super().get_string_width(s, *args, **kwargs)

    def footer(self) -> None:
        if not self.page_footer:
            return
        self.set_y(-12)
        self.set_font(pdf_fonts.MAIN, size=8)
        self.set_text_color(*MUTED)
        self.cell(0, 5, f"{self.results.event_name} · page {self.page_no()} of {{nb}}", align="C")


def _texts(boards: Iterable[ResultsBoard]) -> list[str]:
    return [text for board in boards for text in (board.title, *(e.username for e in board.entries))]


def fit_text(pdf: FPDF, text: str, width: float, size: float, style: str = "") -> None:
    """Set the font so `text` fits `width` mm: shrink down to MIN_FONT_PT, then cut the text with an ellipsis."""
    pdf.set_font(pdf_fonts.MAIN, style=style, size=size)
    while pdf.get_string_width(text) > width and size > MIN_FONT_PT:
        size = max(MIN_FONT_PT, size - 1)
        pdf.set_font(pdf_fonts.MAIN, style=style, size=size)


def _fitted(pdf: FPDF, text: str, width: float) -> str:
    if pdf.get_string_width(text) <= width:
        return text
    while text and pdf.get_string_width(text + "…") > width:
        text = text[:-1]
    return text + "…"


def draw_avatar(pdf: FPDF, entry: ResultEntry, x: float, y: float, size: float) -> None:
    """The racer's identicon (5×5 mirrored cells on white, framed) or, without one, a disc in their colour."""
    pdf.set_fill_color(*hex_rgb(entry.colour))
    if entry.avatar_cells is None:
        pdf.ellipse(x, y, size, size, style="F")
        return
    pdf.set_draw_color(*RULE)
    pdf.set_line_width(0.2)
    pdf.set_fill_color(255, 255, 255)
    pdf.rect(x, y, size, size, style="DF")
    cell = size / 6  # identicon: 5 cells plus half a cell of margin on each side
    pdf.set_fill_color(*hex_rgb(entry.colour))
    for column, row in entry.avatar_cells:
        pdf.rect(x + cell * (0.5 + column), y + cell * (0.5 + row), cell, cell, style="F")


# --- race summary --------------------------------------------------------------------------------------------------

_COLUMNS: tuple[tuple[str, float, str], ...] = (
    ("Pos", 12, "R"), ("", 9, "C"), ("Racer", 62, "L"), ("Country", 17, "C"), ("Result", 24, "R"),
    ("Gap", 20, "R"), ("Fastest lap", 24, "R"), ("Laps", 12, "R"))


def summary_pdf(results: EventResults, boards: Sequence[ResultsBoard]) -> bytes:
    pdf = _Document(results, "portrait", "Race summary", _texts(boards))
    pdf.add_page()
    _summary_heading(pdf, results)
    for board in boards:
        if pdf.get_y() + 30 > pdf.h - 20:
            pdf.add_page()
        _board_heading(pdf, board)
        _table_header(pdf, board)
        if not board.entries:
            pdf.set_font(pdf_fonts.MAIN, size=10)
            pdf.cell(0, SUMMARY_ROW_MM, "No submitted races yet.", new_x="LMARGIN", new_y="NEXT")
        for index, entry in enumerate(board.entries):
            if pdf.get_y() + SUMMARY_ROW_MM > pdf.h - 18:
                pdf.add_page()
                _table_header(pdf, board)
            _summary_row(pdf, entry, index)
        pdf.ln(6)
    return bytes(pdf.output())


def _summary_heading(pdf: FPDF, results: EventResults) -> None:
    pdf.set_text_color(*INK)
    fit_text(pdf, results.event_name, pdf.epw, 22, "B")
    pdf.cell(0, 11, _fitted(pdf, results.event_name, pdf.epw), new_x="LMARGIN", new_y="NEXT")
    pdf.set_font(pdf_fonts.MAIN, size=10)
    pdf.set_text_color(*MUTED)
    details = [long_date(results.event_date), results.country_code]
    if results.sponsor:
        details.append(f"Sponsored by {results.sponsor}")
    pdf.cell(0, 6, _fitted(pdf, " · ".join(details), pdf.epw), new_x="LMARGIN", new_y="NEXT")
    pdf.ln(4)


def _board_heading(pdf: FPDF, board: ResultsBoard) -> None:
    pdf.set_text_color(*INK)
    fit_text(pdf, board.title, pdf.epw, 14, "B")
    pdf.cell(0, 8, _fitted(pdf, board.title, pdf.epw), new_x="LMARGIN", new_y="NEXT")
    pdf.set_font(pdf_fonts.MAIN, size=9)
    pdf.set_text_color(*MUTED)
    pdf.cell(0, 5, f"Ranked by: {board.ranking} · {len(board.entries)} racers", new_x="LMARGIN", new_y="NEXT")
    pdf.ln(1)


def _table_header(pdf: FPDF, board: ResultsBoard) -> None:
    pdf.set_font(pdf_fonts.MAIN, style="B", size=9)
    pdf.set_text_color(*INK)
    pdf.set_draw_color(*RULE)
    for label, width, align in _COLUMNS:
        pdf.cell(width, 7, label, border="B", align=align)
    pdf.ln(7)


def _summary_row(pdf: FPDF, entry: ResultEntry, index: int) -> None:
    x, y = pdf.l_margin, pdf.get_y()
    if index % 2:
        pdf.set_fill_color(*ZEBRA)
        pdf.rect(x, y, sum(w for _, w, _ in _COLUMNS), SUMMARY_ROW_MM, style="F")
    pdf.set_fill_color(*hex_rgb(entry.colour))
    pdf.rect(x, y, 1.5, SUMMARY_ROW_MM, style="F")  # the racer's colour, as on the big screen
    pdf.set_text_color(*INK)
    values = [str(entry.position), "", entry.username, entry.country_code, entry.time, entry.gap, entry.best_lap,
              str(entry.valid_laps)]
    for (label, width, align), value in zip(_COLUMNS, values, strict=True):
        if label == "":
            draw_avatar(pdf, entry, pdf.get_x() + (width - 6) / 2, y + 1, 6)
            pdf.cell(width, SUMMARY_ROW_MM, "")
            continue
        bold = label in ("Pos", "Result")
        if label == "Racer":
            fit_text(pdf, value, width - 2, 10, "B" if entry.position <= 3 and not entry.is_dnf else "")
            value = _fitted(pdf, value, width - 2)
        else:
            pdf.set_font(pdf_fonts.MAIN, style="B" if bold else "", size=10)
        pdf.cell(width, SUMMARY_ROW_MM, value, align=align)
    pdf.set_xy(x, y + SUMMARY_ROW_MM)


# --- podium sheet --------------------------------------------------------------------------------------------------

_PODIUM_LAYOUT = ((2, 45.0), (1, 62.0), (3, 32.0))  # (position, step height mm), left to right


def podium_pdf(results: EventResults, boards: Sequence[ResultsBoard]) -> bytes:
    pdf = _Document(results, "landscape", "Podium", _texts(boards))
    for board in boards:
        pdf.add_page()
        pdf.set_text_color(*INK)
        fit_text(pdf, results.event_name, pdf.epw, 24, "B")
        pdf.cell(0, 12, _fitted(pdf, results.event_name, pdf.epw), align="C", new_x="LMARGIN", new_y="NEXT")
        pdf.set_font(pdf_fonts.MAIN, size=13)
        pdf.set_text_color(*MUTED)
        pdf.cell(0, 7, _fitted(pdf, f"{board.title} · {board.ranking}", pdf.epw), align="C",
                 new_x="LMARGIN", new_y="NEXT")
        podium = {e.position: e for e in board.podium}
        if not podium:
            pdf.ln(30)
            pdf.set_font(pdf_fonts.MAIN, size=16)
            pdf.cell(0, 10, "No results yet.", align="C")
            continue
        _podium_steps(pdf, podium)
    return bytes(pdf.output())


def _podium_steps(pdf: FPDF, podium: dict[int, ResultEntry]) -> None:
    step_width, base_y = 80.0, pdf.h - 28
    left = (pdf.w - step_width * 3) / 2
    for slot, (position, height) in enumerate(_PODIUM_LAYOUT):
        x = left + slot * step_width
        top = base_y - height
        pdf.set_fill_color(*PODIUM_FILL[position])
        pdf.rect(x + 2, top, step_width - 4, height, style="F")
        pdf.set_text_color(255, 255, 255)
        pdf.set_font(pdf_fonts.MAIN, style="B", size=40)
        pdf.set_xy(x, top + 4)
        pdf.cell(step_width, 18, ordinal(position), align="C")
        entry = podium.get(position)
        if entry is None:
            continue
        draw_avatar(pdf, entry, x + (step_width - 24) / 2, top - 62, 24)
        pdf.set_text_color(*INK)
        fit_text(pdf, entry.username, step_width - 6, 18, "B")
        pdf.set_xy(x, top - 35)
        pdf.cell(step_width, 10, _fitted(pdf, entry.username, step_width - 6), align="C")
        pdf.set_font(pdf_fonts.MAIN, size=10)
        pdf.set_text_color(*MUTED)
        pdf.set_xy(x, top - 25)
        pdf.cell(step_width, 6, entry.country_code, align="C")
        pdf.set_font(pdf_fonts.MAIN, style="B", size=20)
        pdf.set_text_color(*INK)
        pdf.set_xy(x, top - 18)
        pdf.cell(step_width, 12, entry.time, align="C")


# --- certificates --------------------------------------------------------------------------------------------------


def certificates_pdf(results: EventResults, boards: Sequence[ResultsBoard]) -> bytes:
    pdf = _Document(results, "landscape", "Certificates", _texts(boards), page_footer=False)
    for board in boards:
        for entry in board.entries:
            pdf.add_page()
            _certificate(pdf, results, board, entry)
    if pdf.page_no() == 0:
        pdf.add_page()
        pdf.set_font(pdf_fonts.MAIN, size=16)
        pdf.cell(0, 10, "No results yet.", align="C")
    return bytes(pdf.output())


def _certificate(pdf: FPDF, results: EventResults, board: ResultsBoard, entry: ResultEntry) -> None:
    colour = hex_rgb(entry.colour)
    pdf.set_draw_color(*colour)
    pdf.set_line_width(3)
    pdf.rect(10, 10, pdf.w - 20, pdf.h - 20)
    pdf.set_line_width(0.5)
    pdf.rect(15, 15, pdf.w - 30, pdf.h - 30)
    draw_avatar(pdf, entry, (pdf.w - 36) / 2, 24, 36)
    pdf.set_text_color(*MUTED)
    pdf.set_font(pdf_fonts.MAIN, size=14)
    pdf.set_xy(20, 64)
    pdf.cell(pdf.w - 40, 8, "Certificate of achievement", align="C", new_x="LMARGIN", new_y="NEXT")
    pdf.set_text_color(*INK)
    fit_text(pdf, entry.username, pdf.w - 50, 40, "B")
    pdf.set_x(20)
    pdf.cell(pdf.w - 40, 20, _fitted(pdf, entry.username, pdf.w - 50), align="C", new_x="LMARGIN", new_y="NEXT")
    pdf.set_font(pdf_fonts.MAIN, size=16)
    if entry.is_dnf:
        placing = "took part in"
    else:
        placing = f"finished {ordinal(entry.position)} of {len(board.entries)} in"
    for line in (placing, results.event_name, f"{board.title} · {long_date(results.event_date)}"):
        if line == results.event_name:
            fit_text(pdf, line, pdf.w - 50, 22, "B")
        pdf.set_x(20)
        pdf.cell(pdf.w - 40, 11, _fitted(pdf, line, pdf.w - 50), align="C", new_x="LMARGIN", new_y="NEXT")
        pdf.set_font(pdf_fonts.MAIN, size=16)
    if not entry.is_dnf:
        pdf.ln(3)
        pdf.set_font(pdf_fonts.MAIN, style="B", size=18)
        pdf.set_x(20)
        pdf.cell(pdf.w - 40, 10, f"{board.ranking}: {entry.time}", align="C", new_x="LMARGIN", new_y="NEXT")
        if entry.best_lap != entry.time:
            pdf.set_font(pdf_fonts.MAIN, size=13)
            pdf.set_x(20)
            pdf.cell(pdf.w - 40, 8, f"Fastest lap: {entry.best_lap} · {entry.valid_laps} valid laps", align="C")
    if results.sponsor:
        pdf.set_font(pdf_fonts.MAIN, size=10)
        pdf.set_text_color(*MUTED)
        pdf.set_xy(20, pdf.h - 30)
        pdf.cell(pdf.w - 40, 6, _fitted(pdf, f"Sponsored by {results.sponsor}", pdf.w - 50), align="C")


# --- which document, which boards ------------------------------------------------------------------------------------

DOCUMENTS = {"summary.pdf": summary_pdf, "podium.pdf": podium_pdf, "certificates.pdf": certificates_pdf}


def render_document(results: EventResults, file_name: str, track: str | None) -> bytes:
    """One of DOCUMENTS for one board (`track`), or for all of them. Certificates for all boards leave out the
    combined board (a racer on two tracks would otherwise get the same achievement twice)."""
    render = DOCUMENTS.get(file_name)
    if render is None:
        raise InvalidInput(f"Download one of {', '.join(DOCUMENTS)}.", field="file_name")
    if track:
        board = results.board(track)
        if board is None:
            raise InvalidInput(f"This event has no board {track!r}.", field="track")
        boards: list[ResultsBoard] = [board]
    else:
        boards = [b for b in results.boards
                  if not (render is certificates_pdf and b.track_id == COMBINED_TRACK_ID)]
    return render(results, boards)
