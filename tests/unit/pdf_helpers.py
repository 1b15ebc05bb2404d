"""Reading a PDF the way a person does: poppler's pdftotext (the words on the page), pdftoppm (the page as an image)
and pdffonts (which fonts are embedded). poppler-utils is installed by `make test` (TEST_DEBS)."""
from __future__ import annotations

import subprocess
from pathlib import Path

from PIL import Image


def _write(pdf: bytes, folder: Path, name: str = "doc.pdf") -> Path:
    assert pdf.startswith(b"%PDF-"), pdf[:40]
    path = folder / name
    path.write_bytes(pdf)
    return path


def pdf_text(pdf: bytes, folder: Path) -> str:
    path = _write(pdf, folder)
    return subprocess.run(["pdftotext", "-layout", "-enc", "UTF-8", str(path), "-"], check=True,
                          capture_output=True, text=True).stdout


def pdf_pages(pdf: bytes, folder: Path, dpi: int = 50) -> list[Image.Image]:
    path = _write(pdf, folder)
    prefix = folder / "page"
    subprocess.run(["pdftoppm", "-r", str(dpi), "-png", str(path), str(prefix)], check=True, capture_output=True)
    return [Image.open(p).convert("RGB") for p in sorted(folder.glob("page*.png"))]


def embedded_fonts(pdf: bytes, folder: Path) -> str:
    path = _write(pdf, folder)
    return subprocess.run(["pdffonts", str(path)], check=True, capture_output=True, text=True).stdout


def pixels_of(image: Image.Image, colour: str) -> int:
    """How many pixels are exactly `colour` (#rrggbb): filled shapes keep their colour inside the antialiased edge."""
    rgb = tuple(int(colour.lstrip("#")[i:i + 2], 16) for i in (0, 2, 4))
    return sum(count for count, value in image.getcolors(maxcolors=1 << 24) or [] if value == rgb)


def words(text: str) -> list[list[str]]:
    """The text's non-empty lines split into words (pdftotext -layout keeps a table row on one line)."""
    return [line.split() for line in text.splitlines() if line.strip()]
