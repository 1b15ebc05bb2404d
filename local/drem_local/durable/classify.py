"""Which requests change state, which service they touch, and which must be snapshotted at once."""
from __future__ import annotations

from typing import Any
from urllib.parse import parse_qs

# Persisted service groups. DynamoDB Streams lives inside the DynamoDB tables, so both pickle together.
DYNAMODB = "dynamodb"
S3 = "s3"
COGNITO = "cognito-idp"
PERSISTED = (DYNAMODB, S3, COGNITO)
MOTO_API = "moto-api"
OTHER = "other"

_READ_PREFIXES = ("Get", "Query", "Scan", "Describe", "List", "BatchGet", "TransactGet", "AdminGet")

# Their results carry ids moto draws at random; the service is snapshotted before the response goes out, on top of
# the journal record's seeded randomness (DurableState.seed_randomness), because these ids name everything after them.
# Sign-ins (InitiateAuth, RespondToAuthChallenge and their Admin forms) are not snapshotted: their refresh tokens and
# sessions are drawn from the same seeded randomness, so replaying the journal reproduces what the client was told,
# and a snapshot pickles the whole user pool under the storage lock (~30 ms at 1,000 racers, plus its fsyncs), which
# at a venue's 8 sign-ins a second held every board write behind it (bench/venue.py, issue 27).
_RANDOM_RESULT_COGNITO_OPS = frozenset({"CreateUserPool", "CreateUserPoolClient", "AdminCreateUser", "SignUp"})


def target_operation(environ: dict[str, Any]) -> str:
    target = environ.get("HTTP_X_AMZ_TARGET", "")
    return target.split(".", 1)[1] if "." in target else ""


def service_of(environ: dict[str, Any]) -> str:
    path = environ.get("PATH_INFO", "")
    if path.startswith("/moto-api"):
        return MOTO_API
    target = environ.get("HTTP_X_AMZ_TARGET", "")
    if target.startswith("DynamoDB"):
        return DYNAMODB
    if target.startswith("AWSCognitoIdentityProviderService"):
        return COGNITO
    scope_service = _signing_service(environ)
    if scope_service is None:
        # Unsigned and untargeted: moto routes these (presigned POST forms, anonymous reads) to S3.
        return S3
    if scope_service == "s3":
        return S3
    if scope_service in ("dynamodb", "cognito-idp"):
        return scope_service
    return OTHER


def _signing_service(environ: dict[str, Any]) -> str | None:
    auth = environ.get("HTTP_AUTHORIZATION", "")
    credential = ""
    if auth.startswith("AWS4-"):
        credential = auth.split("Credential=", 1)[1].split(",", 1)[0] if "Credential=" in auth else ""
    elif auth.startswith("AWS "):
        return "s3"  # SigV2 is S3-only here
    else:
        query = parse_qs(environ.get("QUERY_STRING", ""))
        if "X-Amz-Credential" in query:
            credential = query["X-Amz-Credential"][0]
        elif "AWSAccessKeyId" in query:
            return "s3"
    parts = credential.split("/")
    return parts[3].lower() if len(parts) >= 5 else None


def is_state_changing(environ: dict[str, Any]) -> bool:
    method = environ.get("REQUEST_METHOD", "GET").upper()
    if method in ("GET", "HEAD", "OPTIONS"):
        return False
    operation = target_operation(environ)
    return not (operation and operation.startswith(_READ_PREFIXES))


def needs_immediate_snapshot(environ: dict[str, Any], service: str) -> bool:
    if service == COGNITO:
        return target_operation(environ) in _RANDOM_RESULT_COGNITO_OPS
    if service == S3 and environ.get("REQUEST_METHOD", "").upper() == "POST":
        # CreateMultipartUpload (?uploads) draws a random UploadId; CompleteMultipartUpload (?uploadId=) assembles it.
        query = parse_qs(environ.get("QUERY_STRING", ""), keep_blank_values=True)
        return "uploads" in query or "uploadId" in query
    return False
