"""The storage server's signature check, fed requests exactly as botocore signs them (botocore/auth.py signers).

Each request is signed by botocore itself, turned into the WSGI environ the server would see, and verified; then the
same request is altered the way an attacker would (other key, other body, other key name, expired) and must fail.
"""
from __future__ import annotations

import base64
import io
import json
from datetime import UTC, datetime, timedelta
from urllib.parse import urlsplit

import boto3
import pytest
from botocore.auth import S3SigV4Auth, SigV4Auth
from botocore.awsrequest import AWSRequest
from botocore.config import Config
from botocore.credentials import Credentials

from drem_local.durable.guard import GATEWAY_PATH, StorageGuard
from drem_local.durable.sigv4 import Refusal, Verified, verify
from drem_local.storage_keys import StorageKeys, generate

pytestmark = pytest.mark.unit

KEYS = generate()
HOST = "127.0.0.1:8001"


def environ_of(request: AWSRequest) -> tuple[dict, bytes]:
    """What werkzeug hands the WSGI app for `request` (RAW_URI is the request target as sent)."""
    parts = urlsplit(request.url)
    body = request.body or b""
    body = body.encode() if isinstance(body, str) else body
    environ = {"REQUEST_METHOD": request.method, "PATH_INFO": parts.path, "QUERY_STRING": parts.query,
               "RAW_URI": parts.path + (f"?{parts.query}" if parts.query else ""), "SERVER_NAME": "127.0.0.1",
               "SERVER_PORT": "8001", "HTTP_HOST": parts.netloc, "wsgi.input": io.BytesIO(body),
               "CONTENT_LENGTH": str(len(body))}
    for name, value in request.headers.items():
        value = value.decode() if isinstance(value, bytes) else value
        key = name.upper().replace("-", "_")
        environ[key if key in ("CONTENT_TYPE", "CONTENT_LENGTH") else f"HTTP_{key}"] = value
    return environ, body


def signed(signer_class=SigV4Auth, service: str = "dynamodb", keys: StorageKeys = KEYS, *, method: str = "POST",
           path: str = "/", body: bytes = b'{"TableName": "laps"}', headers: dict | None = None) -> AWSRequest:
    request = AWSRequest(method=method, url=f"http://{HOST}{path}", data=body,
                         headers={"X-Amz-Target": "DynamoDB_20120810.GetItem",
                                  "Content-Type": "application/x-amz-json-1.0", **(headers or {})})
    signer_class(Credentials(keys.access_key_id, keys.secret_access_key), service, "us-east-1").add_auth(request)
    return request


def s3(keys: StorageKeys = KEYS, endpoint: str = f"http://{HOST}"):
    return boto3.client("s3", endpoint_url=endpoint, region_name="us-east-1", **keys.boto_kwargs(),
                        config=Config(signature_version="s3v4", s3={"addressing_style": "path"}))


def presigned_environ(url: str, method: str = "GET") -> tuple[dict, bytes]:
    return environ_of(AWSRequest(method=method, url=url, headers={}))


def post_form_environ(post: dict, content: bytes = b"model bytes") -> tuple[dict, bytes]:
    boundary = "drem-test-boundary"
    lines = []
    for name, value in post["fields"].items():
        lines += [f"--{boundary}", f'Content-Disposition: form-data; name="{name}"', "", value]
    text = "\r\n".join(lines).encode()
    body = text + (f"\r\n--{boundary}\r\nContent-Disposition: form-data; name=\"file\"; filename=\"m.tar.gz\"\r\n"
                   f"Content-Type: application/gzip\r\n\r\n").encode() + content + f"\r\n--{boundary}--\r\n".encode()
    request = AWSRequest(method="POST", url=post["url"], data=body,
                         headers={"Content-Type": f"multipart/form-data; boundary={boundary}"})
    return environ_of(request)


def test_a_request_botocore_signed_with_the_installation_keys_is_accepted():
    environ, body = environ_of(signed())
    assert verify(environ, body, KEYS) == Verified("header", "dynamodb")


def test_s3_header_signatures_with_encoded_keys_and_queries_are_accepted():
    request = signed(S3SigV4Auth, "s3", method="PUT", path="/models/uploads/sub%201/a%2Bb.tar.gz?tagging=",
                     body=b"archive", headers={"X-Amz-Content-SHA256": "UNSIGNED-PAYLOAD"})
    environ, body = environ_of(request)
    assert verify(environ, body, KEYS) == Verified("header", "s3")


def test_an_unsigned_request_is_refused():
    environ, body = environ_of(AWSRequest(method="POST", url=f"http://{HOST}/", data=b"{}",
                                          headers={"X-Amz-Target": "DynamoDB_20120810.Scan"}))
    refusal = verify(environ, body, KEYS)
    assert isinstance(refusal, Refusal) and refusal.status == 403 and "signed" in refusal.message


def test_a_signature_made_with_other_keys_is_refused():
    stranger = verify(*environ_of(signed(keys=generate())), KEYS)
    assert isinstance(stranger, Refusal) and stranger.code == "InvalidAccessKeyId"
    guessed_secret = StorageKeys(KEYS.access_key_id, "not-the-secret")
    forged = verify(*environ_of(signed(keys=guessed_secret)), KEYS)
    assert isinstance(forged, Refusal) and forged.code == "SignatureDoesNotMatch"


def test_a_signed_request_with_another_body_is_refused():
    request = signed()
    environ, _body = environ_of(request)
    refusal = verify(environ, b'{"TableName": "users"}', KEYS)
    assert isinstance(refusal, Refusal) and refusal.code == "SignatureDoesNotMatch"
    s3_request = signed(S3SigV4Auth, "s3", method="PUT", path="/b/k", body=b"original")
    environ, _body = environ_of(s3_request)
    refusal = verify(environ, b"replaced", KEYS)
    assert isinstance(refusal, Refusal) and refusal.code == "XAmzContentSHA256Mismatch"


def test_a_replayed_header_signature_older_than_15_minutes_is_refused():
    environ, body = environ_of(signed())
    refusal = verify(environ, body, KEYS, now=datetime.now(UTC) + timedelta(minutes=16))
    assert isinstance(refusal, Refusal) and refusal.code == "RequestTimeTooSkewed"


def test_a_presigned_get_works_until_it_expires():
    url = s3().generate_presigned_url("get_object", Params={"Bucket": "models", "Key": "models/a b+c.tar.gz"},
                                      ExpiresIn=60)
    environ, body = presigned_environ(url)
    assert verify(environ, body, KEYS) == Verified("query", "s3")
    expired = verify(environ, body, KEYS, now=datetime.now(UTC) + timedelta(seconds=61))
    assert isinstance(expired, Refusal) and "expired" in expired.message


def test_a_presigned_get_for_another_key_or_with_longer_expiry_is_refused():
    url = s3().generate_presigned_url("get_object", Params={"Bucket": "models", "Key": "models/mine.tar.gz"},
                                      ExpiresIn=60)
    for altered in (url.replace("models/mine", "models/theirs"), url.replace("X-Amz-Expires=60", "X-Amz-Expires=600")):
        refusal = verify(*presigned_environ(altered), KEYS)
        assert isinstance(refusal, Refusal) and refusal.code == "SignatureDoesNotMatch", altered


def test_a_presigned_post_form_is_accepted_until_its_policy_expires():
    post = s3().generate_presigned_post("models", "uploads/sub/m.tar.gz", ExpiresIn=60,
                                        Conditions=[["content-length-range", 1, 1000]])
    environ, body = post_form_environ(post)
    assert verify(environ, body, KEYS) == Verified("post", "s3")
    expired = verify(environ, body, KEYS, now=datetime.now(UTC) + timedelta(seconds=61))
    assert isinstance(expired, Refusal) and "expired" in expired.message


def test_a_presigned_post_with_a_rewritten_policy_is_refused():
    post = s3().generate_presigned_post("models", "uploads/sub/m.tar.gz", ExpiresIn=60)
    policy = json.loads(base64.b64decode(post["fields"]["policy"]))
    policy["expiration"] = "2099-01-01T00:00:00Z"
    post["fields"]["policy"] = base64.b64encode(json.dumps(policy).encode()).decode()
    refusal = verify(*post_form_environ(post), KEYS)
    assert isinstance(refusal, Refusal) and refusal.code == "SignatureDoesNotMatch"


def test_a_post_form_signed_with_other_keys_is_refused():
    post = s3(generate()).generate_presigned_post("models", "uploads/sub/m.tar.gz", ExpiresIn=60)
    refusal = verify(*post_form_environ(post), KEYS)
    assert isinstance(refusal, Refusal) and refusal.code == "InvalidAccessKeyId"


# --- the guard in front of moto -----------------------------------------------------------------------------------

def test_moto_admin_api_and_cors_preflights_are_refused_even_when_signed():
    guard = StorageGuard(KEYS)
    for method, path in (("GET", "/moto-api/data.json"), ("POST", "/moto-api/reset"), ("GET", "/moto-api/")):
        request = signed(SigV4Auth, "s3", method=method, path=path, body=b"")
        refusal = guard.check(*environ_of(request))
        assert isinstance(refusal, Refusal) and refusal.status == 404, path
    preflight = AWSRequest(method="OPTIONS", url=f"http://{HOST}/models/k", headers={"Origin": "http://evil.test"})
    refusal = guard.check(*environ_of(preflight))
    assert isinstance(refusal, Refusal) and refusal.status == 403


def test_the_gateway_passes_presigned_links_only_and_hands_moto_the_plain_path():
    guard = StorageGuard(KEYS)
    venue = "http://192.168.10.5:8000" + GATEWAY_PATH
    url = s3(endpoint=venue).generate_presigned_url("get_object", Params={"Bucket": "models", "Key": "models/a.tar.gz"},
                                                    ExpiresIn=60)
    environ, body = presigned_environ(url)
    assert guard.check(environ, body) is None
    assert environ["PATH_INFO"] == "/models/models/a.tar.gz" and environ["HTTP_HOST"] == "127.0.0.1:8001"
    assert environ["RAW_URI"].startswith("/models/models/a.tar.gz?X-Amz-Algorithm=")

    header_signed = signed(S3SigV4Auth, "s3", method="GET", path=GATEWAY_PATH + "/models/models/a.tar.gz", body=b"")
    refusal = guard.check(*environ_of(header_signed))
    assert isinstance(refusal, Refusal) and "presigned" in refusal.message


def test_a_user_pool_jwks_stays_public_as_on_aws():
    guard = StorageGuard(KEYS)
    jwks = AWSRequest(method="GET", url=f"http://{HOST}/us-east-1_abc123/.well-known/jwks.json", headers={})
    assert guard.check(*environ_of(jwks)) is None
    users = AWSRequest(method="GET", url=f"http://{HOST}/us-east-1_abc123/users", headers={})
    assert isinstance(guard.check(*environ_of(users)), Refusal)


def test_the_app_presigns_for_the_gateway_path_the_storage_server_strips():
    from chalicelib.storage.clients import STORAGE_GATEWAY_PATH

    assert STORAGE_GATEWAY_PATH == GATEWAY_PATH
