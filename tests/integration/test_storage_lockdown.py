"""The storage port, attacked as someone on the same machine (or a page in its browser) would, on a real stack.

Before: no credentials needed, any Origin echoed, `/moto-api/data.json` listed every plaintext password and
`/moto-api/reset` wiped the event; the state dir was world-readable. Each attack below must now fail, while the
app keeps working (the other integration tests) and presigned links through the app's gateway still work.
"""
from __future__ import annotations

import json
import stat
from datetime import UTC, datetime, timedelta

import botocore.auth
import botocore.signers
import pytest
import requests
from botocore.exceptions import ClientError

from drem_local.storage_keys import StorageKeys, generate, local_client

pytestmark = pytest.mark.integration


def _table(live_stack) -> str:
    return next(iter(live_stack.outputs.tables.values()))


def test_an_unsigned_request_gets_nothing(live_stack):
    scan = requests.post(live_stack.storage_url + "/", timeout=10, data=json.dumps({"TableName": _table(live_stack)}),
                         headers={"X-Amz-Target": "DynamoDB_20120810.Scan",
                                  "Content-Type": "application/x-amz-json-1.0"})
    users = requests.post(live_stack.storage_url + "/", timeout=10,
                          data=json.dumps({"UserPoolId": live_stack.outputs.user_pool_id}),
                          headers={"X-Amz-Target": "AWSCognitoIdentityProviderService.ListUsers",
                                   "Content-Type": "application/x-amz-json-1.1"})
    bucket = requests.get(f"{live_stack.storage_url}/{live_stack.outputs.buckets['models']}", timeout=10)

    for answer in (scan, users, bucket):
        assert answer.status_code == 403, answer.text
        assert "Items" not in answer.text and "Users" not in answer.text and "Contents" not in answer.text


def test_a_signature_with_other_keys_is_refused(live_stack):
    stranger = local_client("cognito-idp", live_stack.storage_url, generate())
    with pytest.raises(ClientError) as refused:
        stranger.list_users(UserPoolId=live_stack.outputs.user_pool_id)
    assert refused.value.response["Error"]["Code"] == "InvalidAccessKeyId"

    right_id_wrong_secret = StorageKeys(_keys(live_stack).access_key_id, "guessed-secret")
    guesser = local_client("dynamodb", live_stack.storage_url, right_id_wrong_secret)
    with pytest.raises(ClientError) as refused:
        guesser.scan(TableName=_table(live_stack))
    assert refused.value.response["Error"]["Code"] == "SignatureDoesNotMatch"


def test_moto_admin_api_is_gone_and_reset_wipes_nothing(live_stack):
    data = requests.get(live_stack.storage_url + "/moto-api/data.json", timeout=10)
    reset = requests.post(live_stack.storage_url + "/moto-api/reset", timeout=10)

    assert data.status_code == 404 and live_stack.admin_password not in data.text
    assert reset.status_code == 404
    cognito = live_stack.client("cognito-idp")
    tokens = cognito.initiate_auth(ClientId=live_stack.outputs.user_pool_client_id, AuthFlow="USER_PASSWORD_AUTH",
                                   AuthParameters={"USERNAME": live_stack.admin_username,
                                                   "PASSWORD": live_stack.admin_password})
    assert tokens["AuthenticationResult"]["AccessToken"], "the event survived the reset attempt"


def test_no_origin_is_echoed_and_preflights_are_refused(live_stack):
    bucket = live_stack.outputs.buckets["models"]
    preflight = requests.options(f"{live_stack.storage_url}/{bucket}/models/x.tar.gz", timeout=10,
                                 headers={"Origin": "http://evil.example", "Access-Control-Request-Method": "GET"})
    assert preflight.status_code == 403
    assert "Access-Control-Allow-Origin" not in preflight.headers

    s3 = live_stack.client("s3")
    s3.meta.events.register("before-send.s3", lambda request, **_: request.headers.__setitem__(
        "Origin", "http://evil.example"))
    answer = s3.list_objects_v2(Bucket=bucket)
    assert not any(name.lower().startswith("access-control-")
                   for name in answer["ResponseMetadata"]["HTTPHeaders"]), answer["ResponseMetadata"]["HTTPHeaders"]


def test_presigned_links_work_through_the_app_and_expire(live_stack, monkeypatch):
    bucket = live_stack.outputs.buckets["models"]
    live_stack.client("s3").put_object(Bucket=bucket, Key="models/lockdown/m.tar.gz", Body=b"archive bytes")
    presigner = local_client("s3", live_stack.url + "/_storage", _keys(live_stack))
    link = presigner.generate_presigned_url("get_object", Params={"Bucket": bucket, "Key": "models/lockdown/m.tar.gz"},
                                            ExpiresIn=60)
    fetched = requests.get(link, timeout=10)
    assert fetched.status_code == 200 and fetched.content == b"archive bytes"
    assert fetched.headers["Content-Disposition"] == "attachment"  # never rendered on the app's origin
    assert fetched.headers["X-Content-Type-Options"] == "nosniff"
    assert "drem_" not in fetched.headers.get("Set-Cookie", "")

    tampered = requests.get(link.replace("models/lockdown/m", "models/lockdown/other"), timeout=10)
    assert tampered.status_code == 403 and "SignatureDoesNotMatch" in tampered.text

    an_hour_ago = datetime.now(UTC) - timedelta(hours=1)
    monkeypatch.setattr(botocore.auth, "get_current_datetime", lambda: an_hour_ago)
    expired = presigner.generate_presigned_url("get_object", ExpiresIn=60,
                                               Params={"Bucket": bucket, "Key": "models/lockdown/m.tar.gz"})
    answer = requests.get(expired, timeout=10)
    assert answer.status_code == 403 and "expired" in answer.text and b"archive bytes" not in answer.content


def test_an_expired_upload_form_is_refused(live_stack, monkeypatch):
    bucket = live_stack.outputs.buckets["models"]
    presigner = local_client("s3", live_stack.url + "/_storage", _keys(live_stack))
    an_hour_ago = datetime.now(UTC) - timedelta(hours=1)
    monkeypatch.setattr(botocore.auth, "get_current_datetime", lambda: an_hour_ago)  # x-amz-date
    monkeypatch.setattr(botocore.signers, "get_current_datetime", lambda: an_hour_ago)  # the policy's expiration
    post = presigner.generate_presigned_post(bucket, "uploads/lockdown/late.tar.gz", ExpiresIn=60)
    answer = requests.post(post["url"], data=post["fields"], files={"file": ("late.tar.gz", b"late")}, timeout=10)

    assert answer.status_code == 403 and "expired" in answer.text
    with pytest.raises(ClientError):
        live_stack.client("s3").head_object(Bucket=bucket, Key="uploads/lockdown/late.tar.gz")


def test_the_gateway_does_not_pass_sdk_calls_even_with_the_keys(live_stack):
    bucket = live_stack.outputs.buckets["models"]
    through_app = local_client("s3", live_stack.url + "/_storage", _keys(live_stack))
    with pytest.raises(ClientError) as refused:
        through_app.list_objects_v2(Bucket=bucket)
    assert refused.value.response["ResponseMetadata"]["HTTPStatusCode"] == 403


def test_the_state_dir_is_private_to_its_user(live_stack):
    assert stat.S_IMODE(live_stack.state_dir.stat().st_mode) == 0o700
    files = [path for path in live_stack.state_dir.rglob("*") if path.is_file()]
    assert {"journal.bin", "manifest.json", "storage-keys.json", "stack.json", "storage.log",
            "app.log"} <= {p.name for p in files}
    loose = {str(p.relative_to(live_stack.state_dir)): oct(stat.S_IMODE(p.stat().st_mode)) for p in files
             if stat.S_IMODE(p.stat().st_mode) & 0o077}
    assert loose == {}, f"readable by others: {loose}"
    loose_dirs = [str(p) for p in live_stack.state_dir.rglob("*") if p.is_dir() and p.stat().st_mode & 0o077]
    assert loose_dirs == []


def _keys(live_stack) -> StorageKeys:
    from drem_local.storage_keys import load

    return load(live_stack.state_dir)
