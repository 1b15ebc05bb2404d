"""An event's logo as uploaded (hostile bytes) → a small image drem can show on every screen.

Only raster formats Pillow decodes are taken (PNG, JPEG, WebP, GIF); SVG is refused because an SVG can carry script
and links. The size is checked before decoding (Pillow reads the header only), so a tiny file that claims a huge
canvas (a decompression bomb) is refused without being expanded. The image is then drawn again from its pixels: its
transparent margin cropped, scaled to fit the board's logo box, metadata and trailing bytes dropped, saved as PNG (or
WebP when a PNG would be too big for the one database item that holds it). What leaves this module is always a file
drem wrote itself.
"""
from __future__ import annotations

import hashlib
import io
import warnings
from dataclasses import dataclass

from PIL import Image, ImageOps, UnidentifiedImageError

from chalicelib.core.errors import InvalidInput

MAX_UPLOAD_BYTES = 2 * 1024 * 1024
MAX_SOURCE_PIXELS = 25_000_000  # a 25-megapixel photo is the most a logo file plausibly is
BOX = (960, 360)  # the largest the big screen draws it (CSS px × 2 for sharp edges), aspect kept
MAX_STORED_BYTES = 300 * 1024  # one DynamoDB item holds at most 400 KB
ACCEPTED_FORMATS = ("PNG", "JPEG", "WEBP", "GIF")  # Pillow's JPEG opener also reads MPO (some phones' JPEGs)
FIELD = "logo"
CONTENT_TYPES = ("image/png", "image/webp")  # what a stored logo is (the app serves them as bytes)
UPLOAD_TYPES = ("image/png", "image/jpeg", "image/webp", "image/gif")  # what `PUT /api/events/{id}/logo` takes


@dataclass(frozen=True)
class LogoImage:
    data: bytes
    content_type: str
    width: int
    height: int

    @property
    def version(self) -> str:
        """Names these exact bytes: the logo's address changes with it, so browsers may cache it for good."""
        return hashlib.sha256(self.data).hexdigest()[:16]


def normalised_logo(upload: bytes) -> LogoImage:
    """The logo drem stores for `upload`, or InvalidInput (field "logo") with a sentence for the organiser."""
    if not upload:
        raise InvalidInput("Choose an image file for the logo.", field=FIELD)
    if len(upload) > MAX_UPLOAD_BYTES:
        raise InvalidInput(f"The logo file is {len(upload) / 1024 / 1024:.1f} MB; the most is "
                           f"{MAX_UPLOAD_BYTES // 1024 // 1024} MB. Save it smaller (a logo needs no more than "
                           f"{BOX[0]}×{BOX[1]} pixels).", field=FIELD)
    if upload.lstrip()[:5].lower() in (b"<?xml", b"<svg ") or b"<svg" in upload[:1024].lower():
        raise InvalidInput("SVG logos are not accepted (an SVG can carry scripts): export it as PNG.", field=FIELD)
    source = _opened(upload)
    try:
        return _redrawn(source)
    finally:
        source.close()


def _opened(upload: bytes) -> Image.Image:
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", Image.DecompressionBombWarning)
            image = Image.open(io.BytesIO(upload), formats=list(ACCEPTED_FORMATS))
    except (UnidentifiedImageError, Image.DecompressionBombWarning, Image.DecompressionBombError, OSError,
            ValueError, SyntaxError):
        raise InvalidInput("This file is not a PNG, JPEG, WebP or GIF image drem can read. Export the logo as PNG "
                           "and upload that.", field=FIELD) from None
    width, height = image.size
    if width * height > MAX_SOURCE_PIXELS:
        image.close()
        raise InvalidInput(f"The logo is {width}×{height} pixels; the most is {MAX_SOURCE_PIXELS // 1_000_000} "
                           f"megapixels. Save it smaller.", field=FIELD)
    if image.format in ("JPEG", "MPO"):
        image.draft("RGB", (BOX[0] * 2, BOX[1] * 2))  # decode a big photo at a fraction of its size
    return image


def _redrawn(source: Image.Image) -> LogoImage:
    try:
        source.seek(0)  # an animated GIF or WebP shows its first frame: a board logo does not move
        upright = ImageOps.exif_transpose(source)
        pixels = upright.convert("RGBA")
    except (OSError, ValueError, SyntaxError, Image.DecompressionBombError):
        raise InvalidInput("The logo image is damaged (its pixels could not be read). Export it again as PNG.",
                           field=FIELD) from None
    drawn = pixels.getchannel("A").getbbox()
    if drawn is None:
        raise InvalidInput("Every pixel of this logo is transparent: there is nothing to show.", field=FIELD)
    # Logos often come with a wide transparent margin; cropped, the logo itself gets the board's whole logo box.
    pixels = pixels.crop(drawn)
    pixels.thumbnail(BOX, Image.Resampling.LANCZOS)
    if pixels.getchannel("A").getextrema()[0] == 255:  # fully opaque: no need to store an alpha channel
        pixels = pixels.convert("RGB")
    data, content_type = _encoded(pixels, "PNG", optimize=True), "image/png"
    if len(data) > MAX_STORED_BYTES:  # a photo-like logo: WebP keeps it sharp at a fraction of the size
        data, content_type = _encoded(pixels, "WEBP", quality=90, method=4), "image/webp"
    return LogoImage(data=data, content_type=content_type, width=pixels.width, height=pixels.height)


def _encoded(image: Image.Image, image_format: str, **options: object) -> bytes:
    out = io.BytesIO()
    image.save(out, format=image_format, **options)
    return out.getvalue()
