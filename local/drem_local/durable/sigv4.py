"""Verify the AWS Signature Version 4 of a request to the local storage server, the way AWS does.

Three forms reach us, all computed by botocore with the installation's keys (drem_local.storage_keys):
- an `Authorization: AWS4-HMAC-SHA256 ...` header (every SDK call; botocore/auth.py SigV4Auth, S3SigV4Auth),
- query parameters `X-Amz-Signature`, `X-Amz-Date`, `X-Amz-Expires` (presigned GETs that cars and browsers use;
  botocore/auth.py SigV4QueryAuth, S3SigV4QueryAuth),
- a POST form with `policy` and `x-amz-signature` (presigned browser uploads; botocore/auth.py S3SigV4PostAuth).
The canonical request is rebuilt with botocore's own SigV4Auth code from the bytes that arrived, so both sides agree
by construction. Limits as on AWS (docs.aws.amazon.com/AmazonS3/latest/API/sigv4-query-string-auth.html): a header
signature may be at most 15 minutes off the clock; a presigned URL lives at most 7 days and not past its expiry.
"""
from __future__ import annotations

import base64
import functools
import hashlib
import hmac
import io
import json
import re
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any
from urllib.parse import quote, unquote

from botocore.auth import S3SigV4Auth, S3SigV4QueryAuth, SigV4Auth, SigV4QueryAuth
from botocore.awsrequest import AWSRequest
from botocore.credentials import Credentials

from drem_local.storage_keys import StorageKeys

ALGORITHM = "AWS4-HMAC-SHA256"
MAX_CLOCK_SKEW_S = 15 * 60
MAX_PRESIGNED_EXPIRES_S = 7 * 24 * 3600
_HEX_SHA256 = re.compile(r"^[0-9a-f]{64}$")
# Payload markers botocore may put in X-Amz-Content-SHA256 instead of a hash (botocore/auth.py).
_UNHASHED_PAYLOADS = ("UNSIGNED-PAYLOAD", "STREAMING-UNSIGNED-PAYLOAD-TRAILER")


@dataclass(frozen=True)
class Refusal:
    """Why a request was turned away: HTTP status, AWS error code, a message that says what to do."""
    status: int
    code: str
    message: str


@dataclass(frozen=True)
class Verified:
    form: str  # "header", "query" or "post"
    service: str


def verify(environ: dict[str, Any], body: bytes, keys: StorageKeys, now: datetime | None = None
           ) -> Verified | Refusal:
    now = now or datetime.now(UTC)
    authorization = environ.get("HTTP_AUTHORIZATION", "")
    query = environ.get("QUERY_STRING", "")
    if authorization.startswith(ALGORITHM + " "):
        return _verify_header(environ, body, keys, authorization, now)
    if authorization:
        return Refusal(403, "AccessDenied", "only AWS Signature Version 4 is accepted by drem's storage server")
    if "X-Amz-Signature=" in query:
        return _verify_query(environ, body, keys, query, now)
    if environ.get("REQUEST_METHOD", "").upper() == "POST" and \
            environ.get("CONTENT_TYPE", "").lower().startswith("multipart/form-data"):
        return _verify_post_form(environ, body, keys, now)
    return Refusal(403, "AccessDenied", "drem's storage server accepts only requests signed with this "
                                        "installation's keys (the app, the bootstrap and the drem CLI have them)")


# --- the three forms ----------------------------------------------------------------------------------------------

def _verify_header(environ: dict[str, Any], body: bytes, keys: StorageKeys, authorization: str,
                   now: datetime) -> Verified | Refusal:
    fields = _authorization_fields(authorization[len(ALGORITHM) + 1:])
    scope = _scope(fields.get("Credential", ""), keys)
    if isinstance(scope, Refusal):
        return scope
    signed_headers = [name for name in fields.get("SignedHeaders", "").split(";") if name]
    signature = fields.get("Signature", "")
    timestamp = environ.get("HTTP_X_AMZ_DATE", "")
    when = _parse_timestamp(timestamp)
    if when is None or timestamp[:8] != scope.date or "host" not in signed_headers:
        return Refusal(403, "IncompleteSignature", "the signature lacks a valid X-Amz-Date or a signed Host header")
    if abs((now - when).total_seconds()) > MAX_CLOCK_SKEW_S:
        return Refusal(403, "RequestTimeTooSkewed", "the request time differs from the server's by more than 15 "
                                                    "minutes")
    payload_hash = environ.get("HTTP_X_AMZ_CONTENT_SHA256")
    if payload_hash is not None and payload_hash not in _UNHASHED_PAYLOADS:
        if not _HEX_SHA256.match(payload_hash):
            return Refusal(400, "InvalidArgument", "X-Amz-Content-SHA256 must be a SHA-256 hex digest")
        if payload_hash != hashlib.sha256(body).hexdigest():
            return Refusal(400, "XAmzContentSHA256Mismatch", "the body does not match its signed SHA-256")
    signer_class = S3SigV4Auth if scope.service == "s3" else SigV4Auth
    # Without the header, botocore's payload hash over plain http is sha256(body) (SigV4Auth.payload); handing it over
    # as that header gives the same canonical request without preparing a whole botocore request for it.
    known_payload_hash = payload_hash if payload_hash is not None else hashlib.sha256(body).hexdigest()
    request = _rebuild_request(environ, body, signed_headers, payload_hash=known_payload_hash)
    expected = _signature(signer_class, keys, scope, timestamp, request, signed_headers)
    if not hmac.compare_digest(expected, signature):
        return Refusal(403, "SignatureDoesNotMatch", "the request signature does not match the installation's keys")
    return Verified("header", scope.service)


def _verify_query(environ: dict[str, Any], body: bytes, keys: StorageKeys, query: str,
                  now: datetime) -> Verified | Refusal:
    params = _raw_query_params(query)
    if params.get("X-Amz-Algorithm") != ALGORITHM:
        return Refusal(403, "AuthorizationQueryParametersError", "X-Amz-Algorithm must be AWS4-HMAC-SHA256")
    scope = _scope(params.get("X-Amz-Credential", ""), keys)
    if isinstance(scope, Refusal):
        return scope
    timestamp = params.get("X-Amz-Date", "")
    when = _parse_timestamp(timestamp)
    expires = params.get("X-Amz-Expires", "")
    signed_headers = [name for name in params.get("X-Amz-SignedHeaders", "").split(";") if name]
    if when is None or timestamp[:8] != scope.date or not expires.isdigit() or "host" not in signed_headers:
        return Refusal(403, "AuthorizationQueryParametersError",
                       "a presigned URL needs X-Amz-Date, X-Amz-Expires and a signed Host header")
    if int(expires) > MAX_PRESIGNED_EXPIRES_S:
        return Refusal(403, "AuthorizationQueryParametersError", "X-Amz-Expires must be at most 604800 seconds")
    if (when - now).total_seconds() > MAX_CLOCK_SKEW_S:
        return Refusal(403, "AccessDenied", "the presigned URL is dated in the future")
    if (now - when).total_seconds() > int(expires):
        return Refusal(403, "AccessDenied", "Request has expired: ask drem for a fresh link")
    signature = params.get("X-Amz-Signature", "")
    # The canonical query is everything but the signature itself (botocore appends it last, after signing).
    unsigned_query = "&".join(pair for pair in query.split("&") if not pair.startswith("X-Amz-Signature="))
    signer_class = S3SigV4QueryAuth if scope.service == "s3" else SigV4QueryAuth
    request = _rebuild_request(environ, body, signed_headers, query=unsigned_query)
    expected = _signature(signer_class, keys, scope, timestamp, request, signed_headers)
    if not hmac.compare_digest(expected, signature):
        return Refusal(403, "SignatureDoesNotMatch", "the presigned URL's signature does not match the "
                                                     "installation's keys (was it altered?)")
    return Verified("query", scope.service)


def _verify_post_form(environ: dict[str, Any], body: bytes, keys: StorageKeys, now: datetime) -> Verified | Refusal:
    fields = _form_fields(environ, body)
    if fields.get("x-amz-algorithm") != ALGORITHM or "policy" not in fields or "x-amz-signature" not in fields:
        return Refusal(403, "AccessDenied", "an upload form needs policy, x-amz-algorithm AWS4-HMAC-SHA256 and "
                                            "x-amz-signature (ask drem for a fresh upload)")
    scope = _scope(fields.get("x-amz-credential", ""), keys)
    if isinstance(scope, Refusal):
        return scope
    policy_text = fields["policy"]
    expected = hmac.new(_signing_key(keys, scope), policy_text.encode(), hashlib.sha256).hexdigest()
    if not hmac.compare_digest(expected, fields["x-amz-signature"]):
        return Refusal(403, "SignatureDoesNotMatch", "the upload form's signature does not match its policy")
    try:
        policy = json.loads(base64.b64decode(policy_text, validate=True))
        expiration = datetime.fromisoformat(policy["expiration"].replace("Z", "+00:00"))
    except (ValueError, KeyError, TypeError, AttributeError):
        return Refusal(400, "InvalidPolicyDocument", "the upload policy has no readable expiration")
    if expiration.tzinfo is None or now > expiration:
        return Refusal(403, "AccessDenied", "Invalid according to Policy: Policy expired (ask drem for a fresh "
                                            "upload)")
    return Verified("post", scope.service)


# --- pieces -------------------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class _Scope:
    date: str
    region: str
    service: str


def _scope(credential: str, keys: StorageKeys) -> _Scope | Refusal:
    parts = unquote(credential).split("/")
    if len(parts) != 5 or parts[4] != "aws4_request" or not all(parts):
        return Refusal(403, "IncompleteSignature", "the credential scope is malformed")
    if not hmac.compare_digest(parts[0], keys.access_key_id):
        return Refusal(403, "InvalidAccessKeyId", "the access key is not this installation's: only drem's own "
                                                  "processes can talk to its storage")
    return _Scope(parts[1], parts[2], parts[3])


@functools.lru_cache(maxsize=64)
def _signing_key(keys: StorageKeys, scope: _Scope) -> bytes:
    """kSigning of the SigV4 spec (botocore/auth.py SigV4Auth.signature); one per day, region and service."""
    key = ("AWS4" + keys.secret_access_key).encode()
    for part in (scope.date, scope.region, scope.service, "aws4_request"):
        key = hmac.new(key, part.encode(), hashlib.sha256).digest()
    return key


def _signature(signer_class: type[SigV4Auth], keys: StorageKeys, scope: _Scope, timestamp: str,
               request: AWSRequest, signed_headers: list[str]) -> str:
    """botocore's own canonical request, string to sign and signature, over exactly the headers the client signed."""
    credentials = Credentials(keys.access_key_id, keys.secret_access_key)
    verifying = _VERIFYING[signer_class]
    signer = verifying(credentials, scope.service, scope.region, expires=0) if issubclass(
        signer_class, SigV4QueryAuth) else verifying(credentials, scope.service, scope.region)
    signer.signed_header_names = frozenset(signed_headers)
    request.context["timestamp"] = timestamp
    canonical = signer.canonical_request(request)
    string_to_sign = signer.string_to_sign(request, canonical)
    return hmac.new(_signing_key(keys, scope), string_to_sign.encode(), hashlib.sha256).hexdigest()


def _only_signed_headers(signer_class: type[SigV4Auth]) -> type[SigV4Auth]:
    """A botocore signer whose header selection is the client's SignedHeaders list, not "every header we have"."""

    class Verifying(signer_class):
        signed_header_names: frozenset[str] = frozenset()

        def headers_to_sign(self, request: AWSRequest) -> Any:
            chosen = super().headers_to_sign(request)
            for name in set(chosen.keys()) - self.signed_header_names:
                del chosen[name]
            return chosen

    return Verifying


_VERIFYING = {cls: _only_signed_headers(cls) for cls in (SigV4Auth, S3SigV4Auth, SigV4QueryAuth, S3SigV4QueryAuth)}


def _rebuild_request(environ: dict[str, Any], body: bytes, signed_headers: list[str],
                     query: str | None = None, payload_hash: str | None = None) -> AWSRequest:
    path, _, raw_query = raw_target(environ).partition("?")
    query = raw_query if query is None else query
    headers = {}
    for name in signed_headers:
        value = _header(environ, name)
        if value is not None:
            headers[name] = value
    payload_hash = payload_hash or environ.get("HTTP_X_AMZ_CONTENT_SHA256")
    if payload_hash is not None and "x-amz-content-sha256" not in headers:
        # botocore puts it in the canonical request as the payload hash whether or not it is a signed header
        headers["X-Amz-Content-SHA256"] = payload_hash
    host = environ.get("HTTP_HOST", "")
    url = f"http://{host}{path}" + (f"?{query}" if query else "")
    return AWSRequest(method=environ.get("REQUEST_METHOD", "GET"), url=url, headers=headers, data=body)


def raw_target(environ: dict[str, Any]) -> str:
    """The request target exactly as the client sent it (percent-encoding intact): what the client signed."""
    raw = environ.get("RAW_URI") or environ.get("REQUEST_URI")
    if raw:
        if raw.startswith(("http://", "https://")):  # absolute form: keep only path and query
            raw = "/" + raw.split("://", 1)[1].partition("/")[2]
        return raw
    path = quote(environ.get("PATH_INFO", ""), safe="/~!$&'()*+,;=:@%")
    query = environ.get("QUERY_STRING", "")
    return path + (f"?{query}" if query else "")


def _header(environ: dict[str, Any], name: str) -> str | None:
    if name == "content-type":
        return environ.get("CONTENT_TYPE")
    if name == "content-length":
        return environ.get("CONTENT_LENGTH")
    return environ.get("HTTP_" + name.upper().replace("-", "_"))


def _authorization_fields(text: str) -> dict[str, str]:
    fields = {}
    for part in text.split(","):
        key, _, value = part.strip().partition("=")
        fields[key] = value
    return fields


def _raw_query_params(query: str) -> dict[str, str]:
    params: dict[str, str] = {}
    for pair in query.split("&"):
        key, _, value = pair.partition("=")
        params.setdefault(unquote(key), unquote(value))
    return params


def _parse_timestamp(text: str) -> datetime | None:
    """`20260514T093000Z` (SIGV4_TIMESTAMP); by hand, since strptime costs more than the whole HMAC chain."""
    if len(text) != 16 or text[8] != "T" or text[15] != "Z" or not (text[:8] + text[9:15]).isdigit():
        return None
    try:
        return datetime(int(text[0:4]), int(text[4:6]), int(text[6:8]), int(text[9:11]), int(text[11:13]),
                        int(text[13:15]), tzinfo=UTC)
    except ValueError:
        return None


def _form_fields(environ: dict[str, Any], body: bytes) -> dict[str, str]:
    """The text fields of a multipart form, names lower-cased (S3 matches form field names case-insensitively)."""
    from werkzeug.formparser import parse_form_data

    form_environ = {"REQUEST_METHOD": "POST", "CONTENT_TYPE": environ.get("CONTENT_TYPE", ""),
                    "CONTENT_LENGTH": str(len(body)), "wsgi.input": io.BytesIO(body)}
    _stream, form, _files = parse_form_data(form_environ)
    return {key.lower(): value for key, value in form.items()}
