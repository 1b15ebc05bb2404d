"""The per-installation token signing key, on real durable servers and the live stack: made at the first start
(0600), kept across restarts, the only key local tokens are signed with and verified against."""
from __future__ import annotations

import gzip
import json
import stat
import time
import urllib.request
from importlib import resources as package_resources

import pytest
from jose import jwt

from drem_infra.resources import TOKEN_SIGNING_KEY_FILE

pytestmark = pytest.mark.integration

PASSWORD = "Correct-Horse-9"


def _pool_with_user(clients) -> tuple[str, str]:
    pool = clients.cognito.create_user_pool(PoolName="drem-keytest-users")["UserPool"]["Id"]
    client_id = clients.cognito.create_user_pool_client(
        UserPoolId=pool, ClientName="web", ExplicitAuthFlows=["ALLOW_USER_PASSWORD_AUTH",
                                                              "ALLOW_REFRESH_TOKEN_AUTH"])["UserPoolClient"]["ClientId"]
    clients.cognito.admin_create_user(UserPoolId=pool, Username="ada", TemporaryPassword=PASSWORD,
                                      MessageAction="SUPPRESS")
    clients.cognito.admin_set_user_password(UserPoolId=pool, Username="ada", Password=PASSWORD, Permanent=True)
    return pool, client_id


def _sign_in(clients, client_id: str) -> str:
    return clients.cognito.initiate_auth(AuthFlow="USER_PASSWORD_AUTH", ClientId=client_id, AuthParameters={
        "USERNAME": "ada", "PASSWORD": PASSWORD})["AuthenticationResult"]["AccessToken"]


def _verify(token: str, key_file, pool: str, client_id: str):
    from chalicelib.auth.tokens import PINNED, verify_token
    from chalicelib.settings import Settings

    PINNED.clear()
    settings = Settings(region="us-east-1", user_pool_id=pool, user_pool_client_id=client_id,
                        token_key_file=key_file)
    return verify_token(token, settings)


def test_the_key_is_made_at_first_start_private_and_kept_across_restarts(durable_server_factory):
    server = durable_server_factory.start("key")
    key_file = server.state_dir / TOKEN_SIGNING_KEY_FILE
    assert stat.S_IMODE(key_file.stat().st_mode) == 0o600
    first = json.loads(key_file.read_text())
    pool, client_id = _pool_with_user(server.clients())
    before = _sign_in(server.clients(), client_id)

    server.restart()

    assert json.loads(key_file.read_text()) == first
    after = _sign_in(server.clients(), client_id)  # real sign-in still works, with the same key
    assert _verify(after, key_file, pool, client_id).username == "ada"
    assert _verify(before, key_file, pool, client_id).username == "ada"  # sessions survive the restart
    published = json.loads(urllib.request.urlopen(f"{server.url}/{pool}/.well-known/jwks.json", timeout=5).read())
    assert [k["kid"] for k in published["keys"]] == [first["kid"]] and "d" not in published["keys"][0]


def test_two_installations_have_different_keys(durable_server_factory):
    one, two = durable_server_factory.start("one"), durable_server_factory.start("two")

    kid = [json.loads((s.state_dir / TOKEN_SIGNING_KEY_FILE).read_text())["kid"] for s in (one, two)]

    assert kid[0] != kid[1]


def test_the_live_app_refuses_an_admin_token_minted_with_motos_shipped_key(live_stack):
    cognito = live_stack.client("cognito-idp")
    real = cognito.initiate_auth(ClientId=live_stack.outputs.user_pool_client_id, AuthFlow="USER_PASSWORD_AUTH",
                                 AuthParameters={"USERNAME": live_stack.admin_username,
                                                 "PASSWORD": live_stack.admin_password})
    token = real["AuthenticationResult"]["AccessToken"]
    claims = jwt.get_unverified_claims(token)
    moto_key = json.loads(gzip.decompress(package_resources.files("moto.cognitoidp").joinpath(
        "resources/jwks-private.json.gz").read_bytes()))
    forged = jwt.encode({**claims, "exp": int(time.time()) + 600}, moto_key, algorithm="RS256",
                        headers={"kid": jwt.get_unverified_header(token)["kid"]})

    def me(bearer: str) -> int:
        request = urllib.request.Request(f"{live_stack.url}/api/me", headers={"Authorization": f"Bearer {bearer}"})
        try:
            return urllib.request.build_opener(urllib.request.ProxyHandler({})).open(request, timeout=10).status
        except urllib.error.HTTPError as exc:
            return exc.code

    assert me(token) == 200
    assert me(forged) == 401
