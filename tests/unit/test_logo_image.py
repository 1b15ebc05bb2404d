"""An uploaded logo is hostile bytes: what drem stores is always an image it drew again itself, small enough for the
board, and anything else is refused with a sentence the organiser can act on."""
from __future__ import annotations

import io
import os

import pytest
from PIL import Image

from chalicelib.core.errors import InvalidInput
from chalicelib.formats.logo_image import BOX, MAX_STORED_BYTES, normalised_logo

pytestmark = pytest.mark.unit


def _saved(image: Image.Image, image_format: str, **options: object) -> bytes:
    out = io.BytesIO()
    image.save(out, format=image_format, **options)
    return out.getvalue()


def _refusal(upload: bytes) -> str:
    with pytest.raises(InvalidInput) as refused:
        normalised_logo(upload)
    assert refused.value.field == "logo"
    return str(refused.value)


def test_a_big_transparent_png_loses_its_margin_fits_the_board_box_and_keeps_its_transparency():
    logo = Image.new("RGBA", (3000, 1000), (0, 0, 0, 0))
    logo.paste((255, 153, 0, 255), (500, 250, 1000, 750))  # two marks with a transparent gap, in a wide margin
    logo.paste((255, 153, 0, 255), (2000, 250, 2500, 750))
    stored = normalised_logo(_saved(logo, "PNG"))

    assert (stored.width, stored.height) == (BOX[0], 240) and stored.content_type == "image/png"  # 2000×500 drawn
    again = Image.open(io.BytesIO(stored.data))
    assert again.mode == "RGBA" and again.getpixel((5, 5)) == (255, 153, 0, 255)
    assert again.getpixel((480, 120))[3] == 0


def test_a_logo_with_nothing_drawn_is_refused():
    assert _refusal(_saved(Image.new("RGBA", (300, 100), (255, 255, 255, 0)), "PNG")) == (
        "Every pixel of this logo is transparent: there is nothing to show.")


def test_a_jpeg_photo_comes_back_as_an_image_drem_wrote_without_the_camera_metadata():
    photo = Image.new("RGB", (400, 200), (20, 90, 200))
    exif = Image.Exif()
    exif[0x010F] = "SpyCam"  # Make
    stored = normalised_logo(_saved(photo, "JPEG", exif=exif) + b"<script>trailing bytes</script>")

    again = Image.open(io.BytesIO(stored.data))
    assert again.format == "PNG" and again.size == (400, 200) and again.mode == "RGB"
    assert b"SpyCam" not in stored.data and b"<script>" not in stored.data
    assert stored.version == normalised_logo(_saved(photo, "JPEG", exif=exif)).version  # same pixels, same address


def test_an_animated_gif_shows_its_first_frame():
    frames = [Image.new("RGB", (120, 60), colour) for colour in ((255, 0, 0), (0, 255, 0))]
    gif = _saved(frames[0], "GIF", save_all=True, append_images=frames[1:], duration=100, loop=0)
    again = Image.open(io.BytesIO(normalised_logo(gif).data))
    assert again.convert("RGB").getpixel((10, 10)) == (255, 0, 0)


def test_a_photo_like_logo_that_would_be_too_big_as_png_is_stored_as_webp_under_the_item_limit():
    noise = Image.frombytes("RGB", (960, 360), os.urandom(960 * 360 * 3))
    stored = normalised_logo(_saved(noise, "PNG"))
    assert stored.content_type == "image/webp" and len(stored.data) <= MAX_STORED_BYTES
    assert Image.open(io.BytesIO(stored.data)).size == (960, 360)


@pytest.mark.parametrize(("upload", "message"), [
    (b"", "Choose an image file for the logo."),
    (b'<?xml version="1.0"?><svg xmlns="http://www.w3.org/2000/svg"><script>alert(1)</script></svg>',
     "SVG logos are not accepted (an SVG can carry scripts): export it as PNG."),
    (b"<svg onload=alert(1)>", "SVG logos are not accepted (an SVG can carry scripts): export it as PNG."),
    (b"%PDF-1.7 not an image at all", "This file is not a PNG, JPEG, WebP or GIF image drem can read. Export the logo "
                                      "as PNG and upload that."),
])
def test_files_that_are_not_raster_images_are_refused_by_name(upload, message):
    assert _refusal(upload) == message


def test_a_file_over_two_megabytes_is_refused_before_it_is_read():
    assert _refusal(b"\x89PNG" + b"\0" * (2 * 1024 * 1024)).startswith("The logo file is 2.0 MB; the most is 2 MB.")


def test_a_tiny_file_claiming_a_huge_canvas_is_refused_without_being_expanded():
    bomb = _saved(Image.new("1", (6000, 6000)), "PNG", optimize=True)  # 36 megapixels in a few kilobytes
    assert len(bomb) < 20_000
    assert _refusal(bomb) == "The logo is 6000×6000 pixels; the most is 25 megapixels. Save it smaller."


def test_a_truncated_png_is_called_damaged():
    whole = _saved(Image.frombytes("RGB", (300, 300), os.urandom(300 * 300 * 3)), "PNG")
    assert _refusal(whole[: len(whole) // 2]) == ("The logo image is damaged (its pixels could not be read). Export it "
                                                   "again as PNG.")
