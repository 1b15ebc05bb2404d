"""Which requests the durable server journals, and which it snapshots before answering."""
from __future__ import annotations

import pytest

from drem_local.durable.classify import COGNITO, DYNAMODB, S3, is_state_changing, needs_immediate_snapshot, service_of

pytestmark = pytest.mark.unit

_SIGV4 = ("AWS4-HMAC-SHA256 Credential=testing/20260101/us-east-1/{service}/aws4_request, "
          "SignedHeaders=host, Signature=0")


def _target(target: str, service: str = "dynamodb") -> dict:
    return {"REQUEST_METHOD": "POST", "PATH_INFO": "/", "HTTP_X_AMZ_TARGET": target,
            "HTTP_AUTHORIZATION": _SIGV4.format(service=service)}


def _s3(method: str, query: str = "") -> dict:
    return {"REQUEST_METHOD": method, "PATH_INFO": "/bucket/key", "QUERY_STRING": query,
            "HTTP_AUTHORIZATION": _SIGV4.format(service="s3")}


@pytest.mark.parametrize("operation", ["GetItem", "Query", "Scan", "DescribeTable", "ListTables", "BatchGetItem",
                                       "TransactGetItems"])
def test_dynamodb_reads_are_not_journaled(operation):
    assert not is_state_changing(_target(f"DynamoDB_20120810.{operation}"))


@pytest.mark.parametrize("operation", ["PutItem", "UpdateItem", "DeleteItem", "TransactWriteItems", "BatchWriteItem"])
def test_dynamodb_writes_are_journaled(operation):
    environ = _target(f"DynamoDB_20120810.{operation}")
    assert is_state_changing(environ) and service_of(environ) == DYNAMODB


def test_logins_are_journaled_but_not_snapshotted_because_their_refresh_tokens_replay_from_the_journal():
    environ = {"REQUEST_METHOD": "POST", "PATH_INFO": "/",
               "HTTP_X_AMZ_TARGET": "AWSCognitoIdentityProviderService.InitiateAuth"}  # unsigned, as boto3 sends it

    assert service_of(environ) == COGNITO and is_state_changing(environ)
    assert not needs_immediate_snapshot(environ, COGNITO)
    assert needs_immediate_snapshot(_target("AWSCognitoIdentityProviderService.AdminCreateUser", "cognito-idp"),
                                    COGNITO)


def test_admin_get_user_is_a_read():
    assert not is_state_changing(_target("AWSCognitoIdentityProviderService.AdminGetUser", "cognito-idp"))


def test_s3_reads_pass_and_multipart_create_and_complete_are_snapshotted():
    assert not is_state_changing(_s3("GET")) and not is_state_changing(_s3("HEAD"))
    assert is_state_changing(_s3("PUT")) and not needs_immediate_snapshot(_s3("PUT"), S3)
    assert needs_immediate_snapshot(_s3("POST", "uploads"), S3)
    assert needs_immediate_snapshot(_s3("POST", "uploadId=abc"), S3)
    assert not needs_immediate_snapshot(_s3("PUT", "partNumber=1&uploadId=abc"), S3)


def test_a_presigned_browser_upload_counts_as_s3():
    presigned_put = {"REQUEST_METHOD": "PUT", "PATH_INFO": "/bucket/key",
                     "QUERY_STRING": "X-Amz-Credential=testing%2F20260101%2Fus-east-1%2Fs3%2Faws4_request"
                                     "&X-Amz-Signature=0"}
    presigned_post_form = {"REQUEST_METHOD": "POST", "PATH_INFO": "/bucket", "CONTENT_TYPE": "multipart/form-data"}

    assert service_of(presigned_put) == S3 and service_of(presigned_post_form) == S3
