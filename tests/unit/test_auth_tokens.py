"""Bearer tokens: real tokens from the (patched) local Cognito are accepted with their groups; every forgery is
refused with 401, above all a token minted with the RSA key that ships inside moto."""
from __future__ import annotations

import gzip
import hashlib
import hmac
import json
import time
from importlib import resources as package_resources
from typing import Any

import pytest
from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric import rsa
from jose import jwk, jwt

from tests.unit.conftest import b64url, bearer, jwt_parts

pytestmark = pytest.mark.unit

ADMIN_ONLY = "/api/users/{username}/groups"


def _moto_jwks(kind: str) -> dict[str, Any]:
    data = package_resources.files("moto.cognitoidp").joinpath(f"resources/jwks-{kind}.json.gz").read_bytes()
    return json.loads(gzip.decompress(data))


def _moto_private_key() -> dict[str, Any]:
    # A single JWK (the public file is a JWKS): the key every moto user pool signs with.
    return _moto_jwks("private")


def _sign_with_moto_key(claims: dict[str, Any], kid: str | None = None) -> str:
    key = _moto_private_key()
    return jwt.encode(claims, key, algorithm="RS256", headers={"kid": kid or key["kid"]})


@pytest.fixture
def sign_with_installation_key(installation_key_file):
    key = json.loads(installation_key_file.read_text())

    def sign(claims: dict[str, Any]) -> str:
        return jwt.encode(claims, key, algorithm="RS256", headers={"kid": key["kid"]})

    return sign


def _claims_of(token: str, **changes: Any) -> dict[str, Any]:
    _, claims, _ = jwt_parts(token)
    claims.update(changes)
    return claims


@pytest.fixture
def racer_token(users) -> str:
    return users.access_token("rita", ("racer",))


@pytest.fixture
def admin_token(users) -> str:
    return users.access_token("ada", ("admin",))


def test_real_access_token_is_accepted_with_its_groups(client, racer_token):
    response = client.http.get("/api/me", headers=bearer(racer_token))

    assert response.status_code == 200
    assert response.json_body["username"] == "rita"
    assert response.json_body["roles"] == ["racer"]


def test_admin_token_reaches_admin_route_and_racer_token_gets_403(client, users, admin_token, racer_token):
    path = ADMIN_ONLY.format(username="rita")

    as_admin = client.http.get(path, headers=bearer(admin_token))
    as_racer = client.http.get(path, headers=bearer(racer_token))

    assert as_admin.status_code == 200
    assert as_admin.json_body == {"username": "rita", "groups": ["racer"]}
    assert as_racer.status_code == 403
    assert as_racer.json_body["error"]["code"] == "Forbidden"


def test_admin_asking_for_an_unknown_user_gets_404_naming_the_field(client, admin_token):
    response = client.http.get(ADMIN_ONLY.format(username="ghost"), headers=bearer(admin_token))

    assert response.status_code == 404
    assert response.json_body["error"]["field"] == "username"


def test_token_signed_by_the_installation_key_with_our_claims_is_accepted(client, racer_token,
                                                                          sign_with_installation_key):
    # Control for the forgeries below: the same signing machinery with honest claims must pass.
    token = sign_with_installation_key(_claims_of(racer_token, exp=int(time.time()) + 600))

    assert client.http.get("/api/me", headers=bearer(token)).status_code == 200


def test_local_cognito_signs_with_the_installation_key_not_motos(racer_token, installation_key_file):
    header, _, _ = jwt_parts(racer_token)
    assert header["kid"] == json.loads(installation_key_file.read_text())["kid"]
    assert header["kid"] != _moto_private_key()["kid"]


@pytest.mark.parametrize("kid", ["moto's own kid", "the installation's kid"])
def test_admin_token_minted_with_motos_shipped_key_is_refused(client, racer_token, installation_key_file, kid):
    # The attack: copy iss/client_id/sub from your own racer token, add the admin group, sign with the key every
    # moto install ships (moto/cognitoidp/resources/jwks-private.json).
    installation_kid = json.loads(installation_key_file.read_text())["kid"]
    forged = _sign_with_moto_key(_claims_of(racer_token, **{"cognito:groups": ["admin"]}),
                                 kid=installation_kid if kid == "the installation's kid" else None)

    for path in ("/api/me", ADMIN_ONLY.format(username="rita")):
        response = client.http.get(path, headers=bearer(forged))
        assert response.status_code == 401, (path, response.body)


def test_local_jwks_publishes_only_the_installation_key(aws_clients, stack, installation_key_file):
    import requests

    published = requests.get(f"https://cognito-idp.us-east-1.amazonaws.com/{stack.user_pool_id}"
                             "/.well-known/jwks.json", timeout=5).json()["keys"]
    assert [k["kid"] for k in published] == [json.loads(installation_key_file.read_text())["kid"]]
    assert "d" not in published[0]


def test_on_aws_the_pools_jwks_decides(aws_mode, client, users):
    token = users.access_token("awsuser", ("racer",))

    assert client.http.get("/api/me", headers=bearer(token)).status_code == 200
    forged = _sign_with_moto_key(_claims_of(token, **{"cognito:groups": ["admin"]}))
    assert client.http.get("/api/me", headers=bearer(forged)).status_code == 401


def _alg_none(token: str) -> str:
    header, claims, _ = jwt_parts(token)
    header["alg"] = "none"
    claims["cognito:groups"] = ["admin"]
    return f"{b64url(json.dumps(header).encode())}.{b64url(json.dumps(claims).encode())}."


def _hs256_with_public_key(token: str) -> str:
    # The classic key-confusion attack; python-jose refuses PEM HMAC keys, so sign by hand.
    public_pem = jwk.construct(_moto_jwks("public")["keys"][0], "RS256").to_pem()
    header = b64url(json.dumps({"alg": "HS256", "typ": "JWT", "kid": "dummy"}).encode())
    payload = b64url(json.dumps(_claims_of(token, **{"cognito:groups": ["admin"]})).encode())
    signature = hmac.new(public_pem, f"{header}.{payload}".encode(), hashlib.sha256).digest()
    return f"{header}.{payload}.{b64url(signature)}"


def _wrong_key(token: str) -> str:
    private = rsa.generate_private_key(public_exponent=65537, key_size=2048)
    pem = private.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                                serialization.NoEncryption())
    return jwt.encode(_claims_of(token, **{"cognito:groups": ["admin"]}), pem, algorithm="RS256",
                      headers={"kid": "dummy"})


def _sign_with_test_installation_key(claims: dict[str, Any]) -> str:
    from chalicelib.settings import get_settings

    key = json.loads(get_settings().token_key_file.read_text())
    return jwt.encode(claims, key, algorithm="RS256", headers={"kid": key["kid"]})


def _expired(token: str) -> str:
    now = int(time.time())
    return _sign_with_test_installation_key(_claims_of(token, iat=now - 7200, exp=now - 3600))


def _wrong_issuer(token: str) -> str:
    return _sign_with_test_installation_key(
        _claims_of(token, iss="https://cognito-idp.us-east-1.amazonaws.com/us-east-1_Other"))


def _wrong_client(token: str) -> str:
    return _sign_with_test_installation_key(_claims_of(token, client_id="some-other-app-client"))


def _installation_kid_other_key(token: str) -> str:
    private = rsa.generate_private_key(public_exponent=65537, key_size=2048)
    pem = private.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                                serialization.NoEncryption())
    kid = jwt_parts(token)[0]["kid"]
    return jwt.encode(_claims_of(token, **{"cognito:groups": ["admin"]}), pem, algorithm="RS256",
                      headers={"kid": kid})


def _groups_edited(token: str) -> str:
    header, payload, signature = token.split(".")
    claims = jwt_parts(token)[1]
    claims["cognito:groups"] = ["admin"]
    return f"{header}.{b64url(json.dumps(claims).encode())}.{signature}"


# forgery → the check that must catch it (asserted, so a forgery cannot pass by failing somewhere else)
FORGERIES = {
    "alg none": (_alg_none, "not signed with RS256"),
    "HS256 signed with the public key": (_hs256_with_public_key, "not signed with RS256"),
    "signed with another RSA key": (_wrong_key, "unknown key"),
    "another RSA key under our kid": (_installation_kid_other_key, "Signature verification failed"),
    "expired": (_expired, "expired"),
    "wrong issuer": (_wrong_issuer, "Invalid issuer"),
    "wrong client_id": (_wrong_client, "another app client"),
    "cognito:groups edited": (_groups_edited, "Signature verification failed"),
    "garbage": (lambda token: "not-a-jwt", "not a JWT"),
}


@pytest.mark.parametrize(("forge", "reason"), FORGERIES.values(), ids=FORGERIES.keys())
def test_forged_tokens_are_refused_with_401(client, racer_token, forge, reason):
    forged = forge(racer_token)

    for path in ("/api/me", ADMIN_ONLY.format(username="rita")):
        response = client.http.get(path, headers=bearer(forged))
        assert response.status_code == 401, (path, response.body)
        assert response.headers["WWW-Authenticate"] == "Bearer"
        assert reason in response.json_body["error"]["message"]


def test_id_token_is_refused_where_an_access_token_is_required(client, users):
    users.create("ivan", ("admin",))
    id_token = users.sign_in("ivan")["IdToken"]

    response = client.http.get("/api/me", headers=bearer(id_token))

    assert response.status_code == 401
    assert "access token" in response.json_body["error"]["message"]


def test_token_for_another_audience_in_an_id_token_is_refused(client, users):
    # Id tokens carry `aud`; one minted for another client must not pass the id-token check either.
    from chalicelib.auth.tokens import verify_token
    from chalicelib.core.errors import NotAuthenticated
    from chalicelib.settings import get_settings

    users.create("ivy", ("racer",))
    id_token = users.sign_in("ivy")["IdToken"]
    forged = _sign_with_test_installation_key(_claims_of(id_token, aud="some-other-app-client"))

    assert verify_token(id_token, get_settings(), token_use="id").username == "ivy"
    with pytest.raises(NotAuthenticated):
        verify_token(forged, get_settings(), token_use="id")


@pytest.mark.parametrize("header", ["", "Bearer", "Bearer ", "Basic dXNlcjpwYXNz", "Token abc"])
def test_missing_or_malformed_authorization_is_401(client, header):
    headers = {"Accept": "application/json"}
    if header:
        headers["Authorization"] = header

    response = client.http.get("/api/me", headers=headers)

    assert response.status_code == 401


def test_device_credentials_are_refused_until_devices_exist(client):
    response = client.http.get("/api/me", headers={"Authorization": "Device car-1:secret"})

    assert response.status_code == 401
