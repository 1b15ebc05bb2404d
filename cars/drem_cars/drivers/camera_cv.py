"""Part: a real camera through OpenCV (`cv2.VideoCapture`), grayscale 160x120 frames stamped on capture.

Capture runs on its own thread (a USB camera blocks for a frame period); `run()` hands out the latest frame and its
capture time, so the safety part sees a stale frame when the camera stalls.
"""
from __future__ import annotations

import threading
import time
from typing import Any

import numpy as np


class OpenCvCamera:
    def __init__(self, source: int | str = 0, width: int = 160, height: int = 120, fps: int = 15) -> None:
        import cv2

        self._cv2 = cv2
        self.capture = cv2.VideoCapture(source)
        if not self.capture.isOpened():
            raise RuntimeError(f"cannot open camera {source!r}")
        self.capture.set(cv2.CAP_PROP_FPS, fps)
        self.size = (width, height)
        self._frame: np.ndarray | None = None
        self._time: float | None = None
        self._running = True
        self._thread = threading.Thread(target=self._update, name="camera", daemon=True)
        self._thread.start()

    def _update(self) -> None:
        cv2 = self._cv2
        while self._running:
            ok, frame = self.capture.read()
            if not ok:
                time.sleep(0.01)
                continue
            gray = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY) if frame.ndim == 3 else frame
            self._frame = cv2.resize(gray, self.size, interpolation=cv2.INTER_AREA)
            self._time = time.monotonic()

    def run(self) -> tuple[Any, float | None]:
        return self._frame, self._time

    def shutdown(self) -> None:
        self._running = False
        self._thread.join(1.0)
        self.capture.release()
