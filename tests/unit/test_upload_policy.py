"""The local storage server enforces a presigned POST's signed policy as S3 does (moto alone ignores it): the real
DurableApp in front of real moto, with policies signed by botocore's own presigner. A racer holding one upload
ticket must not be able to write another key, a bigger file, or anything at all without a valid signature."""
from __future__ import annotations

import base64
import json
from datetime import UTC, datetime, timedelta

import boto3
import pytest
import requests
from botocore.config import Config
from moto.core.base_backend import BackendDict
from werkzeug.test import Client

from drem_local.durable.post_policy import PostPolicyGuard
from drem_local.durable.server import DurableApp
from drem_local.durable.state import DurableState

pytestmark = pytest.mark.unit

BUCKET = "drem-local-models"
KEY = "uploads/racer-sub/model-1.tar.gz"
LIMIT = 1000
_S3_AUTH = "AWS4-HMAC-SHA256 Credential=testing/20260101/us-east-1/s3/aws4_request, SignedHeaders=host, Signature=0"


@pytest.fixture
def storage(tmp_path):
    from moto.moto_server.werkzeug_app import DomainDispatcherApplication, create_backend_app

    BackendDict.reset()
    guard = PostPolicyGuard({"testing": "testing"}.get, max_body_bytes=64 * 1024)
    app = DurableApp(DomainDispatcherApplication(create_backend_app), DurableState(tmp_path / "state", fsync=False),
                     upload_guard=guard)
    app.recover()
    client = Client(app)
    assert client.put(f"/{BUCKET}", headers={"Authorization": _S3_AUTH}).status_code == 200
    yield app, client
    BackendDict.reset()


def ticket(key: str = KEY, maximum: int = LIMIT, expires_s: int = 300) -> dict:
    """Exactly what the app hands a racer (chalicelib/storage/model_files.py presign_upload), signed by botocore."""
    s3 = boto3.session.Session(aws_access_key_id="testing", aws_secret_access_key="testing",
                               region_name="us-east-1").client(
        "s3", endpoint_url="http://127.0.0.1:9", config=Config(signature_version="s3v4",
                                                               s3={"addressing_style": "path"}))
    return s3.generate_presigned_post(Bucket=BUCKET, Key=key, Conditions=[["content-length-range", 1, maximum]],
                                      ExpiresIn=expires_s)


def post(client: Client, fields: dict, data: bytes | None, query: str = "", headers: dict | None = None):
    files = {"file": ("model.tar.gz", data)} if data is not None else None
    prepared = requests.Request("POST", f"http://127.0.0.1:9/{BUCKET}", data=fields, files=files).prepare()
    return client.post(f"/{BUCKET}{query}", data=prepared.body,
                       headers={"Content-Type": prepared.headers["Content-Type"], **(headers or {})})


def put(client: Client, key: str, data: bytes) -> None:
    assert client.put(f"/{BUCKET}/{key}", data=data, headers={"Authorization": _S3_AUTH}).status_code == 200


def stored(client: Client, key: str) -> bytes | None:
    reply = client.get(f"/{BUCKET}/{key}", headers={"Authorization": _S3_AUTH})
    return reply.get_data() if reply.status_code == 200 else None


def error_code(reply) -> str:
    text = reply.get_data(as_text=True)
    return text.split("<Code>", 1)[1].split("</Code>", 1)[0] if "<Code>" in text else text


def test_the_ticket_as_issued_uploads(storage) -> None:
    _app, client = storage
    reply = post(client, ticket()["fields"], b"x" * LIMIT)

    assert reply.status_code in (200, 204), reply.get_data(as_text=True)
    assert stored(client, KEY) == b"x" * LIMIT


def test_a_file_over_the_signed_size_range_is_refused_and_not_stored(storage) -> None:
    _app, client = storage
    reply = post(client, ticket()["fields"], b"x" * (LIMIT + 1))

    assert (reply.status_code, error_code(reply)) == (400, "EntityTooLarge")
    assert f"<MaxSizeAllowed>{LIMIT}</MaxSizeAllowed>" in reply.get_data(as_text=True)
    assert stored(client, KEY) is None


def test_an_empty_file_is_under_the_range(storage) -> None:
    _app, client = storage
    reply = post(client, ticket()["fields"], b"")

    assert (reply.status_code, error_code(reply)) == (400, "EntityTooSmall")
    assert stored(client, KEY) is None


def test_another_key_with_a_valid_ticket_is_refused(storage) -> None:
    _app, client = storage
    victim = "models/victim-sub/their-model.tar.gz"
    reply = post(client, {**ticket()["fields"], "key": victim}, b"owned")

    assert (reply.status_code, error_code(reply)) == (403, "AccessDenied")
    assert "Policy Condition failed" in reply.get_data(as_text=True)
    assert stored(client, victim) is None and stored(client, KEY) is None


def test_a_policy_rewritten_without_limits_fails_the_signature(storage) -> None:
    _app, client = storage
    fields = ticket()["fields"]
    policy = json.loads(base64.b64decode(fields["policy"]))
    policy["conditions"] = [c for c in policy["conditions"] if not (isinstance(c, list) and c[0] ==
                                                                     "content-length-range")]
    forged = {**fields, "policy": base64.b64encode(json.dumps(policy).encode()).decode()}

    reply = post(client, forged, b"x" * (LIMIT + 1))

    assert (reply.status_code, error_code(reply)) == (403, "AccessDenied")
    assert "signature" in reply.get_data(as_text=True)
    assert stored(client, KEY) is None


def test_an_anonymous_form_upload_is_refused(storage) -> None:
    _app, client = storage
    reply = post(client, {"key": KEY}, b"x")

    assert (reply.status_code, error_code(reply)) == (403, "AccessDenied")
    assert stored(client, KEY) is None


def test_an_expired_ticket_is_refused(storage) -> None:
    app, client = storage
    fields = ticket(expires_s=60)["fields"]
    app.upload_guard._now = lambda: datetime.now(UTC) + timedelta(minutes=2)

    reply = post(client, fields, b"x")

    assert (reply.status_code, error_code(reply)) == (403, "AccessDenied")
    assert "Policy expired" in reply.get_data(as_text=True)


def test_an_extra_field_not_in_the_policy_is_refused(storage) -> None:
    _app, client = storage
    reply = post(client, {**ticket()["fields"], "x-amz-meta-owner": "admin"}, b"x")

    assert (reply.status_code, error_code(reply)) == (403, "AccessDenied")
    assert "Extra input fields: x-amz-meta-owner" in reply.get_data(as_text=True)


def test_a_body_over_the_server_ceiling_is_refused_from_its_length_unread(storage) -> None:
    _app, client = storage
    reply = post(client, ticket(maximum=10 * 1024 * 1024)["fields"], b"x" * (65 * 1024))

    assert (reply.status_code, error_code(reply)) == (400, "EntityTooLarge")
    assert stored(client, KEY) is None


# --- issue 27: a query string (or an operation header) no longer switches the policy off --------------------------

VICTIM = "models/victim-sub/their-model.tar.gz"


@pytest.mark.parametrize("query", ["?x=1", "?acl", "?uploads", f"?key={VICTIM}"])
def test_another_racers_key_posted_to_the_url_with_a_query_is_refused(storage, query) -> None:
    """The attack as reported: one's own ticket, posted to `{url}?x=1` with another racer's key, answered 204."""
    _app, client = storage
    put(client, VICTIM, b"their validated archive")

    reply = post(client, {**ticket()["fields"], "key": VICTIM}, b"owned", query=query)

    assert (reply.status_code, error_code(reply)) == (403, "AccessDenied")
    assert stored(client, VICTIM) == b"their validated archive"


def test_ones_own_ticket_posted_with_a_query_is_refused_too(storage) -> None:
    _app, client = storage
    reply = post(client, ticket()["fields"], b"x", query="?x=1")

    assert (reply.status_code, error_code(reply)) == (403, "AccessDenied")
    assert "without a query string" in reply.get_data(as_text=True)
    assert stored(client, KEY) is None


@pytest.mark.parametrize(("size", "code"), [(0, "EntityTooSmall"), (LIMIT + 1, "EntityTooLarge")])
def test_empty_and_oversize_files_with_a_query_are_refused(storage, size, code) -> None:
    _app, client = storage
    reply = post(client, ticket()["fields"], b"x" * size, query="?x=1")

    assert (reply.status_code, error_code(reply)) == (400, code)
    assert stored(client, KEY) is None


def test_a_delete_document_posted_to_the_url_with_delete_deletes_nothing(storage) -> None:
    """DeleteObjects by form: a <Delete> document as the form's file, posted to `{url}?delete`."""
    _app, client = storage
    put(client, VICTIM, b"their validated archive")
    delete = (f"<Delete><Object><Key>{VICTIM}</Key></Object><Object><Key>{KEY}</Key></Object></Delete>").encode()

    for fields in (ticket()["fields"], {**ticket()["fields"], "key": VICTIM}, {"key": VICTIM}):
        reply = post(client, fields, delete, query="?delete")
        assert reply.status_code == 403, reply.get_data(as_text=True)
        assert "<DeleteResult>" not in reply.get_data(as_text=True)

    assert stored(client, VICTIM) == b"their validated archive"


def test_a_form_naming_another_service_is_refused(storage) -> None:
    _app, client = storage
    reply = post(client, ticket()["fields"], b"x", headers={"X-Amz-Target": "DynamoDB_20120810.ListTables"})

    assert reply.status_code == 403
    assert stored(client, KEY) is None


@pytest.mark.parametrize("target", ["https://evil.example/phish", "//evil.example/", "/\\evil.example",
                                    "javascript:alert(1)"])
@pytest.mark.parametrize("field", ["success_action_redirect", "redirect"])
def test_a_redirect_to_another_origin_is_refused_even_when_signed(storage, field, target) -> None:
    """Even a policy that allows the field cannot bounce a browser from drem's address to another site."""
    _app, client = storage
    s3 = boto3.session.Session(aws_access_key_id="testing", aws_secret_access_key="testing",
                               region_name="us-east-1").client(
        "s3", endpoint_url="http://127.0.0.1:9", config=Config(signature_version="s3v4",
                                                               s3={"addressing_style": "path"}))
    signed = s3.generate_presigned_post(Bucket=BUCKET, Key=KEY, Fields={field: target},
                                        Conditions=[{field: target}, ["content-length-range", 1, LIMIT]])

    reply = post(client, signed["fields"], b"x")

    assert (reply.status_code, error_code(reply)) == (403, "AccessDenied")
    assert "Location" not in reply.headers
    assert stored(client, KEY) is None


@pytest.mark.parametrize("query", ["?success_action_redirect=https://evil.example/",
                                   "?redirect=https://evil.example/"])
def test_a_redirect_in_the_query_is_refused(storage, query) -> None:
    _app, client = storage
    reply = post(client, ticket()["fields"], b"x", query=query)

    assert reply.status_code == 403
    assert "Location" not in reply.headers
    assert stored(client, KEY) is None


def test_a_redirect_to_a_path_on_this_site_is_allowed_when_signed(storage) -> None:
    _app, client = storage
    s3 = boto3.session.Session(aws_access_key_id="testing", aws_secret_access_key="testing",
                               region_name="us-east-1").client(
        "s3", endpoint_url="http://127.0.0.1:9", config=Config(signature_version="s3v4",
                                                               s3={"addressing_style": "path"}))
    signed = s3.generate_presigned_post(Bucket=BUCKET, Key=KEY, Fields={"success_action_redirect": "/done"},
                                        Conditions=[{"success_action_redirect": "/done"},
                                                    ["content-length-range", 1, LIMIT]])

    reply = post(client, signed["fields"], b"x")

    assert reply.status_code == 303
    assert stored(client, KEY) == b"x"


def test_a_ticket_for_another_bucket_is_refused(storage) -> None:
    _app, client = storage
    assert client.put("/drem-local-runs", headers={"Authorization": _S3_AUTH}).status_code == 200
    fields = ticket()["fields"]
    files = {"file": ("model.tar.gz", b"x")}
    prepared = requests.Request("POST", "http://127.0.0.1:9/drem-local-runs", data=fields, files=files).prepare()
    reply = client.post("/drem-local-runs", data=prepared.body,
                        headers={"Content-Type": prepared.headers["Content-Type"]})

    assert (reply.status_code, error_code(reply)) == (403, "AccessDenied")
    assert "bucket" in reply.get_data(as_text=True)
