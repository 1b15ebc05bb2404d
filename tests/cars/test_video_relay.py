"""The car side of the car's eye without a server: frames made the size and view staff chose, the console's MJPEG
read whatever its chunking, and the camera tap in the drive loop only keeps the newest frame."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from drem_cars.video_relay import VideoSettings, encode, parse_size
from drem_cars.video_sources import FrameTap, SourceFrame, mjpeg_frames
from tests.cars.fake_deepracer_console import VIDEO_BOUNDARY, camera_frame


def decoded(jpeg: bytes) -> np.ndarray:
    return cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_UNCHANGED)


def test_the_sims_grey_frame_goes_out_at_the_chosen_size() -> None:
    grey = np.random.default_rng(35).integers(0, 255, (120, 160), np.uint8)
    assert decoded(encode(SourceFrame(grey, 0.0, 1), VideoSettings())).shape[:2] == (360, 480)
    assert decoded(encode(SourceFrame(grey, 0.0, 1), VideoSettings(width=320, height=240))).shape[:2] == (240, 320)


def test_the_models_view_is_160x120_grey_whatever_the_camera_gives() -> None:
    jpeg = camera_frame(480, 360, 7)  # what a stock car's console streams
    model_view = decoded(encode(SourceFrame(jpeg, 0.0, 1), VideoSettings(view="model")))
    assert model_view.shape == (120, 160)  # one channel: grey
    assert encode(SourceFrame(jpeg, 0.0, 1), VideoSettings()) is jpeg  # the camera view passes as the car made it


def test_the_consoles_mjpeg_is_read_whatever_its_chunking() -> None:
    frames = [camera_frame(64, 48, n) for n in (1, 2, 3)]
    body = f"--{VIDEO_BOUNDARY}\r\n".encode() + b"".join(
        f"Content-type: image/jpeg\r\nX-Timestamp: {n}.500000\r\nContent-Length: {len(f)}\r\n\r\n".encode() + f
        + f"\r\n--{VIDEO_BOUNDARY}\r\n".encode() for n, f in enumerate(frames))
    headers = {"Content-Type": f"multipart/x-mixed-replace;boundary={VIDEO_BOUNDARY}"}
    one_byte_at_a_time = (body[i:i + 1] for i in range(len(body)))
    assert list(mjpeg_frames(one_byte_at_a_time, headers)) == [(f, n + 0.5) for n, f in enumerate(frames)]
    with pytest.raises(ValueError, match="not MJPEG"):
        list(mjpeg_frames(iter([b"<html>"]), {"Content-Type": "text/html"}))


def test_the_camera_tap_keeps_only_the_newest_frame() -> None:
    tap = FrameTap()
    for value in range(5):
        tap.run(np.full((120, 160), value, np.uint8))
    latest = tap.latest()
    assert latest is not None and latest.number == 5 and int(latest.image[0, 0]) == 4


@pytest.mark.parametrize("text", ["480", "480x", "0x360", "99999x360", "axb"])
def test_a_bad_size_is_refused_in_words(text: str) -> None:
    with pytest.raises(ValueError, match="WIDTHxHEIGHT"):
        parse_size(text)
