"""What the video relay sends: the rate, size and view staff chose, and each frame made a JPEG of that size and view."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from drem_cars.video_sources import SourceFrame

MODEL_VIEW_SIZE = (160, 120)
View = Literal["camera", "model"]


@dataclass(frozen=True)
class VideoSettings:
    fps: float = 15.0
    width: int = 480
    height: int = 360
    view: View = "camera"
    jpeg_quality: int = 75

    @property
    def size(self) -> tuple[int, int]:
        return MODEL_VIEW_SIZE if self.view == "model" else (self.width, self.height)


def parse_size(text: str) -> tuple[int, int]:
    """`480x360` → (480, 360); a clear message for anything else."""
    width, _, height = text.lower().partition("x")
    if not (width.isdigit() and height.isdigit()) or not (16 <= int(width) <= 1920 and 16 <= int(height) <= 1080):
        raise ValueError(f"--video-size {text!r}: give WIDTHxHEIGHT, e.g. 480x360 (16..1920 by 16..1080)")
    return int(width), int(height)


def encode(frame: SourceFrame, settings: VideoSettings) -> bytes:
    """The frame as a JPEG of the chosen size and view; a JPEG from the car already at that size passes as is."""
    import cv2
    import numpy as np

    image = frame.image
    if isinstance(image, bytes):
        if settings.view == "camera":
            return image  # the console already streams the size asked for
        image = cv2.imdecode(np.frombuffer(image, np.uint8), cv2.IMREAD_COLOR)
    if settings.view == "model" and image.ndim == 3:
        image = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    width, height = settings.size
    if image.shape[1] != width or image.shape[0] != height:
        shrink = image.shape[1] > width
        image = cv2.resize(image, (width, height), interpolation=cv2.INTER_AREA if shrink else cv2.INTER_LINEAR)
    ok, jpeg = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, settings.jpeg_quality])
    if not ok:
        raise ValueError("the frame could not be encoded as JPEG")
    return bytes(jpeg.tobytes())
