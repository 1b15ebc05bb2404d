"""Part: a real camera through OpenCV (`cv2.VideoCapture`), grayscale 160x120 frames stamped on capture.

The source is a camera index (`0` = /dev/video0), a video file or a stream URL. Capture runs on its own thread (a USB
camera blocks for a frame period); `run()` hands out the latest frame and its capture time, so the safety part sees a
stale frame when the camera stalls. A video file is played at its own frame rate, as a camera would deliver it, and
stops at its end: from then on the last frame only grows older, so the safety part stops the car.
"""
from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import Any

import numpy as np


class CameraUnavailable(RuntimeError):
    """The camera, file or stream cannot be opened; the message says which."""


def camera_source(text: str) -> int | str:
    """`--camera` value → what cv2.VideoCapture takes: digits are a device index, anything else a path or URL."""
    return int(text) if text.strip().isdigit() else text


class OpenCvCamera:
    def __init__(self, source: int | str = 0, width: int = 160, height: int = 120, fps: int = 15) -> None:
        import cv2

        self._cv2 = cv2
        if isinstance(source, str) and "://" not in source and not Path(source).is_file():
            raise CameraUnavailable(f"cannot open camera {source!r}: no such file")
        self.capture = cv2.VideoCapture(source)
        if not self.capture.isOpened():
            self.capture.release()
            what = f"/dev/video{source}" if isinstance(source, int) else source
            raise CameraUnavailable(f"cannot open camera {what!r}: no such device, or it is in use")
        self.from_file = isinstance(source, str) and Path(source).is_file()
        file_fps = self.capture.get(cv2.CAP_PROP_FPS) if self.from_file else 0.0
        self.frame_period_s = 1.0 / (file_fps if file_fps and file_fps > 0 else fps)
        if not self.from_file:
            self.capture.set(cv2.CAP_PROP_FPS, fps)
        self.size = (width, height)
        self.frames_read = 0
        self.ended = False
        self._latest: tuple[np.ndarray | None, float | None] = (None, None)  # swapped whole: frame and its time
        self._running = True
        self._thread = threading.Thread(target=self._update, name="camera", daemon=True)
        self._thread.start()

    def _update(self) -> None:
        cv2 = self._cv2
        next_due = time.monotonic()
        while self._running:
            if self.from_file:  # a file reads in microseconds: deliver it at its frame rate, like a camera
                delay = next_due - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
                next_due += self.frame_period_s
            ok, frame = self.capture.read()
            if not ok:
                if self.from_file:
                    self.ended = True
                    return
                time.sleep(0.01)
                continue
            gray = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY) if frame.ndim == 3 else frame
            if gray.shape[:2] != (self.size[1], self.size[0]):
                gray = cv2.resize(gray, self.size, interpolation=cv2.INTER_AREA)
            self._latest = (gray, time.monotonic())
            self.frames_read += 1

    def run(self) -> tuple[Any, float | None]:
        return self._latest

    def shutdown(self) -> None:
        self._running = False
        self._thread.join(1.0)
        self.capture.release()
