"""Where a car's camera frames come from, for the video relay (drem_cars.video_relay). Each source keeps only its
latest frame: nothing queues, and reading it never waits for the drive loop.

- `FrameTap`: a vehicle part after the camera (sim car: its rendered frames; DIY car: its OpenCV camera). Its `run`
  only keeps a reference to the frame the loop already has: no copy, no encoding in the control loop.
- `ConsoleCamera`: a stock DeepRacer's camera, read from its console's video route (MJPEG) on the console session
  the driver already holds, on its own thread, only while the relay is wanted.
"""
from __future__ import annotations

import logging
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any, Protocol

log = logging.getLogger("drem_cars.video")


@dataclass(frozen=True)
class SourceFrame:
    image: Any  # a numpy array (grey or BGR), or JPEG bytes straight from the car
    taken_ms: float  # epoch ms the frame was taken (viewers measure glass-to-glass from it)
    number: int


class FrameSource(Protocol):
    def latest(self) -> SourceFrame | None: ...
    def open(self, width: int, height: int) -> None: ...  # the relay is wanted: start delivering frames
    def close(self) -> None: ...


class FrameTap:
    """Vehicle part: inputs [CAMERA_IMAGE]. Holds the newest frame for the relay (latest-frame-wins)."""

    def __init__(self) -> None:
        self._latest: SourceFrame | None = None
        self._count = 0

    def run(self, image: Any) -> None:
        if image is not None:
            self._count += 1
            self._latest = SourceFrame(image, time.time() * 1000, self._count)  # one reference swap: atomic

    def latest(self) -> SourceFrame | None:
        return self._latest

    def open(self, width: int, height: int) -> None: ...

    def close(self) -> None: ...


class ConsoleCamera:
    """Reads the console's MJPEG on a thread while open; `latest` is the newest whole JPEG (passed on as is)."""

    def __init__(self, console: Any, *, retry_s: float = 2.0) -> None:
        self._console = console
        self._retry_s = retry_s
        self._latest: SourceFrame | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._size = (480, 360)
        self.error: str | None = None

    def latest(self) -> SourceFrame | None:
        return self._latest

    def open(self, width: int, height: int) -> None:
        if self._thread is not None and self._thread.is_alive() and not self._stop.is_set():
            return  # already reading (a closed reader still finishing its last read is replaced)
        self._size, self._stop = (width, height), threading.Event()
        self._thread = threading.Thread(target=self._read, args=(self._stop,), name="drem-console-camera",
                                        daemon=True)
        self._thread.start()

    def close(self) -> None:
        self._stop.set()
        self._latest = None

    def _read(self, stop: threading.Event) -> None:
        count = 0
        while not stop.is_set():
            try:
                with self._console.camera_stream(*self._size) as reply:
                    self.error = None
                    for jpeg, _stamp_s in mjpeg_frames(arriving(reply), reply.headers):
                        count += 1
                        # The car's X-Timestamp is its steady clock (web_video_server), not the wall clock: the
                        # time of arrival is the closest wall-clock reading of when it was taken.
                        self._latest = SourceFrame(jpeg, time.time() * 1000, count)
                        if stop.is_set():
                            return
            except Exception as exc:  # noqa: BLE001 - the car away, the login held: say so and try again
                self.error = str(exc)
                log.warning("camera: %s (trying again in %.0f s)", exc, self._retry_s)
            stop.wait(self._retry_s)


def arriving(reply: Any, size: int = 65536) -> Iterator[bytes]:
    """The body as it arrives (read1: whatever is there, not a full buffer), so a frame is not held back waiting
    for the next ones to fill a read."""
    while True:
        chunk = reply.raw.read1(size)
        if not chunk:
            return
        yield chunk


def mjpeg_frames(chunks: Iterator[bytes], headers: Any, max_part: int = 4 << 20) -> Iterator[tuple[bytes, float]]:
    """(JPEG, X-Timestamp or 0) for each part of a `multipart/x-mixed-replace` body, whatever the chunking."""
    content_type = headers.get("Content-Type", "")
    boundary = content_type.partition("boundary=")[2].strip().strip('"')
    if not content_type.startswith("multipart/x-mixed-replace") or not boundary:
        raise ValueError(f"the car's video route answered {content_type or 'no content type'}, not MJPEG")
    marker = b"--" + boundary.removeprefix("--").encode()
    buffer = b""
    for chunk in chunks:
        buffer += chunk
        while True:
            start = buffer.find(marker)
            if start < 0:
                buffer = buffer[-len(marker):]
                break
            head_end = buffer.find(b"\r\n\r\n", start)
            if head_end < 0:
                break
            fields = _part_headers(buffer[start + len(marker):head_end])
            length = int(fields.get("content-length", "-1") or -1)
            if not 0 < length <= max_part:
                raise ValueError("an MJPEG part without a usable Content-Length")
            body_start = head_end + 4
            if len(buffer) < body_start + length:
                break
            yield buffer[body_start:body_start + length], float(fields.get("x-timestamp", "0") or 0)
            buffer = buffer[body_start + length:]
        if len(buffer) > max_part * 2:
            raise ValueError("the car's MJPEG stream is not framed as expected")


def _part_headers(raw: bytes) -> dict[str, str]:
    fields: dict[str, str] = {}
    for line in raw.decode("latin-1").split("\r\n"):
        name, colon, value = line.partition(":")
        if colon:
            fields[name.strip().lower()] = value.strip()
    return fields
