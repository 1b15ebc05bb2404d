"""HTTP client for the device API (`Authorization: Device <id>.<secret>`).

Errors are sorted by what the agent must do: `Revoked` (401: the credential was revoked or the device deregistered —
stop cleanly and say so), `Unreachable` (no answer, or 5xx/429: try again later; nothing is lost), `Rejected` (any
other 4xx: this request will never succeed as it is).
"""
from __future__ import annotations

import secrets
import time
from dataclasses import replace
from typing import Any

import requests

from drem_cars.credentials import CredentialStore, StoredCredential

CSRF_COOKIE = "drem_csrf"
CSRF_HEADER = "X-CSRF-Token"


class DeviceApiError(Exception):
    def __init__(self, message: str, status: int = 0) -> None:
        super().__init__(message)
        self.status = status


class Revoked(DeviceApiError):
    """The server no longer accepts this device's credential."""


class Unreachable(DeviceApiError):
    """The server did not answer usefully; retry later."""


class Rejected(DeviceApiError):
    """The server refused this request for good (4xx other than 401/408/429)."""


def _error_for(reply: requests.Response, what: str) -> DeviceApiError:
    try:
        message = reply.json().get("error", {}).get("message") or reply.text
    except (ValueError, AttributeError):
        message = reply.text or reply.reason
    text = f"{what}: HTTP {reply.status_code}: {message}"
    if reply.status_code == 401:
        return Revoked(f"{what}: the server no longer accepts this device (credential revoked or device "
                       f"deregistered): {message}", 401)
    if reply.status_code >= 500 or reply.status_code in (408, 429):
        return Unreachable(text, reply.status_code)
    return Rejected(text, reply.status_code)


def activate(api: str, code: str, hostname: str, device_kind: str = "car", *, timeout_s: float = 15.0,
             attempt_id: str | None = None, retry_delays_s: tuple[float, ...] = (1.0, 2.0, 4.0, 8.0),
             ) -> StoredCredential:
    """Exchange a one-time activation code for a device credential.

    Every try of one activation sends the same `attempt_id`, so when an answer is lost (server restarted, WiFi
    dropped) a retry resumes the activation the server already stored instead of finding the code used. Unreachable
    and 5xx answers are retried after `retry_delays_s`; a refusal is not.

    A random double-submit CSRF token goes along (cookie + header): harmless where the route is CSRF-exempt, and
    enough where it is not — a device holds no session a forged request could ride on."""
    api = api.rstrip("/")
    attempt_id = attempt_id or secrets.token_urlsafe(24)
    for delay_s in (*retry_delays_s, None):
        try:
            return _activate_once(api, code, hostname, device_kind, attempt_id, timeout_s)
        except Unreachable:
            if delay_s is None:
                raise
            time.sleep(delay_s)  # backoff between network retries (not a wait in a test)
    raise AssertionError("unreachable")


def _activate_once(api: str, code: str, hostname: str, device_kind: str, attempt_id: str,
                   timeout_s: float) -> StoredCredential:
    token = secrets.token_urlsafe(24)
    body = {"code": code, "hostname": hostname, "device_kind": device_kind, "attempt_id": attempt_id}
    try:
        reply = requests.post(f"{api}/api/devices/activate", timeout=timeout_s, json=body,
                              headers={CSRF_HEADER: token, "Accept": "application/json"},
                              cookies={CSRF_COOKIE: token})
    except requests.RequestException as exc:
        raise Unreachable(f"cannot reach {api} ({exc.__class__.__name__})") from None
    if reply.status_code != 201:
        error = _error_for(reply, "activation refused")
        raise (Rejected(str(error), reply.status_code) if isinstance(error, Revoked) else error)
    issued = reply.json()
    return StoredCredential(api=api, device_id=issued["device_id"], device_kind=issued["device_kind"],
                            hostname=issued["hostname"], fleet_id=issued.get("fleet_id"),
                            credential=issued["credential"])


class DeviceClient:
    def __init__(self, store: CredentialStore, *, api: str | None = None, timeout_s: float = 10.0) -> None:
        self._store = store
        self.credential = store.load()
        self.api = (api or self.credential.api).rstrip("/")
        self.timeout_s = timeout_s
        self._http = requests.Session()
        self._http.trust_env = False  # a proxy from the environment must never see the device credential

    @property
    def device_id(self) -> str:
        return self.credential.device_id

    def request(self, method: str, path: str, body: Any = None, *, what: str = "", wait_s: float = 0.0) -> Any:
        headers = {"Authorization": f"Device {self.credential.credential}", "Accept": "application/json"}
        try:
            reply = self._http.request(method, f"{self.api}{path}", json=body, headers=headers,
                                       timeout=self.timeout_s + wait_s)
        except requests.RequestException as exc:
            raise Unreachable(f"{what or path}: cannot reach {self.api} ({exc.__class__.__name__})") from None
        if reply.status_code >= 400:
            raise _error_for(reply, what or f"{method} {path}")
        return reply.json() if reply.content else None

    # --- the device API ---
    def heartbeat(self, telemetry: dict[str, Any]) -> dict[str, Any]:
        return self.request("POST", "/api/devices/self/heartbeat", telemetry, what="heartbeat")

    def commands(self) -> list[dict[str, Any]]:
        return self.request("GET", "/api/devices/self/commands", what="commands")["commands"]

    def acknowledge(self, command_id: str, ok: bool, message: str = "") -> dict[str, Any]:
        return self.request("POST", f"/api/devices/self/commands/{command_id}/ack",
                            {"result": "ok" if ok else "failed", "message": message[:1000]}, what="command ack")

    def assignment(self, *, wait_for_version: int | None = None, wait_s: float = 0.0) -> dict[str, Any]:
        """The car's assignment; with `wait_for_version`, the server answers when it changes (or after wait_s)."""
        if wait_for_version is None:
            return self.request("GET", "/api/devices/self/assignment", what="assignment")
        return self.request("GET", f"/api/devices/self/assignment?wait_for_version={int(wait_for_version)}"
                                   f"&wait_s={wait_s:g}", what="assignment", wait_s=wait_s)

    def report_model_status(self, report: dict[str, Any]) -> dict[str, Any]:
        return self.request("POST", "/api/devices/self/assignment/status", report, what="model status")

    def strip_event(self, event: dict[str, Any]) -> dict[str, Any]:
        return self.request("POST", "/api/timing/strip-events", event, what="strip event")

    def rotate(self) -> StoredCredential:
        """New secret from the server, saved (0600) before it is used; the old one stops working at once."""
        issued = self.request("POST", "/api/devices/self/rotate", what="credential rotation")
        self.credential = replace(self.credential, credential=issued["credential"])
        self._store.save(self.credential)
        return self.credential

    def download(self, url: str, destination: Any, chunk: int = 1 << 16) -> None:
        """Stream a presigned GET into an open binary file (no device credential goes to the bucket)."""
        try:
            with requests.get(url, stream=True, timeout=self.timeout_s) as reply:
                if reply.status_code != 200:
                    raise Unreachable(f"model download: HTTP {reply.status_code}", reply.status_code)
                for piece in reply.iter_content(chunk):
                    destination.write(piece)
        except requests.RequestException as exc:
            raise Unreachable(f"model download failed ({exc.__class__.__name__})") from None
