"""drem's icon, drawn here rather than shipped as a binary: a violet tile with a white oval race track and a
chequered start line. `ico_bytes()` rasterises it into a 32×32 `.ico` for `/favicon.ico` (browsers and tools that
ask for it by name); static/favicon.svg is the same drawing for `<link rel="icon">`."""
from __future__ import annotations

import struct
from functools import lru_cache

CONTENT_TYPE = "image/x-icon"
SIZE = 32
VIOLET = (0x6B, 0x2B, 0xD9)
WHITE = (0xFF, 0xFF, 0xFF)
BLACK = (0x11, 0x18, 0x27)


def _pixel(x: float, y: float) -> tuple[int, int, int, int]:
    """RGBA at the pixel centre (x, y) of the 32×32 drawing (transparent outside the rounded tile)."""
    corner = 6.0
    dx, dy = max(corner - x, 0, x - (SIZE - corner)), max(corner - y, 0, y - (SIZE - corner))
    if dx * dx + dy * dy > corner * corner:
        return (0, 0, 0, 0)
    # The track: an ellipse ring centred on the tile.
    ex, ey = (x - 16) / 11.5, (y - 16) / 7.5
    ring = ex * ex + ey * ey
    on_track = 0.55 <= ring <= 1.0
    if on_track and 21.5 <= x <= 24.5 and y > 16:  # the start line crosses the bottom straight
        white_square = (int(x) + int(y)) % 2 == 0
        return (*(WHITE if white_square else BLACK), 255)
    return (*(WHITE if on_track else VIOLET), 255)


@lru_cache(maxsize=1)
def ico_bytes() -> bytes:
    """A one-image ICO holding a 32-bit BMP (bottom-up rows, BGRA, then an all-zero AND mask)."""
    rows = []
    for y in reversed(range(SIZE)):
        rows.append(b"".join(bytes((b, g, r, a)) for r, g, b, a in (_pixel(x + .5, y + .5) for x in range(SIZE))))
    mask = bytes(SIZE * SIZE // 8)  # 1 bit per pixel, rows padded to 32 bits: 4 bytes × 32 rows
    bitmap = struct.pack("<IiiHHIIiiII", 40, SIZE, SIZE * 2, 1, 32, 0, len(rows) * SIZE * 4 + len(mask), 0, 0, 0, 0)
    image = bitmap + b"".join(rows) + mask
    header = struct.pack("<HHH", 0, 1, 1)
    entry = struct.pack("<BBBBHHII", SIZE, SIZE, 0, 0, 1, 32, len(image), 6 + 16)
    return header + entry + image
