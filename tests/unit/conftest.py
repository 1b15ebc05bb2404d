"""Unit-test fixtures: ONE in-process moto (`mock_aws`) for the whole run, wiped before every test, plus the drem
stack bootstrapped from `drem_infra.resources`, a Chalice test client, and helpers for users with real moto tokens.

Every fixture the unit tests share lives here (test modules import helper classes and functions, never fixtures):
the API drivers `desk`, `api`, `console`, `alice` and `scenario` (their classes are in race_helpers, device_api,
operator_console_helpers, models_helpers and scenario), the fake server `clock`, and `world` for the modules marked
`one_stack_per_module`.

moto is patched the way the durable server patches it (drem_local.durable.token_signing): every pool signs with a
per-session installation key, the app pins that key (DREM_TOKEN_KEY_FILE), sign-up codes never match and the
new-password session is bound to its user. `aws_mode` turns the pinning off to exercise the AWS (JWKS) path.

Wiping uses `BackendDict.reset()`, not `mock_aws().reset()`: the latter also drops moto's interception of `requests`
calls, after which the app's JWKS fetch would try the real internet.
"""
from __future__ import annotations

import base64
import json
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest
from chalice.test import Client
from moto import mock_aws
from moto.core.base_backend import BackendDict

from drem_infra.resources import TOKEN_SIGNING_KEY_ENV
from drem_local.bootstrap import StackOutputs, clients_for
from tests.unit.stack_snapshot import fresh_stack

if TYPE_CHECKING:
    from tests.unit.authz_principals import World
    from tests.unit.device_api import Api
    from tests.unit.models_helpers import ModelsApi
    from tests.unit.operator_console_helpers import Console
    from tests.unit.race_helpers import Desk, FakeClock
    from tests.unit.scenario import Scenario

STAGE = "test"
REGION = "us-east-1"
# Meets the pool's password policy (drem_infra.resources.PasswordPolicy).
PASSWORD = "Correct-Horse-9"
# The marker of modules whose tests share one stack (see module_wipe and world at the end of this file).
ONE_STACK_PER_MODULE = "one_stack_per_module"


def _reset_app_caches() -> None:
    from chalicelib.auth import rate_limits
    from chalicelib.auth.revocation import REVOKED
    from chalicelib.auth.tokens import JWKS, PINNED
    from chalicelib.domain.league_board_cache import PROCESS_LEAGUE_BOARDS
    from chalicelib.domain.shown_names_cache import PROCESS_SHOWN_NAMES
    from chalicelib.settings import get_settings
    from chalicelib.storage.clients import reset_clients

    get_settings.cache_clear()
    reset_clients()
    PROCESS_SHOWN_NAMES.clear()
    PROCESS_LEAGUE_BOARDS.clear()
    JWKS.clear()
    PINNED.clear()
    REVOKED.clear()
    for window in rate_limits.ALL:
        window.clear()


@pytest.fixture(scope="session")
def installation_key_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from drem_local.token_key import ensure_signing_key, key_path

    state_dir = tmp_path_factory.mktemp("installation")
    ensure_signing_key(state_dir)
    return key_path(state_dir)


@pytest.fixture(scope="session", autouse=True)
def moto_session(installation_key_file: Path) -> Iterator[None]:
    from drem_local.durable import token_signing

    mock = mock_aws()
    mock.start()
    token_signing.install(json.loads(installation_key_file.read_text()))
    yield
    token_signing.uninstall()
    mock.stop()


@pytest.fixture(autouse=True)
def fresh_moto(request: pytest.FixtureRequest, moto_session: None) -> Iterator[None]:
    if request.node.get_closest_marker(ONE_STACK_PER_MODULE) is not None:
        yield  # module_wipe wiped once for the whole module
        return
    BackendDict.reset()
    _reset_app_caches()
    yield
    _reset_app_caches()


@pytest.fixture
def aws_clients() -> Any:
    return clients_for(None, REGION)


@pytest.fixture
def stack(aws_clients: Any, monkeypatch: pytest.MonkeyPatch, installation_key_file: Path) -> StackOutputs:
    """Tables, buckets, user pool, app client and groups, with the app's env pointing at them (tokens pinned to the
    installation key, as a local stack runs). Bootstrapped once per process, then restored from a copy
    (tests/unit/stack_snapshot.py)."""
    outputs = fresh_stack(aws_clients, STAGE)
    for name, value in outputs.to_env().items():
        monkeypatch.setenv(name, value)
    monkeypatch.setenv(TOKEN_SIGNING_KEY_ENV, str(installation_key_file))
    monkeypatch.delenv("DREM_PUBLIC_URL", raising=False)
    monkeypatch.delenv("DREM_BASE_PATH", raising=False)
    _reset_app_caches()
    return outputs


@pytest.fixture
def aws_mode(stack: StackOutputs, monkeypatch: pytest.MonkeyPatch) -> StackOutputs:
    """The app as deployed on AWS: no pinned key, the pool's JWKS (served by moto) decides."""
    monkeypatch.delenv(TOKEN_SIGNING_KEY_ENV)
    _reset_app_caches()
    return stack


@pytest.fixture(scope="session")
def chalice_app() -> Any:
    from app import app

    return app


@pytest.fixture
def client(stack: StackOutputs, chalice_app: Any, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Client]:
    # An empty project dir: the stage env vars in .chalice/config.json would override the test stack's names.
    with Client(chalice_app, project_dir=str(tmp_path_factory.mktemp("no-chalice-config"))) as test_client:
        yield test_client


@dataclass
class Users:
    """Creates Cognito users in groups and signs them in, returning moto's real tokens."""
    clients: Any
    outputs: StackOutputs

    def create(self, username: str, groups: tuple[str, ...] = (), password: str = PASSWORD,
               temporary: bool = False) -> str:
        cognito, pool = self.clients.cognito, self.outputs.user_pool_id
        cognito.admin_create_user(UserPoolId=pool, Username=username, TemporaryPassword=password,
                                  MessageAction="SUPPRESS",
                                  UserAttributes=[{"Name": "email", "Value": f"{username}@example.test"}])
        if not temporary:
            cognito.admin_set_user_password(UserPoolId=pool, Username=username, Password=password, Permanent=True)
        for group in groups:
            cognito.admin_add_user_to_group(UserPoolId=pool, Username=username, GroupName=group)
        return username

    def sign_in(self, username: str, password: str = PASSWORD) -> dict[str, Any]:
        reply = self.clients.cognito.initiate_auth(
            AuthFlow="USER_PASSWORD_AUTH", ClientId=self.outputs.user_pool_client_id,
            AuthParameters={"USERNAME": username, "PASSWORD": password})
        return reply["AuthenticationResult"]

    def access_token(self, username: str, groups: tuple[str, ...] = ()) -> str:
        self.create(username, groups)
        return self.sign_in(username)["AccessToken"]


@pytest.fixture
def users(aws_clients: Any, stack: StackOutputs) -> Users:
    return Users(aws_clients, stack)


def bearer(token: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}", "Accept": "application/json"}


def set_cookie_headers(headers: Mapping[str, Any]) -> list[str]:
    for name, value in headers.items():
        if name.lower() == "set-cookie":
            return [value] if isinstance(value, str) else list(value)
    return []


def cookie_attributes(headers: Mapping[str, Any], name: str) -> dict[str, str] | None:
    """The Set-Cookie for `name` as {"value": ..., "path": ..., "samesite": ..., "httponly": "", ...}."""
    for header in set_cookie_headers(headers):
        first, *attributes = [part.strip() for part in header.split(";")]
        cookie_name, _, value = first.partition("=")
        if cookie_name == name:
            parsed = {"value": value}
            for attribute in attributes:
                key, _, attribute_value = attribute.partition("=")
                parsed[key.lower()] = attribute_value
            return parsed
    return None


@dataclass
class Browser:
    """A cookie jar over the Chalice test client, behaving like a browser that honours Max-Age=0 deletions."""
    client: Client
    cookies: dict[str, str] = field(default_factory=dict)

    def request(self, method: str, path: str, *, form: Mapping[str, str | list[str]] | None = None,
                headers: Mapping[str, str] | None = None) -> Any:
        all_headers = {"Accept": "text/html", **(headers or {})}
        if self.cookies:
            all_headers["Cookie"] = "; ".join(f"{k}={v}" for k, v in self.cookies.items())
        body = b""
        if form is not None:
            from urllib.parse import urlencode

            body = urlencode(form, doseq=True).encode()  # a list is a repeated field, as checkboxes send it
            all_headers["Content-Type"] = "application/x-www-form-urlencoded"
        response = getattr(self.client.http, method.lower())(path, headers=all_headers, body=body)
        for header in set_cookie_headers(response.headers):
            first, *attributes = [part.strip() for part in header.split(";")]
            name, _, value = first.partition("=")
            if "Max-Age=0" in attributes or value == "":
                self.cookies.pop(name, None)
            else:
                self.cookies[name] = value
        return response

    def get(self, path: str, **kwargs: Any) -> Any:
        return self.request("GET", path, **kwargs)

    def post(self, path: str, form: Mapping[str, str | list[str]] | None = None, **kwargs: Any) -> Any:
        return self.request("POST", path, form=form, **kwargs)

    @property
    def csrf_token(self) -> str:
        return self.cookies["drem_csrf"]


@pytest.fixture
def browser(client: Client) -> Browser:
    return Browser(client)


def jwt_parts(token: str) -> tuple[dict[str, Any], dict[str, Any], str]:
    header, payload, signature = token.split(".")
    return _b64json(header), _b64json(payload), signature


def _b64json(segment: str) -> dict[str, Any]:
    return json.loads(base64.urlsafe_b64decode(segment + "=" * (-len(segment) % 4)))


def b64url(data: bytes) -> str:
    return base64.urlsafe_b64encode(data).rstrip(b"=").decode()


# --- The API as the tests drive it. app.py registers every blueprint and the real device-credential verifier; the
# classes behind these fixtures (Desk, Api, Console, ModelsApi, World) live in the helper modules named. ---

@pytest.fixture
def device_verifier() -> Iterator[None]:
    """The real device-credential verifier, whatever an earlier test left installed (and put back afterwards)."""
    from chalicelib.core import principals
    from chalicelib.routes.devices import verify_device_credential

    previous = principals._device_verifier
    principals.set_device_credential_verifier(verify_device_credential)
    yield
    principals.set_device_credential_verifier(previous)


@pytest.fixture
def clock(monkeypatch: pytest.MonkeyPatch) -> FakeClock:
    """The server clock, moved by hand so manual lap times are exact."""
    from chalicelib import services
    from tests.unit.race_helpers import FakeClock

    fake = FakeClock()
    monkeypatch.setattr(services, "now_ms", fake)
    return fake


@pytest.fixture
def desk(client: Client, users: Users, device_verifier: None) -> Desk:
    """race_helpers.Desk: the race/timing/leaderboard API driven as operator "op" and as activated devices."""
    from tests.unit.race_helpers import Desk

    desk = Desk(client, users)
    desk.token("op", "operator")
    return desk


@pytest.fixture
def scenario(desk: Desk, clock: FakeClock) -> Scenario:
    """scenario.Scenario: racers, a fleet with a timer, an event and races with laps, built through the API."""
    from tests.unit.scenario import Scenario

    return Scenario(desk, clock)


@pytest.fixture
def api(client: Client, users: Users, device_verifier: None) -> Api:
    """device_api.Api: the events/fleets/devices API as staff of any role (`as_=`) or as a device."""
    from tests.unit.device_api import Api

    return Api(client, users)


@pytest.fixture
def console(client: Client, users: Users, device_verifier: None) -> Console:
    """operator_console_helpers.Console: a browser on the operator console plus a desk for setting things up."""
    from tests.unit.operator_console_helpers import Console
    from tests.unit.race_helpers import Desk

    desk = Desk(client, users)
    desk.token("op", "operator")
    return Console(desk, Browser(client), users)


@pytest.fixture
def alice(client: Client, users: Users) -> ModelsApi:
    """The racer "alice" on the models API (models_helpers.ModelsApi)."""
    from tests.unit.models_helpers import ModelsApi

    return ModelsApi(client, bearer(users.access_token("alice", ("racer",))))


# --- One stack per module (marker `one_stack_per_module`): for the authorization matrix and the route fuzz, which
# make hundreds of calls as the principals of `world`; bootstrapping a stack per test would take minutes. ---

def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", f"{ONE_STACK_PER_MODULE}: wipe moto once per module, not before every test "
                                       "(the module's tests share the `world` fixture's principals)")


@pytest.fixture(scope="module", autouse=True)
def module_wipe(request: pytest.FixtureRequest, moto_session: None) -> Iterator[None]:
    if request.node.get_closest_marker(ONE_STACK_PER_MODULE) is None:
        yield
        return
    BackendDict.reset()
    _reset_app_caches()
    yield
    BackendDict.reset()
    _reset_app_caches()


@pytest.fixture(scope="module")
def world(request: pytest.FixtureRequest, module_wipe: None, chalice_app: Any,
          tmp_path_factory: pytest.TempPathFactory) -> Iterator[World]:
    """authz_principals.World: the stack, the app and the eleven principals with real credentials."""
    from tests.unit.authz_principals import build_world

    if request.node.get_closest_marker(ONE_STACK_PER_MODULE) is None:
        pytest.fail(f"`world` lives for a module: mark the module `pytest.mark.{ONE_STACK_PER_MODULE}`")

    yield from build_world(chalice_app, tmp_path_factory)
