"""The fonts every drem PDF embeds, so a racer's name prints in whatever script they wrote it.

Noto Sans (Latin, Greek, Cyrillic) is the main face; Noto Sans Arabic, Droid Sans Fallback (Chinese, Japanese) and
Nanum Gothic (Korean Hangul, which Droid Sans Fallback lacks: 김민준 printed blank) are fallbacks fpdf2 switches to per
glyph. Text is shaped with HarfBuzz (uharfbuzz), which joins Arabic letters and orders
right-to-left runs. Shaping costs about 5 ms a line, so it is switched on only for the texts that need it (see
`needs_shaping`); Latin and CJK print the same without it. The fallbacks are large (the CJK face is 4 MB), so they are added only when the document's text
has a character Noto Sans lacks.

The files come from Debian packages installed at setup (`make install`: fonts-noto-core, fonts-droid-fallback,
fonts-nanum) and,
in the Lambda bundle, from the `drem_fonts/` folder `drem build` copies them to. Nothing is committed to the repo.
"""
from __future__ import annotations

import os
import unicodedata
from collections.abc import Iterable
from functools import lru_cache
from pathlib import Path

from fontTools.ttLib import TTFont

from chalicelib.core.errors import ServiceUnavailable

MAIN = "noto"
FONT_FILES = {
    (MAIN, ""): "NotoSans-Regular.ttf",
    (MAIN, "B"): "NotoSans-Bold.ttf",
    ("noto-arabic", ""): "NotoSansArabic-Regular.ttf",
    ("noto-arabic", "B"): "NotoSansArabic-Bold.ttf",
    ("droid-cjk", ""): "DroidSansFallbackFull.ttf",
    ("nanum-kr", ""): "NanumGothic.ttf",
}
# In this order: a Chinese or Japanese character takes Droid's glyph even though Nanum has Hanja too.
FALLBACKS = ("noto-arabic", "droid-cjk", "nanum-kr")
# Lambda bundle (vendor/ lands at the bundle root), a local `drem build`, then the Debian packages.
_BUNDLE_ROOT = Path(__file__).resolve().parents[2]
SEARCH_DIRS = (_BUNDLE_ROOT / "drem_fonts", _BUNDLE_ROOT / "vendor" / "drem_fonts",
               Path("/usr/share/fonts/truetype/noto"), Path("/usr/share/fonts/truetype/droid"),
               Path("/usr/share/fonts/truetype/nanum"))


def search_dirs() -> tuple[Path, ...]:
    extra = os.environ.get("DREM_FONT_DIR")
    return ((Path(extra),) if extra else ()) + SEARCH_DIRS


@lru_cache(maxsize=None)
def font_path(file_name: str) -> Path:
    for folder in search_dirs():
        candidate = folder / file_name
        if candidate.is_file():
            return candidate
    raise ServiceUnavailable(f"The font {file_name} is not installed; run `make install` (Debian packages "
                       "fonts-noto-core, fonts-droid-fallback and fonts-nanum).")


@lru_cache(maxsize=1)
def main_coverage() -> frozenset[int]:
    with TTFont(font_path(FONT_FILES[(MAIN, "")]), lazy=True) as font:
        return frozenset(font.getBestCmap())


def needs_fallback(texts: Iterable[str]) -> bool:
    covered = main_coverage()
    return any(ord(ch) not in covered for text in texts for ch in text if not ch.isspace())


# Scripts whose letters change shape or order: Hebrew, Arabic, Syriac, Thaana, N'Ko (0590-08FF), the Indic scripts,
# Sinhala, Thai, Lao, Tibetan, Myanmar (0900-109F), Khmer (1780-17FF) and the Hebrew/Arabic presentation forms.
_COMPLEX_RANGES = ((0x0590, 0x08FF), (0x0900, 0x109F), (0x1780, 0x17FF), (0xFB1D, 0xFEFF))


def needs_shaping(text: str) -> bool:
    return any(any(low <= ord(ch) <= high for low, high in _COMPLEX_RANGES)
               or unicodedata.bidirectional(ch) in ("R", "AL") for ch in text if ord(ch) >= 0x0590)


def install(pdf: object, texts: Iterable[str]) -> None:
    """Add drem's fonts to an `fpdf.FPDF`, with the fallbacks only when `texts` needs them."""
    wanted = [key for key in FONT_FILES if key[0] == MAIN]
    if needs_fallback(texts):
        wanted = list(FONT_FILES)
    for family, style in wanted:
        pdf.add_font(family, style=style, fname=str(font_path(FONT_FILES[(family, style)])))  # type: ignore[attr-defined]
    pdf.set_font(MAIN, size=12)  # type: ignore[attr-defined]
    if len(wanted) > 2:
        pdf.set_fallback_fonts(list(FALLBACKS), exact_match=False)  # type: ignore[attr-defined]
