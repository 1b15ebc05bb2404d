"""Drive a stock AWS DeepRacer through its device console (the car's own web server), as the car really behaves.

What the car does, read in its source (aws-deepracer/aws-deepracer-webserver-pkg, -ctrl-pkg, -systems-pkg,
-model-optimizer-pkg, -i2c-pkg; details and citations in tests/cars/fake_deepracer_console.py):

- Every POST/PUT, `/login` included, is checked by Flask-WTF's CSRFProtect: the token is the page's
  `<meta name="csrf-token">`, sent as `X-CSRFToken` (with a `Referer`, which the check demands under HTTPS). It
  expires after an hour (400 "The CSRF token has expired."), as does the `deepracer_token` login cookie (then 401).
  The car keeps one login: another client logging in logs us out (401). Each call logs in again once and retries.
- Upload (`/api/uploadModels`) answers `message`; the car installs the one `*.pb` of the archive as
  `<folder>/model.pb`. Loading (`/api/models/<folder>/model`: the model optimizer appends `.pb` itself) answers
  `reason` when the metadata is refused, and otherwise success at once: the load runs in the background and its
  outcome is only in `GET /api/isModelLoading` (`loading` / `loaded` / `error`). Loading in manual mode (the car
  boots in manual) also "succeeds" and then reads `error`, so the driver switches to autonomous first.
- `max_nav_throttle` starts at 0 on a booted car and only applies in autonomous mode; the car moves only after
  `start_stop: start`. The tail light changes only in calibration mode (elsewhere the call "succeeds" and nothing
  happens), and entering calibration mode stops the car.

- A restart (every battery swap) boots the car in manual mode with nothing loaded; the model folders stay on its disk.
  Whether our login survives it we could not read upstream (login.py is not in the index): the token lives in a file,
  /opt/aws/deepracer/token.txt ([webserver constants.py] TOKEN_PATH), and the copies of webserver.py we could read sign
  sessions with a constant key, so it probably does; the driver works either way (tests/cars/fake_deepracer_console.py
  models both).

drem's decisions: a model is reported loaded only when `isModelLoading` says `loaded`, and the agent asks the car
again every check (`model_lost`), reloading a model a restarted car lost; a restart is known by the car having stopped
answering and then answering again (a battery swap takes minutes; no login or session key is relied on), so a refused
young login after that is the restart's, and one without it is another client's; START_CAR is refused
unless the car says `loaded`; HTTPS only with the car's certificate pinned (drem_cars.car_tls); the car is left
stopped in autonomous mode with the staff throttle cap (100 % by default) applied; it starts on the staff START_CAR
command and stops on EMERGENCY_STOP (race start does not start it). The tail light is set only while the car is
stopped (briefly in calibration mode, then back to autonomous with the model still loaded); a colour asked for while
the car is started is applied at its next stop. Polls (battery) do not take the login back from someone else for
`yield_login_s`; staff commands and model loads always do. Faults (heartbeat) say when someone else holds the car.
"""
from __future__ import annotations

import re
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import requests

from drem_cars.car_tls import PinnedCertificateAdapter, changed_certificate_message
from drem_cars.drivers import CarUnreachable
from drem_cars.model_files import TENSORFLOW_FILES, ModelError
from drem_cars.model_store import ARCHIVE_COPY, InstalledModel

_META_TAG = re.compile(r"<meta\s[^>]*>", re.I)
_META_NAME = re.compile(r"""\bname\s*=\s*["']csrf-token["']""", re.I)
_META_CONTENT = re.compile(r"""\bcontent\s*=\s*["']([^"']+)["']""", re.I)
LOGIN_COOKIE = "deepracer_token"
LOGIN_LIFE_S = 3600.0        # the car's cookie max_age and Flask-WTF's token time limit
BATTERY_FULL_LEVEL = 10      # the battery node reports 0..11 (11 = above full), -1 when it cannot read the chip
FAULT_MAX = 120              # the heartbeat refuses longer fault lines
CAMERA_ROUTE = "/route?topic=/camera_pkg/display_mjpeg"  # the console's camera (see tests/cars/fake_deepracer_console)
EVENT_SHOWN_S = 600.0        # how long the Cars page keeps saying what happened to the car (a restart, a reload)


class ConsoleError(RuntimeError):
    """The DeepRacer console refused or could not be reached; the message says which, in plain words."""


class ConsoleUnreachable(ConsoleError, CarUnreachable):
    """No answer from the car (WiFi, car off): worth trying again later, unlike a refusal."""


class ConsoleHeld(ConsoleError):
    """Someone else is logged in to the car's console and drem is leaving it to them for now."""


class DeepRacerConsole:
    """The console's HTTP API: one session, logged in again when the car forgets it."""

    def __init__(self, base_url: str, password: str, *, fingerprint: str | None = None, timeout_s: float = 30.0,
                 upload_timeout_s: float = 300.0, yield_login_s: float = 120.0,
                 clock: Callable[[], float] = time.monotonic) -> None:
        """`fingerprint`: the SHA-256 of the car's self-signed certificate (drem_cars.car_tls), required for https."""
        self.base_url = base_url.rstrip("/")
        if self.base_url.startswith("https://") and not fingerprint:
            raise ConsoleError(f"{self.base_url}: drem talks https to a car only with its certificate pinned")
        self.fingerprint = fingerprint
        self._password = password
        self._http = requests.Session()
        self._http.verify = False  # the car signs its own certificate: it is pinned instead (no CA can vouch)
        if fingerprint:
            self._http.mount(self.base_url, PinnedCertificateAdapter(fingerprint))
        self._http.trust_env = False
        self.timeout_s = timeout_s
        self.upload_timeout_s = upload_timeout_s
        self.yield_login_s = yield_login_s
        self._clock = clock
        self.csrf_token: str | None = None
        self.logged_in_at: float | None = None
        self.held_by_other_since: float | None = None  # when a young login of ours was replaced by someone else's
        # Times the car stopped answering and then answered again (a battery swap restarts it; a WiFi gap looks the
        # same, which only matters if the model is gone too): the driver then re-checks the car.
        self.restarts = 0
        self.restarted_at: float | None = None
        self._unanswered = False
        # The agent calls from two threads (commands + heartbeat, model loads). Logins are serialised, requests are
        # not (an emergency stop must not wait for an upload).
        self._login_lock = threading.Lock()

    # --- session ---
    def login(self) -> None:
        self.csrf_token = self._page_token()
        try:
            del self._http.cookies[LOGIN_COOKIE]
        except KeyError:
            pass
        reply = self._send("POST", "/login", data={"password": self._password}, headers=self._headers())
        if reply.status_code == 400 and "csrf" in reply.text.lower():
            raise ConsoleError(f"the console refused the login's CSRF token ({_short(reply.text)})")
        if reply.status_code >= 400 or reply.text.strip() == "failure" or LOGIN_COOKIE not in self._http.cookies:
            raise ConsoleError("the console refused the password (see the sticker under the car)")
        self.logged_in_at = self._clock()
        self.held_by_other_since = None

    def _page_token(self) -> str:
        for path in ("/", "/login"):  # `/` sends a logged-out client on to the login page
            token = csrf_meta_token(self._send("GET", path).text)
            if token:
                return token
        raise ConsoleError("the console page has no csrf-token meta tag; is this a DeepRacer device console?")

    def _headers(self) -> dict[str, str]:
        return {"X-CSRFToken": self.csrf_token or "", "Referer": f"{self.base_url}/"}

    def _send(self, method: str, path: str, *, timeout: float | None = None, **kwargs: Any) -> requests.Response:
        try:
            reply = self._http.request(method, f"{self.base_url}{path}", timeout=timeout or self.timeout_s, **kwargs)
        except requests.exceptions.SSLError as exc:
            if self.fingerprint and "fingerprint" in str(exc).lower():
                raise ConsoleError(changed_certificate_message(self.base_url, str(exc))) from None
            self._unanswered = True
            raise ConsoleUnreachable(f"cannot reach the DeepRacer console at {self.base_url} over TLS "
                                     f"({_short(str(exc))})") from None
        except requests.RequestException as exc:
            self._unanswered = True
            raise ConsoleUnreachable(f"cannot reach the DeepRacer console at {self.base_url} "
                                     f"({exc.__class__.__name__})") from None
        if self._unanswered:
            self._unanswered = False
            self.restarts += 1
            self.restarted_at = self._clock()
        if self.base_url.startswith("http://"):
            # The car marks its cookies Secure (it is HTTPS behind nginx); reached over plain http (nginx bypassed,
            # a bench replica) they must still come back, or every CSRF check fails.
            for cookie in self._http.cookies:
                cookie.secure = False
        return reply

    def _call(self, method: str, path: str, *, take_back: bool = True, **kwargs: Any) -> requests.Response:
        if self.csrf_token is None:
            self._relogin(take_back, self._credentials_in_use(), None)
        sent = self._credentials_in_use()
        reply = self._authed(method, path, **kwargs)
        if _needs_login(reply):
            self._relogin(take_back, sent, reply)
            reply = self._authed(method, path, **kwargs)
        if _needs_login(reply):
            raise ConsoleError(f"{method} {path}: the console still refuses drem after logging in again "
                               f"(HTTP {reply.status_code}: {_short(reply.text)})")
        if reply.status_code >= 400:
            raise ConsoleError(f"{method} {path}: HTTP {reply.status_code}: {_short(reply.text)}")
        return reply

    def _credentials_in_use(self) -> tuple[str | None, str | None]:
        return self._http.cookies.get(LOGIN_COOKIE), self.csrf_token

    def _relogin(self, take_back: bool, sent: tuple[str | None, str | None],
                 refused: requests.Response | None) -> None:
        with self._login_lock:
            if self.csrf_token is not None and self._credentials_in_use() != sent:
                return  # our other thread logged in meanwhile: retry with its login
            if refused is not None and self.held_by_other_since is None and self._login_was_young():
                if self._came_back_since_login():
                    self.login()  # the restart forgot us; nobody else holds the car: log in at once, whatever the call
                    return
                if refused.status_code == 401:
                    self.held_by_other_since = self._clock()
            self._login_unless_held(take_back)

    def _came_back_since_login(self) -> bool:
        """A young login refused: did the car restart, or did someone else log in? Restarted if the car stopped
        answering after our login and came back (a battery swap); the session cookie is no evidence, as the car's
        session key may well be the same at every start."""
        return (self.restarted_at is not None and self.logged_in_at is not None
                and self.restarted_at >= self.logged_in_at)

    def _authed(self, method: str, path: str, **kwargs: Any) -> requests.Response:
        headers = {**self._headers(), **kwargs.pop("headers", {})}
        # No redirects: a console that sends a logged-out API call to its login page must not turn a PUT into a GET.
        return self._send(method, path, headers=headers, allow_redirects=False, **kwargs)

    def _login_was_young(self) -> bool:
        return self.logged_in_at is not None and self._clock() - self.logged_in_at < LOGIN_LIFE_S - 60

    def _login_unless_held(self, take_back: bool) -> None:
        since = self.held_by_other_since
        if not take_back and since is not None and self._clock() - since < self.yield_login_s:
            raise ConsoleHeld(self.held_message())
        self.login()

    def held_message(self) -> str | None:
        if self.held_by_other_since is None:
            return None
        return "someone else logged in to the car's console; drem logs back in for staff commands and model loads"

    def _api(self, method: str, path: str, **kwargs: Any) -> Any:
        reply = self._call(method, path, **kwargs)
        try:
            body = reply.json()
        except ValueError:
            raise ConsoleError(f"{path}: the console answered with something that is not JSON") from None
        if isinstance(body, dict) and body.get("success") is False:
            raise ConsoleError(f"{path}: {body.get('reason') or body.get('message') or 'refused'}")
        return body

    # --- the console API ---
    def camera_stream(self, width: int, height: int, *, timeout_s: float = 5.0) -> requests.Response:
        """The car's camera as the console streams it (MJPEG, web_video_server's `multipart/x-mixed-replace`), on
        the session drem already holds; never takes the login back from someone else (video is not worth it)."""
        return self._call("GET", f"{CAMERA_ROUTE}&width={int(width)}&height={int(height)}", take_back=False,
                          stream=True, timeout=timeout_s)

    def upload_model(self, archive: Path, folder: str) -> dict[str, Any]:
        data = archive.read_bytes()  # bytes, not a file handle: a retry after logging in again resends it whole
        return self._api("PUT", "/api/uploadModels", timeout=self.upload_timeout_s,
                         files={"file": (f"{folder}.tar.gz", data, "application/gzip")})

    def load_model(self, folder: str) -> dict[str, Any]:
        return self._api("PUT", f"/api/models/{folder}/model")  # the car's optimizer appends ".pb"

    def model_loading_status(self, *, take_back: bool = True) -> str:
        return str(_field(self._api("GET", "/api/isModelLoading", take_back=take_back), "isModelLoading",
                          "/api/isModelLoading"))

    def drive_mode(self, mode: str) -> dict[str, Any]:
        return self._api("PUT", "/api/drive_mode", json={"drive_mode": mode})

    def max_nav_throttle(self, pct: int) -> dict[str, Any]:
        return self._api("PUT", "/api/max_nav_throttle", json={"throttle": pct})

    def start_stop(self, start: bool) -> dict[str, Any]:
        return self._api("PUT", "/api/start_stop", json={"start_stop": "start" if start else "stop"})

    def calibration_mode(self) -> dict[str, Any]:
        return self._api("GET", "/api/set_calibration_mode")

    def set_led_color(self, red: int, green: int, blue: int) -> dict[str, Any]:
        return self._api("POST", "/api/set_led_color", json={"red": red, "green": green, "blue": blue})

    def uploaded_models(self, *, take_back: bool = True) -> list[str]:
        entries = self._api("GET", "/api/uploaded_model_list", take_back=take_back)
        if not isinstance(entries, list):
            raise ConsoleError("/api/uploaded_model_list: the console did not answer with a list")
        return [str(_field(entry, "name", "/api/uploaded_model_list")) for entry in entries]

    def delete_models(self, folders: list[str]) -> dict[str, Any]:
        return self._api("PUT", "/api/deleteModels", json={"filenames": folders})

    def battery_level(self) -> int:
        level = _field(self._api("GET", "/api/get_battery_level", take_back=False), "battery_level",
                       "/api/get_battery_level")
        try:
            return int(level)
        except (TypeError, ValueError):
            raise ConsoleError(f"/api/get_battery_level: battery_level {level!r} is not a number") from None


class DeepRacerConsoleDriver:
    """CarDriver over the console (see the module docstring for what the car does and what drem decided)."""

    def __init__(self, console: DeepRacerConsole, *, load_timeout_s: float = 180.0, poll_s: float = 0.1,
                 settle_s: float = 2.0, clock: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep) -> None:
        self.console = console
        self.load_timeout_s = load_timeout_s
        self.poll_s = poll_s
        self.settle_s = settle_s  # the load thread needs a moment before isModelLoading speaks of *this* load
        self._clock = clock
        self._sleep = sleep
        self.throttle_cap_pct = 100
        self.started = False
        self.pending_tail_light: str | None = None
        self._faults: list[str] = []
        self._uploaded: dict[str, str] = {}  # folder -> archive md5 this process uploaded (the car keeps folders)
        self._restarts_seen = 0
        self._event: tuple[float, str] | None = None  # what happened to the car lately, for staff (monotonic, text)

    # --- models ---
    def load_model(self, model: InstalledModel) -> None:
        if not any((model.path / name).is_file() for name in TENSORFLOW_FILES):
            raise ModelError(f"{model.name} has no agent/model.pb: a DeepRacer console runs TensorFlow models "
                             "only (this one is ONNX; run it with the drem car agent instead)")
        try:
            uploaded_before = self._uploaded.get(model.folder) == model.archive_md5
            if not uploaded_before:
                self.upload(model)
            self._stop()
            self.console.drive_mode("auto")
            try:
                self.console.load_model(model.folder)
            except ConsoleUnreachable:
                raise
            except ConsoleError:
                if not uploaded_before:
                    raise
                # The folder drem put there earlier is gone (deleted on the car's own page): upload it again, once.
                self._uploaded.pop(model.folder, None)
                self.upload(model)
                self.console.load_model(model.folder)
            self._wait_until_loaded(model.folder)
            self.console.max_nav_throttle(self.throttle_cap_pct)
        except ConsoleUnreachable:
            raise  # not the model's fault: the agent tries again on its next cycle
        except ConsoleError as exc:
            raise ModelError(str(exc)) from None

    def upload(self, model: InstalledModel) -> None:
        """Put the model's folder on the car (a later load of it is then the load call alone: the car keeps its
        folders, across restarts too; one it no longer has is uploaded again when its load is refused)."""
        self._uploaded.pop(model.folder, None)
        self.console.upload_model(model.path / ARCHIVE_COPY, model.folder)
        self._uploaded[model.folder] = model.archive_md5

    def preload(self, model: InstalledModel) -> None:
        """A later racer's model goes onto the car while it drives (an upload does not touch the loaded model), once
        per process; should the folder be gone by its turn, the car refuses the load and it is uploaded again."""
        if not any((model.path / name).is_file() for name in TENSORFLOW_FILES):
            return  # ONNX only: its load says why the car cannot take it
        if self._uploaded.get(model.folder) != model.archive_md5:
            self.upload(model)

    def model_lost(self, model: InstalledModel) -> str | None:
        """None while the car still drives `model` (or cannot be asked now); otherwise what happened, in words. Asks
        the car itself: its folders (`/api/uploaded_model_list`) and `isModelLoading` (a restarted car, after a
        battery swap, boots in manual mode with nothing loaded). A folder drem put there that is gone is forgotten,
        so it is uploaded again; the driving model's own is uploaded again at once (the car drives on meanwhile)."""
        try:
            folders = set(self.console.uploaded_models(take_back=False))
            status = self.console.model_loading_status(take_back=False)
        except (ConsoleHeld, ConsoleUnreachable):
            return None  # someone else has the car for now, or it is off: asked again on the next check
        for folder in [f for f in self._uploaded if f not in folders]:
            del self._uploaded[folder]  # deleted on the car: the next racers' are put back by the agent's preload
        if status in ("loaded", "loading"):
            self._restarts_seen = self.console.restarts  # a WiFi gap that lost nothing
            if model.folder not in folders:
                self.upload(model)  # a restart would otherwise find nothing to load
            return None
        if self.console.restarts > self._restarts_seen:
            self._restarts_seen = self.console.restarts
            text = f"car restarted {_utc_clock()} and lost {model.name[:30]}: loading it again"
        else:
            text = f"car no longer has {model.name[:30]} loaded (isModelLoading: {status[:20]}): loading it again"
        self._note(text)
        self.started = False
        return text

    def reloaded(self, model: InstalledModel) -> None:
        """The model lost by the car is loaded again: say so for a while, then the note goes."""
        if self._event is not None and "loading it again" in self._event[1]:
            self._note(self._event[1].replace("loading it again", f"loaded again {_utc_clock()}"))

    def _note(self, text: str) -> None:
        self._event = (self._clock(), text[:FAULT_MAX])

    def _wait_until_loaded(self, folder: str) -> None:
        asked = self._clock()
        seen_loading = False
        restarts = self.console.restarts
        while True:
            try:
                status = self.console.model_loading_status()
            except ConsoleUnreachable:
                raise ConsoleUnreachable(f"the car stopped answering while loading {folder}/model (restarted?); "
                                         "loading it again when it is back") from None
            if self.console.restarts != restarts:  # a battery swap mid-load: not the model's fault, load it again
                raise ConsoleUnreachable(f"the car restarted while loading {folder}/model; loading it again")
            seen_loading = seen_loading or status == "loading"
            settled = seen_loading or self._clock() - asked >= self.settle_s
            if settled and status == "loaded":
                return
            if settled and status == "error":
                raise ConsoleError(f"the car could not load {folder}/model: /api/isModelLoading says \"error\" "
                                   "(its model optimizer or inference engine failed; the car's logs say why)")
            if self._clock() - asked > self.load_timeout_s:
                raise ConsoleError(f"the car was still loading {folder}/model after {self.load_timeout_s:.0f} s "
                                   f"(/api/isModelLoading: {status!r})")
            self._sleep(self.poll_s)

    def unload_models(self) -> None:
        """The loaded model is no longer assigned: the car must not drive it."""
        self.emergency_stop()

    def delete_all_models(self) -> int:
        self.emergency_stop()
        folders = self.console.uploaded_models()
        if folders:
            self.console.delete_models(folders)
        self._uploaded.clear()
        return len(folders)

    # --- staff commands ---
    def start_car(self) -> None:
        self.console.drive_mode("auto")  # a no-op for the model; it also leaves calibration mode behind
        status = self.console.model_loading_status()
        if status != "loaded":
            hint = " (it restarted and is being loaded again)" if self.console.restarts > 0 else ""
            raise ConsoleError(f"not started: the car has no model loaded{hint}; its console says "
                               f"isModelLoading {status!r}")
        self.console.max_nav_throttle(self.throttle_cap_pct)
        self.console.start_stop(True)
        self.started = True

    def emergency_stop(self) -> None:
        self._stop()
        if self.pending_tail_light is not None:
            try:
                self._apply_tail_light(self.pending_tail_light)
            except ConsoleError:
                pass  # the car is stopped, which is what was asked; the colour stays pending (and in the faults)

    def _stop(self) -> None:
        self.console.start_stop(False)
        self.started = False

    def set_throttle_cap(self, pct: int) -> None:
        if not 0 <= pct <= 100:
            raise ValueError("the throttle cap is a percentage from 0 to 100")
        self.throttle_cap_pct = pct
        self.console.max_nav_throttle(pct)

    def set_tail_light(self, colour_hex: str) -> str:
        if self.started:
            self.pending_tail_light = colour_hex
            return f"tail light {colour_hex} when the car next stops (it changes only in calibration mode)"
        self._apply_tail_light(colour_hex)
        return f"tail light {colour_hex}"

    def _apply_tail_light(self, colour_hex: str) -> None:
        value = colour_hex.lstrip("#")
        red, green, blue = int(value[0:2], 16), int(value[2:4], 16), int(value[4:6], 16)
        self.console.calibration_mode()  # stops the car; the loaded model stays loaded
        try:
            self.console.set_led_color(red, green, blue)
        finally:
            self.console.drive_mode("auto")
            self.console.max_nav_throttle(self.throttle_cap_pct)
        self.pending_tail_light = None

    # --- telemetry ---
    def heartbeat_ok(self) -> None: ...

    def battery_pct(self) -> float | None:
        faults: list[str] = []
        pct: float | None = None
        try:
            level = self.console.battery_level()
        except ConsoleHeld:
            level = None
        except ConsoleError as exc:
            level = None
            faults.append(f"console: {exc}"[:FAULT_MAX])
        if level is not None and level < 0:
            faults.append("the car cannot read its battery level (the console reports -1)")
        elif level is not None:
            pct = min(100.0, 100.0 * level / BATTERY_FULL_LEVEL)
        held = self.console.held_message()
        if held is not None:
            faults.append(held)
        if self.pending_tail_light is not None:
            faults.append(f"tail light {self.pending_tail_light} waits for the car to stop")
        if self._event is not None and self._clock() - self._event[0] < EVENT_SHOWN_S:
            faults.append(self._event[1])
        self._faults = faults
        return pct

    def faults(self) -> list[str]:
        return list(self._faults)

    def fps(self) -> float | None:
        return None

    def inference_ms(self) -> float | None:
        return None


def _utc_clock() -> str:
    return time.strftime("%H:%M:%S UTC", time.gmtime())


def _field(body: Any, key: str, path: str) -> Any:
    if not isinstance(body, dict) or key not in body:
        raise ConsoleError(f"{path}: the console's answer has no {key!r}")
    return body[key]


def csrf_meta_token(page: str) -> str | None:
    """The content of `<meta name="csrf-token" content=...>`, whatever the attribute order."""
    for tag in _META_TAG.findall(page):
        content = _META_CONTENT.search(tag)
        if _META_NAME.search(tag) and content:
            return content.group(1)
    return None


def _needs_login(reply: requests.Response) -> bool:
    """401: no valid login cookie (expired, or someone else logged in). 400 from CSRFProtect: the token expired.
    A redirect to the login page: the same as a 401, said the way a web page says it."""
    if reply.is_redirect and "login" in reply.headers.get("Location", "").lower():
        return True
    return reply.status_code == 401 or (reply.status_code == 400 and "csrf" in reply.text.lower())


def _short(text: str) -> str:
    plain = re.sub(r"<[^>]+>", " ", text)
    return " ".join(plain.split())[:200]
