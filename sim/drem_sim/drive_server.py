"""Manual drive: a person drives the simulator in real time from a browser page and records run folders.

`drem sim drive --track T` serves one page on 127.0.0.1 (never another interface: there is no login). The
simulation runs in its own thread at the camera rate (15 Hz, real time); the page sends the driver's stick
({steering, throttle} in -1..1, + steering = left) and shows the camera frame and lap times. While recording,
every decision is written as a run folder with `drem_sim.runs` (driver "human"), the same format the
demonstrator writes, so `drem train` learns from people exactly as from the demonstrator.

Endpoints: GET / (the page), GET /frame.png, GET /state, POST /control, POST /record {"on": bool}, POST /reset.
POSTs must be JSON (`Content-Type: application/json`): a cross-site form cannot send that without a CORS
preflight, which this server never grants.
"""
from __future__ import annotations

import json
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from drem_sim.env import RaceEnv
from drem_sim.runs import RunRecorder, whole_lap_figures
from drem_sim.tracks import Track

PAGE = Path(__file__).with_name("drive_page.html")
MAX_BODY_BYTES = 1024
FULL_THROTTLE_SPEED = 3.0  # m/s at throttle 1; the car tops out at 4 m/s but nobody can steer that by keyboard
CONTROL_TIMEOUT_S = 1.0  # no control message for this long (tab closed, pad unplugged): the car coasts to a stop

Uploader = Callable[[Path], str]


class ControlError(ValueError):
    """A control message the server will not act on."""


@dataclass(frozen=True)
class Control:
    steering: float = 0.0  # -1 (full right) .. 1 (full left)
    throttle: float = 0.0  # -1 (brake) .. 1 (full speed)

    @classmethod
    def parse(cls, body: Any) -> Control:
        if not isinstance(body, dict) or set(body) - {"steering", "throttle"}:
            raise ControlError('a control is {"steering": -1..1, "throttle": -1..1}')
        values = []
        for key in ("steering", "throttle"):
            value = body.get(key, 0.0)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ControlError(f"{key} must be a number between -1 and 1")
            values.append(max(-1.0, min(1.0, float(value))))
        return cls(*values)


class DriveSession:
    """The car, its latest frame and the optional recorder; stepped by `run()` in real time or `step()` by hand."""

    def __init__(self, track: Track, runs_root: Path, *, uploader: Uploader | None = None, seed: int = 0,
                 control_timeout_s: float = CONTROL_TIMEOUT_S) -> None:
        self.env = RaceEnv(track)
        self.runs_root = Path(runs_root)
        self.uploader = uploader
        self.control_timeout_s = control_timeout_s
        self.seed = seed
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._control = Control()
        self._control_at = time.monotonic()
        self._recorder: RunRecorder | None = None
        # laps, resets, sim time and whole laps when recording began
        self._record_from: tuple[int, int, float, int] = (0, 0, 0.0, 0)
        self.last_run: dict[str, Any] | None = None
        with self._lock:
            self._obs, info = self.env.reset(seed=seed)
            self._params = info["params"]
            self._png = _encode_png(self._obs)

    # ---- driver input ---------------------------------------------------------------------
    def set_control(self, control: Control) -> None:
        with self._lock:
            self._control = control
            self._control_at = time.monotonic()

    def action(self) -> dict[str, float]:
        control = self._control
        if time.monotonic() - self._control_at > self.control_timeout_s:
            control = Control()
        max_steering = self.env.physics.spec.max_steering_deg
        return {"steering_angle": control.steering * max_steering,
                "speed": max(0.0, control.throttle) * FULL_THROTTLE_SPEED}

    # ---- simulation -----------------------------------------------------------------------
    def step(self) -> None:
        with self._lock:
            action, obs, seen = self.action(), self._obs, self._params
            t_ms, lap = round(self.env.sim_time * 1000), self.env.laps
            self._obs, self._params, _, _, _ = self.env.step(action)
            if self._recorder is not None:
                assert obs is not None, "a drive session's env always has a camera"
                self._recorder.add(obs, action, seen, t_ms=t_ms - round(self._record_from[2] * 1000),
                                   lap=lap - self._record_from[0], offtrack=bool(self._params["is_offtrack"]),
                                   car_speed=self.env.car_state()["speed"])
            self._png = _encode_png(self._obs)

    def run(self) -> None:
        """Step at the decision rate until `stop()`; late ticks are dropped, never bunched."""
        period = self.env.step_seconds
        next_tick = time.monotonic()
        while not self._stop.is_set():
            self.step()
            next_tick += period
            delay = next_tick - time.monotonic()
            if delay < 0:
                next_tick = time.monotonic()
            elif self._stop.wait(delay):
                break

    def stop(self) -> None:
        self._stop.set()

    def reset(self) -> None:
        with self._lock:
            finished = self._finish_recording()
            self._obs, info = self.env.reset(seed=self.seed)
            self._params = info["params"]
            self._png = _encode_png(self._obs)
        self._upload(finished)

    # ---- recording ------------------------------------------------------------------------
    def set_recording(self, on: bool) -> dict[str, Any]:
        with self._lock:
            if on and self._recorder is None:
                track = self.env.track
                self._recorder = RunRecorder(
                    self.runs_root, track.track_id, direction="reverse" if track.is_reversed else "forward",
                    driver="human", seed=None, camera=self.env.camera.config if self.env.camera else None,
                    extra={"track_direction": track.direction, "decision_hz": self.env.config.decision_hz})
                self._record_from = (self.env.laps, self.env.resets, self.env.sim_time,
                                     self.env.whole_laps.laps_completed)
            finished = None if on else self._finish_recording()
        self._upload(finished)
        return self.state()

    def _finish_recording(self) -> Path | None:
        """Close the run folder (caller holds the lock); the upload happens after, without the lock."""
        recorder, self._recorder = self._recorder, None
        if recorder is None:
            return None
        _, resets_from, _, whole_from = self._record_from
        run_dir = recorder.close(**whole_lap_figures(self.env, since_lap=whole_from, since_resets=resets_from))
        self.last_run = {"run_dir": str(run_dir), "frames": recorder.frames, "uploaded": None, "upload_error": None}
        return run_dir

    def _upload(self, run_dir: Path | None) -> None:
        # Outside the lock: the car keeps driving while a run is copied to S3.
        if run_dir is None or self.uploader is None or self.last_run is None:
            return
        try:
            self.last_run["uploaded"] = self.uploader(run_dir)
        except Exception as error:  # noqa: BLE001 - the run is safe on disk; say why the copy failed
            self.last_run["upload_error"] = f"{type(error).__name__}: {error}"

    # ---- outputs --------------------------------------------------------------------------
    def frame_png(self) -> bytes:
        with self._lock:
            return self._png

    def state(self) -> dict[str, Any]:
        with self._lock:
            return self._state()

    def _state(self) -> dict[str, Any]:
        env, params = self.env, self._params
        whole = env.whole_laps  # the laps that count (drem_leaderboard.laps): none finished after a put-back
        return {"track": env.track.track_id, "laps": whole.laps_completed,
                "lap_times_s": [round(t, 3) for t in whole.lap_times_s],
                "progress": round(float(params["progress"]), 2), "speed": round(float(params["speed"]), 2),
                "steering_angle": round(float(params["steering_angle"]), 1), "resets": env.resets,
                "steps": env.steps, "sim_time": round(env.sim_time, 2),
                "recording": self._recorder is not None,
                "recorded_frames": self._recorder.frames if self._recorder is not None else 0,
                "last_run": self.last_run}


def _encode_png(frame: np.ndarray | None) -> bytes:
    assert frame is not None, "a drive session's env always has a camera"
    ok, data = cv2.imencode(".png", frame)
    if not ok:
        raise RuntimeError("could not encode a camera frame")
    return data.tobytes()


class DriveServer(ThreadingHTTPServer):
    daemon_threads = True

    def __init__(self, session: DriveSession, port: int = 8765) -> None:
        super().__init__(("127.0.0.1", port), _Handler)
        self.session = session
        self.page = PAGE.read_bytes()

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.server_address[1]}/"


class _Handler(BaseHTTPRequestHandler):
    server: DriveServer

    def log_message(self, format: str, *args: Any) -> None:  # noqa: A002 - stdlib signature
        pass  # 15 frame requests a second would drown the terminal

    def do_GET(self) -> None:  # noqa: N802 - stdlib naming
        session = self.server.session
        if self.path == "/":
            self._send(HTTPStatus.OK, self.server.page, "text/html; charset=utf-8")
        elif self.path.split("?")[0] == "/frame.png":
            self._send(HTTPStatus.OK, session.frame_png(), "image/png")
        elif self.path == "/state":
            self._json(HTTPStatus.OK, session.state())
        else:
            self._json(HTTPStatus.NOT_FOUND, {"error": f"no page {self.path}"})

    def do_POST(self) -> None:  # noqa: N802 - stdlib naming
        session = self.server.session
        try:
            body = self._read_json()
            if self.path == "/control":
                session.set_control(Control.parse(body))
                self._json(HTTPStatus.OK, {"ok": True})
            elif self.path == "/record":
                if not isinstance(body, dict) or not isinstance(body.get("on"), bool):
                    raise ControlError('recording takes {"on": true|false}')
                self._json(HTTPStatus.OK, session.set_recording(body["on"]))
            elif self.path == "/reset":
                session.reset()
                self._json(HTTPStatus.OK, session.state())
            else:
                self._json(HTTPStatus.NOT_FOUND, {"error": f"no action {self.path}"})
        except ControlError as error:
            self._json(HTTPStatus.BAD_REQUEST, {"error": str(error)})
        except _MediaTypeError as error:
            self._json(HTTPStatus.UNSUPPORTED_MEDIA_TYPE, {"error": str(error)})

    def _read_json(self) -> Any:
        if self.headers.get_content_type() != "application/json":
            raise _MediaTypeError("send JSON with Content-Type: application/json")
        length = int(self.headers.get("Content-Length") or 0)
        if length > MAX_BODY_BYTES:
            raise ControlError(f"body larger than {MAX_BODY_BYTES} bytes")
        try:
            return json.loads(self.rfile.read(length) or b"{}")
        except ValueError as error:
            raise ControlError(f"body is not JSON ({error})") from None

    def _json(self, status: HTTPStatus, payload: Any) -> None:
        self._send(status, json.dumps(payload).encode(), "application/json")

    def _send(self, status: HTTPStatus, data: bytes, content_type: str) -> None:
        self.send_response(status)
        self.send_header("Content-Type", content_type)
        self.send_header("Content-Length", str(len(data)))
        self.send_header("Cache-Control", "no-store")
        self.send_header("X-Content-Type-Options", "nosniff")
        self.end_headers()
        self.wfile.write(data)


class _MediaTypeError(ValueError):
    pass


def start(track: Track, runs_root: Path, *, port: int = 8765, uploader: Uploader | None = None,
          seed: int = 0) -> tuple[DriveServer, list[threading.Thread]]:
    """Start the simulation thread and the HTTP server thread; `stop(server, threads)` ends both."""
    session = DriveSession(track, runs_root, uploader=uploader, seed=seed)
    server = DriveServer(session, port)
    threads = [threading.Thread(target=session.run, name="drive-sim", daemon=True),
               threading.Thread(target=server.serve_forever, name="drive-http", daemon=True)]
    for thread in threads:
        thread.start()
    return server, threads


def stop(server: DriveServer, threads: list[threading.Thread]) -> None:
    server.session.stop()
    server.shutdown()
    server.server_close()
    for thread in threads:
        thread.join(timeout=5)
    server.session.set_recording(False)  # a run still being recorded is closed, not lost
