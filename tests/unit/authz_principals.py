"""The eleven principals of the authorization matrix, with real credentials, in ONE stack per test module.

Anonymous (no credentials, but a valid CSRF cookie/header pair so a PUBLIC form post is not refused for CSRF),
racer A and B, registration, commentator, operator, admin (real Cognito access tokens from the local pool, sent as
Bearer), admin_cookie (an admin signed in through /login like a browser: session cookies and the session-bound CSRF
token, so the cookie + CSRF path is covered too), cars X and Y and a timer (activated through the real activation
API, sent as `Authorization: Device <id>.<secret>`).

The matrix makes ~900 calls; bootstrapping the stack for each would take minutes, so a module using `world` is
marked `one_stack_per_module` (tests/unit/conftest.py): moto is wiped once per module instead of before every test.
Every allowed call's scenario creates its own objects (a route's refused callers share one), and an allowed call
that uses up its caller (deleting one's own account, rotating a device secret) runs as a freshly minted principal of
the same kind.
"""
from __future__ import annotations

import importlib
import json
import pkgutil
import secrets
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import pytest
from chalice import Blueprint
from chalice.test import Client

from drem_local.bootstrap import clients_for, ensure_stack
from tests.unit.conftest import PASSWORD, REGION, STAGE, Users, _reset_app_caches, bearer, set_cookie_headers

PRINCIPALS = ("anonymous", "racer_a", "racer_b", "registration", "commentator", "operator", "admin", "admin_cookie",
              "car_x", "car_y", "timer")
USER_GROUPS = {"racer_a": ("racer",), "racer_b": ("racer",), "registration": ("registration",),
               "commentator": ("commentator",), "operator": ("operator",), "admin": ("admin",)}
CARS = ("car_x", "car_y")
TIMERS = ("timer",)
COOKIE_USERS = {"admin_cookie": ("admin",)}

def route_modules() -> list[Any]:
    """Every module of chalicelib.routes that defines a Blueprint `bp`."""
    import chalicelib.routes as package

    modules = [importlib.import_module(info.name)
               for info in pkgutil.walk_packages(package.__path__, prefix=f"{package.__name__}.")]
    return [module for module in modules if isinstance(getattr(module, "bp", None), Blueprint)]


def full_app(chalice_app: Any) -> Any:
    """The session app with every route module registered: app.py registers them; one it does not register yet
    (written, not wired) is registered here (once), so the matrix and the OpenAPI tests cover the whole API."""
    from chalicelib.core import principals

    registered = {entry.view_function.__module__ for by_method in chalice_app.routes.values()
                  for entry in by_method.values()}
    for module in route_modules():
        if module.__name__ not in registered:
            chalice_app.register_blueprint(module.bp)
    if principals._device_verifier is principals.reject_all_device_credentials:
        from chalicelib.routes import devices

        principals.set_device_credential_verifier(devices.verify_device_credential)
    return chalice_app


@dataclass
class Reply:
    status: int
    headers: dict[str, Any]
    body: bytes

    @property
    def json(self) -> Any:
        return json.loads(self.body) if self.body else None


@dataclass
class World:
    """The stack, the app client and the nine principals' request headers."""
    client: Client
    users: Users
    headers: dict[str, dict[str, str]] = field(default_factory=dict)
    usernames: dict[str, str] = field(default_factory=dict)
    device_ids: dict[str, str] = field(default_factory=dict)
    fleet_id: str = ""
    refused_scenarios: dict[tuple[str, str], Any] = field(default_factory=dict)  # see test_authz_matrix.scenario_for
    _minted: int = 0

    def call(self, method: str, path: str, principal: str, body: Any = None,
             headers: dict[str, str] | None = None, raw: bytes | None = None) -> Reply:
        """`body` goes as JSON; `raw` as the bytes they are (with its Content-Type in `headers`)."""
        all_headers = {**self.headers[principal], "Content-Type": "application/json", **(headers or {})}
        payload = raw if raw is not None else b"" if body is None else json.dumps(body).encode()
        response = getattr(self.client.http, method.lower())(path, headers=all_headers, body=payload)
        return Reply(response.status_code, dict(response.headers), response.body or b"")

    def ok(self, method: str, path: str, principal: str, body: Any = None) -> Any:
        """A set-up call that must succeed; its JSON reply."""
        reply = self.call(method, path, principal, body)
        assert reply.status < 300, f"set-up {method} {path} as {principal} failed: {reply.status} {reply.body[:300]!r}"
        return reply.json

    def sub_of(self, principal: str) -> str:
        return self.ok("GET", "/api/me", principal)["sub"]

    def mint(self, principal: str) -> str:
        """A new principal of the same kind as `principal` (for calls that use up their caller); its name."""
        self._minted += 1
        name = f"{principal}__{self._minted}"
        if principal in USER_GROUPS:
            self._add_user(name, USER_GROUPS[principal])
        elif principal in COOKIE_USERS:
            self._add_cookie_user(name, COOKIE_USERS[principal])
        elif principal in CARS:
            self._add_car(name)
        elif principal in TIMERS:
            self._add_car(name, "timer")
        else:
            self.headers[name] = dict(self.headers[principal])
        return name

    def _add_user(self, name: str, groups: tuple[str, ...]) -> None:
        username = name.replace("_", "-")
        self.headers[name] = bearer(self.users.access_token(username, groups))
        self.usernames[name] = username

    def _add_cookie_user(self, name: str, groups: tuple[str, ...]) -> None:
        """Signed in through the login form, as a browser: the matrix then sends its cookies and CSRF token."""
        username = name.replace("_", "-")
        self.users.create(username, groups)
        csrf = self.headers["anonymous"]["X-CSRF-Token"]
        reply = self.client.http.post("/login", headers={"Cookie": f"drem_csrf={csrf}",
                                                         "Content-Type": "application/x-www-form-urlencoded"},
                                      body=f"username={username}&password={PASSWORD}&csrf_token={csrf}".encode())
        assert reply.status_code == 303, reply.body
        cookies = dict(c.split(";", 1)[0].split("=", 1) for c in set_cookie_headers(reply.headers))
        jar = {k: cookies[k] for k in ("drem_session", "drem_refresh", "drem_csrf")}
        self.headers[name] = {"Accept": "application/json", "X-CSRF-Token": jar["drem_csrf"],
                              "Cookie": "; ".join(f"{k}={v}" for k, v in jar.items())}
        self.usernames[name] = username

    def _add_car(self, name: str, kind: str = "car") -> None:
        hostname = name.replace("_", "-")
        code = self.ok("POST", "/api/devices/activation-codes", "admin",
                       {"fleet_id": self.fleet_id, "hostname": hostname, "device_kind": kind})["code"]
        issued = self.ok("POST", "/api/devices/activate", "anonymous",
                         {"code": code, "hostname": hostname, "device_kind": kind})
        self.headers[name] = {"Authorization": f"Device {issued['credential']}", "Accept": "application/json"}
        self.device_ids[name] = issued["device_id"]


def _anonymous_headers() -> dict[str, str]:
    token = secrets.token_urlsafe(32)
    return {"Accept": "application/json", "Cookie": f"drem_csrf={token}", "X-CSRF-Token": token}


def build_world(chalice_app: Any, tmp_path_factory: pytest.TempPathFactory) -> Iterator[World]:
    """The `world` fixture's body (tests/unit/conftest.py): a stack, the full app and every principal, until the
    generator is closed."""
    patch = pytest.MonkeyPatch()
    aws = clients_for(None, REGION)
    outputs = ensure_stack(aws, STAGE)
    for name, value in outputs.to_env().items():
        patch.setenv(name, value)
    patch.delenv("DREM_PUBLIC_URL", raising=False)
    _reset_app_caches()
    app = full_app(chalice_app)
    try:
        with Client(app, project_dir=str(tmp_path_factory.mktemp("authz-no-chalice-config"))) as client:
            built = World(client, Users(aws, outputs), headers={"anonymous": _anonymous_headers()})
            for principal, groups in USER_GROUPS.items():
                built._add_user(principal, groups)
            built.fleet_id = built.ok("POST", "/api/fleets", "admin", {"name": "Matrix cars"})["fleet_id"]
            for car in CARS:
                built._add_car(car)
            built._add_car("timer", "timer")
            for principal, groups in COOKIE_USERS.items():
                built._add_cookie_user(principal, groups)
            yield built
    finally:
        patch.undo()
