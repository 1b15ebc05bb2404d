"""A small HTTP client for the drem API, shared by the CLI subcommands (and HTTP tests) that act like any API client.

    parser: add_connection_arguments(parser)   → --api, --token, --username, --password
    run:    api = ApiClient.from_args(args); api.get("/api/events"); api.post("/api/fleets", json={...})

The token comes from --token (or $DREM_TOKEN); otherwise the client exchanges --username/--password (or
$DREM_USERNAME/$DREM_PASSWORD) for tokens at `POST /api/auth/token` and sends the access token it is issued as a
Bearer token, so the same client works against a laptop stack or a deployed API.
"""
from __future__ import annotations

import argparse
import os
from typing import Any

import requests

DEFAULT_API = "http://127.0.0.1:8000"
STATE_DIR_ENV = "DREM_STATE_DIR"


def running_stack_api(state_dir: str | os.PathLike[str] | None = None) -> str | None:
    """The app URL of the stack `drem up` runs on `state_dir` ($DREM_STATE_DIR, else ./.drem), if it runs."""
    from pathlib import Path

    from drem_local.stack import pid_is_drem, read_stack_file

    info = read_stack_file(Path(state_dir or os.environ.get(STATE_DIR_ENV) or ".drem")) or {}
    url = info.get("urls", {}).get("app")
    return url if url and pid_is_drem(info.get("pids", {}).get("app")) else None


def api_url(args: argparse.Namespace) -> str:
    """--api, else $DREM_API, else the URL of the stack running on --state-dir ($DREM_STATE_DIR, ./.drem)."""
    given = getattr(args, "api", None) or os.environ.get("DREM_API")
    return given or running_stack_api(getattr(args, "state_dir", None)) or DEFAULT_API


class ApiError(Exception):
    """The API refused a request (or could not be reached); the message is the API's own explanation."""

    def __init__(self, status: int, message: str, field: str | None = None) -> None:
        super().__init__(f"{message} (HTTP {status}" + (f", field {field})" if field else ")") if status else message)
        self.status = status
        self.message = message
        self.field = field


def add_connection_arguments(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("connection")
    # Resolved when the command runs (`api_url`): --state-dir names which running stack to ask.
    group.add_argument("--api", default=None,
                       help=f"base URL of the drem API (default: $DREM_API, else the stack `drem up` runs with its "
                            f"data in --state-dir, $DREM_STATE_DIR or ./.drem, else {DEFAULT_API})")
    group.add_argument("--state-dir", default=None,
                       help="the data directory of the `drem up` to talk to (default: $DREM_STATE_DIR, else ./.drem)")
    group.add_argument("--token", default=os.environ.get("DREM_TOKEN"), help="an access token (or $DREM_TOKEN)")
    group.add_argument("--username", default=os.environ.get("DREM_USERNAME"), help="sign in as (or $DREM_USERNAME)")
    group.add_argument("--password", default=os.environ.get("DREM_PASSWORD"), help="password (or $DREM_PASSWORD)")


# The same, under the name some modules use.
add_api_arguments = add_connection_arguments


class ApiClient:
    def __init__(self, base_url: str = DEFAULT_API, token: str | None = None, *, timeout_s: float = 30.0) -> None:
        self.base_url = base_url.rstrip("/")
        self.token = token
        self.timeout_s = timeout_s
        self._http = requests.Session()

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> ApiClient:
        client = cls(api_url(args), getattr(args, "token", None))
        if not client.token:
            if not (args.username and args.password):
                raise ApiError(0, "give --token, or --username and --password (or $DREM_USERNAME/$DREM_PASSWORD)")
            client.login(args.username, args.password)
        return client

    def login(self, username: str, password: str) -> str:
        """Exchange username and password for tokens at /api/auth/token; keep the access token for Bearer calls."""
        try:
            grant = self.request("POST", "/api/auth/token", json={"username": username, "password": password},
                                 authenticated=False)
        except ApiError as exc:
            if exc.status == 401:
                raise ApiError(401, f"could not sign in as {username!r}: {exc.message}") from None
            raise
        if not isinstance(grant, dict) or not grant.get("access_token"):
            raise ApiError(401, f"could not sign in as {username!r}: a new password is needed (sign in once in the "
                                "browser to set it)")
        self.token = grant["access_token"]
        return self.token

    # Both names are in use by callers.
    sign_in = login

    def get(self, path: str, params: dict[str, Any] | None = None) -> Any:
        return self.request("GET", path, params=params)

    def post(self, path: str, json: Any = None, params: dict[str, Any] | None = None) -> Any:
        return self.request("POST", path, json={} if json is None else json, params=params)

    def put(self, path: str, json: Any = None) -> Any:
        return self.request("PUT", path, json={} if json is None else json)

    def delete(self, path: str) -> Any:
        return self.request("DELETE", path)

    def post_bytes(self, path: str, data: bytes, content_type: str, params: dict[str, Any] | None = None) -> Any:
        """POST a file's bytes as the body (a league upload)."""
        return self.request("POST", path, data=data, params=params, content_type=content_type)

    def request(self, method: str, path: str, *, json: Any = None, params: dict[str, Any] | None = None,
                authenticated: bool = True, data: bytes | None = None, content_type: str | None = None) -> Any:
        headers = {"Accept": "application/json"}
        if content_type:
            headers["Content-Type"] = content_type
        if self.token and authenticated:
            headers["Authorization"] = f"Bearer {self.token}"
        try:
            reply = self._http.request(method, f"{self.base_url}{path}", json=json, data=data, params=params,
                                       headers=headers, timeout=self.timeout_s)
        except requests.RequestException as exc:
            raise _unreachable(self.base_url, exc) from None
        if reply.status_code >= 400:
            raise _api_error(reply)
        return reply.json() if reply.content else None


def _api_error(reply: requests.Response) -> ApiError:
    try:
        error = reply.json().get("error", {})
    except (ValueError, AttributeError):
        error = {}
    return ApiError(reply.status_code, error.get("message") or reply.reason or "request failed", error.get("field"))


def _unreachable(base_url: str, exc: Exception) -> ApiError:
    return ApiError(0, f"cannot reach {base_url} ({exc.__class__.__name__}); is `drem up` running? If it keeps its "
                       "data elsewhere, give that directory with --state-dir (or the URL with --api).")
