"""Drive an AWS DeepRacer through its device console web API (the car's own HTTPS Flask server).

Session: GET `/` carries `<meta name="csrf-token" content=...>`; POST `/login` (form `password=`) sets the
`deepracer_token` cookie; every later call sends `X-CSRFToken`. The car's certificate is self-signed, so TLS is not
verified unless a CA file is given. The console runs TensorFlow models (`agent/model.pb`, optimised on the car), so
this driver uploads console-format archives; an ONNX-only model is refused with a clear reason.
"""
from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import requests

from drem_cars.model_files import TENSORFLOW_FILES, ModelError
from drem_cars.model_store import ARCHIVE_COPY, InstalledModel

_CSRF_META = re.compile(r'<meta\s+name=["\']csrf-token["\']\s+content=["\']([^"\']+)["\']', re.I)


class ConsoleError(RuntimeError):
    """The DeepRacer console refused or could not be reached."""


class DeepRacerConsole:
    def __init__(self, base_url: str, password: str, *, verify: bool | str = False, timeout_s: float = 30.0) -> None:
        self.base_url = base_url.rstrip("/")
        self._password = password
        self._http = requests.Session()
        self._http.verify = verify
        self._http.trust_env = False
        self.timeout_s = timeout_s
        self.csrf_token: str | None = None

    def login(self) -> None:
        page = self._call("GET", "/", auth=False)
        match = _CSRF_META.search(page.text)
        if not match:
            raise ConsoleError("the console page has no csrf-token meta tag; is this a DeepRacer device console?")
        self.csrf_token = match.group(1)
        reply = self._call("POST", "/login", data={"password": self._password}, auth=False, check=False)
        if reply.status_code >= 400 or "deepracer_token" not in self._http.cookies:
            raise ConsoleError("the console refused the password (see the sticker under the car)")

    def _call(self, method: str, path: str, *, auth: bool = True, check: bool = True, **kwargs: Any
              ) -> requests.Response:
        headers = kwargs.pop("headers", {})
        if auth:
            if self.csrf_token is None:
                self.login()
            headers["X-CSRFToken"] = self.csrf_token
        try:
            reply = self._http.request(method, f"{self.base_url}{path}", headers=headers, timeout=self.timeout_s,
                                       **kwargs)
        except requests.RequestException as exc:
            raise ConsoleError(f"cannot reach the DeepRacer console at {self.base_url} ({exc.__class__.__name__})"
                               ) from None
        if check and reply.status_code >= 400:
            raise ConsoleError(f"{method} {path}: HTTP {reply.status_code}: {reply.text[:200]}")
        return reply

    def _api(self, method: str, path: str, **kwargs: Any) -> dict[str, Any]:
        reply = self._call(method, path, **kwargs)
        try:
            body = reply.json()
        except ValueError:
            raise ConsoleError(f"{path}: the console answered with something that is not JSON") from None
        if isinstance(body, dict) and body.get("success") is False:
            raise ConsoleError(f"{path}: {body.get('reason') or body}")
        return body

    # --- the console API ---
    def upload_model(self, archive: Path, name: str) -> dict[str, Any]:
        with open(archive, "rb") as handle:
            return self._api("PUT", "/api/uploadModels",
                             files={"file": (f"{name}.tar.gz", handle, "application/gzip")})

    def load_model(self, folder: str, model_file: str = "model.pb") -> dict[str, Any]:
        return self._api("PUT", f"/api/models/{folder}/{model_file}")

    def drive_mode(self, mode: str) -> dict[str, Any]:
        return self._api("PUT", "/api/drive_mode", json={"drive_mode": mode})

    def max_nav_throttle(self, pct: int) -> dict[str, Any]:
        return self._api("PUT", "/api/max_nav_throttle", json={"throttle": pct})

    def start_stop(self, start: bool) -> dict[str, Any]:
        return self._api("PUT", "/api/start_stop", json={"start_stop": "start" if start else "stop"})

    def set_led_color(self, red: int, green: int, blue: int) -> dict[str, Any]:
        return self._api("POST", "/api/set_led_color", json={"red": red, "green": green, "blue": blue})

    def battery_level(self) -> int | None:
        body = self._api("GET", "/api/get_battery_level")
        level = body.get("battery_level")
        return int(level) if isinstance(level, (int, float)) and level >= 0 else None


class DeepRacerConsoleDriver:
    """CarDriver over the console: models are uploaded then loaded, stops and the cap go to the console."""

    BATTERY_LEVELS = 10  # the console reports the battery in 0..10 steps

    def __init__(self, console: DeepRacerConsole) -> None:
        self.console = console
        self._faults: list[str] = []

    def load_model(self, model: InstalledModel) -> None:
        if not any((model.path / name).is_file() for name in TENSORFLOW_FILES):
            raise ModelError(f"{model.name} has no agent/model.pb: a DeepRacer console runs TensorFlow models "
                             "only (this one is ONNX; run it with the drem car agent instead)")
        try:
            self.console.upload_model(model.path / ARCHIVE_COPY, model.folder)
            self.console.load_model(model.folder)
            self.console.drive_mode("auto")
        except ConsoleError as exc:
            raise ModelError(str(exc)) from None

    def unload_models(self) -> None:
        self.emergency_stop()

    def emergency_stop(self) -> None:
        self.console.start_stop(False)

    def set_throttle_cap(self, pct: int) -> None:
        self.console.max_nav_throttle(pct)

    def set_tail_light(self, colour_hex: str) -> None:
        value = colour_hex.lstrip("#")
        self.console.set_led_color(int(value[0:2], 16), int(value[2:4], 16), int(value[4:6], 16))

    def heartbeat_ok(self) -> None: ...

    def battery_pct(self) -> float | None:
        try:
            level = self.console.battery_level()
            self._faults = []
        except ConsoleError as exc:
            self._faults = [f"console: {exc}"[:120]]
            return None
        return None if level is None else min(100.0, 100.0 * level / self.BATTERY_LEVELS)

    def faults(self) -> list[str]:
        return list(self._faults)

    def fps(self) -> float | None:
        return None

    def inference_ms(self) -> float | None:
        return None
