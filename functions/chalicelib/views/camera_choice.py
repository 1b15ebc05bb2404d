"""The camera choices staff have on the console (a car's row on the Cars page, a fleet's row on the Fleets page): the
one list of frame rates and sizes both forms offer, and how a chosen setting reads in a sentence."""
from __future__ import annotations

from chalicelib.domain.devices import CarVideoSettings

# The forms offer these (the API takes any in CarVideoSettings' bounds).
VIDEO_SIZES = ((320, 240), (480, 360), (640, 480))
VIDEO_RATES = (5, 10, 15, 20, 30)
VIEW_LABELS = {"camera": "camera", "model": "model view"}


def video_text(video: CarVideoSettings) -> str:
    """"15 fps, 480×360, camera": the words the form's options use."""
    return f"{video.fps} fps, {video.width}×{video.height}, {VIEW_LABELS[video.view]}"


def cars_text(count: int) -> str:
    return f"{count} car" if count == 1 else f"{count} cars"
