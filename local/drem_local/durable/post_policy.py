"""Browser-form uploads (S3 presigned POST) checked the way S3 checks them, because moto does not.

moto stores whatever a form POST carries: it ignores the policy's signature, expiry, `content-length-range` and key
conditions, so any racer holding one upload ticket (or none) could write any key of any bucket and fill the disk.
`PostPolicyGuard.refusal` runs before moto (and before the journal) and answers as S3 would:

* the form must carry a `policy` signed with SigV4 (`x-amz-algorithm` AWS4-HMAC-SHA256, `x-amz-credential`,
  `x-amz-signature` = HMAC of the base64 policy with the credential's signing key) by a credential the stack knows;
* the policy must not have expired;
* every condition must hold: `{"bucket": ...}`, `{"key": ...}` / `["eq", "$key", ...]`, `["starts-with", "$key",
  ...]` (and the same for the other fields), and `["content-length-range", min, max]` against the file's size;
* every form field except `policy`, `x-amz-signature`, `file` and `x-ignore-*` must appear in the conditions.

Modelled on S3's documented rules (docs.aws.amazon.com/AmazonS3/latest/API/sigv4-HTTPPOSTConstructPolicy.html,
sigv4-post-example.html) and MinIO's implementation of them (minio/minio `cmd/postpolicyform.go`, `checkPostPolicy`
and `parsePostPolicyForm`; errors EntityTooLarge / EntityTooSmall for the size range, AccessDenied "Invalid according
to Policy: ..." for the rest). A body larger than `max_body_bytes` is refused from its Content-Length, unread.
"""
from __future__ import annotations

import base64
import binascii
import hashlib
import hmac
import io
import json
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any
from xml.sax.saxutils import escape

from werkzeug.formparser import parse_form_data

# Form fields S3 never requires in the conditions (AWS: "except x-amz-signature, file, policy, and field names that
# have an x-ignore- prefix"); the field names are case-insensitive.
_EXEMPT_FIELDS = frozenset({"policy", "x-amz-signature", "file"})


@dataclass(frozen=True)
class Refusal:
    status: str  # e.g. "403 Forbidden"
    code: str
    message: str
    extra: tuple[tuple[str, str], ...] = ()

    def body(self) -> bytes:
        details = "".join(f"<{name}>{escape(value)}</{name}>" for name, value in self.extra)
        return (f'<?xml version="1.0" encoding="UTF-8"?>\n<Error><Code>{self.code}</Code>'
                f"<Message>{escape(self.message)}</Message>{details}</Error>").encode()


def _denied(message: str) -> Refusal:
    return Refusal("403 Forbidden", "AccessDenied", message)


def is_form_upload(environ: Mapping[str, Any]) -> bool:
    """Any POST of multipart/form-data, whatever its query string: S3 and MinIO treat it as POST Object.

    MinIO's router (minio/minio `cmd/api-router.go`) sends every bucket POST whose Content-Type holds
    multipart/form-data to `PostPolicyBucketHandler` before it looks at `?delete`, and S3's POST Object is the form
    upload whatever else the URL carries. moto instead reads the query (and the form's fields) as the operation, so a
    form posted to `{url}?x=1` or `{url}?delete` used to pass here unchecked; it is now always held to its policy.
    """
    return (environ.get("REQUEST_METHOD", "").upper() == "POST"
            and "multipart/form-data" in environ.get("CONTENT_TYPE", "").lower())


class PostPolicyGuard:
    def __init__(self, secret_for: Callable[[str], str | None], *, max_body_bytes: int,
                 now: Callable[[], datetime] = lambda: datetime.now(UTC)) -> None:
        self._secret_for = secret_for
        self.max_body_bytes = max_body_bytes
        self._now = now

    def refusal_before_reading(self, environ: Mapping[str, Any]) -> Refusal | None:
        length = str(environ.get("CONTENT_LENGTH") or "").strip()
        if not length.isascii() or not length.isdigit() or len(length) > 15:
            return Refusal("411 Length Required", "MissingContentLength",
                           "You must provide the Content-Length HTTP header.")
        if int(length) > self.max_body_bytes:
            return _too_large(int(length), self.max_body_bytes)
        return None

    def refusal(self, environ: Mapping[str, Any], body: bytes) -> Refusal | None:
        """None when S3 would accept this form upload; otherwise the error S3 would answer with."""
        problem = self._policy_refusal(environ, body)
        if problem is None and (environ.get("QUERY_STRING") or environ.get("HTTP_X_AMZ_TARGET")):
            # moto would act on the query (`?delete` runs DeleteObjects on the form's file as its XML, `?uploads`
            # starts a multipart upload); drem's forms never carry one, and DeleteObjects needs a signed request.
            return _denied("A browser upload form is posted to the bucket's own address, without a query string; "
                           "deleting objects or any other operation needs a signed request.")
        return problem

    def _policy_refusal(self, environ: Mapping[str, Any], body: bytes) -> Refusal | None:
        fields, file_size = _form(environ, body)
        if file_size is None:
            return Refusal("400 Bad Request", "InvalidArgument", "POST requires exactly one file upload per request.")
        policy_b64 = fields.get("policy")
        if not policy_b64:
            return _denied("Bucket POST must contain a field named 'policy'; anonymous form uploads are refused.")
        problem = self._signature_problem(fields, policy_b64)
        if problem:
            return _denied(problem)
        try:
            policy = json.loads(base64.b64decode(policy_b64, validate=True))
            expiration = datetime.fromisoformat(policy["expiration"].replace("Z", "+00:00"))
            conditions = policy["conditions"]
            if not isinstance(conditions, list):
                raise TypeError
        except (binascii.Error, ValueError, KeyError, TypeError, AttributeError, RecursionError):
            return Refusal("400 Bad Request", "InvalidPolicyDocument",
                           "Invalid Policy: the policy is not base64 JSON with expiration and conditions.")
        if expiration.tzinfo is None or expiration <= self._now():
            return _denied("Invalid according to Policy: Policy expired.")
        fields = {**fields, "bucket": _bucket_of(environ)}
        return _foreign_redirect(fields) or _check_conditions(conditions, fields, file_size)

    def _signature_problem(self, fields: Mapping[str, str], policy_b64: str) -> str | None:
        if fields.get("x-amz-algorithm") != "AWS4-HMAC-SHA256":
            return "Only AWS4-HMAC-SHA256 signed policies are accepted here."
        scope = fields.get("x-amz-credential", "").split("/")
        if len(scope) != 5 or scope[3] != "s3" or scope[4] != "aws4_request":
            return "The x-amz-credential field is malformed."
        access_key, day, region = scope[0], scope[1], scope[2]
        secret = self._secret_for(access_key)
        if secret is None:
            return "The AWS Access Key Id you provided does not exist in our records."
        expected = hmac.new(_signing_key(secret, day, region), policy_b64.encode(), hashlib.sha256).hexdigest()
        if not hmac.compare_digest(expected, fields.get("x-amz-signature", "")):
            return "The request signature we calculated does not match the signature you provided."
        return None


def _signing_key(secret: str, day: str, region: str) -> bytes:
    key = f"AWS4{secret}".encode()
    for part in (day, region, "s3", "aws4_request"):
        key = hmac.new(key, part.encode(), hashlib.sha256).digest()
    return key


def _form(environ: Mapping[str, Any], body: bytes) -> tuple[dict[str, str], int | None]:
    """The text fields (names lower-cased, as S3 matches them) and the size of the single file, or None."""
    form_environ = {**environ, "wsgi.input": io.BytesIO(body), "CONTENT_LENGTH": str(len(body))}
    _stream, form, files = parse_form_data(form_environ, max_form_memory_size=1024 * 1024)
    fields: dict[str, str] = {}
    for name, values in form.lists():
        if len(values) != 1:
            return fields, None  # a field given twice: S3 refuses the request
        fields[name.lower()] = values[0]
    uploads = [upload for _name, upload in files.items(multi=True)]
    if len(uploads) != 1:
        return fields, None
    upload = uploads[0]
    upload.stream.seek(0, io.SEEK_END)
    return fields, upload.stream.tell()


def _foreign_redirect(fields: Mapping[str, str]) -> Refusal | None:
    """A redirect after upload may only name a path on this same site.

    S3 sends the browser to `success_action_redirect` (or the older `redirect`) with a 303 when the policy allows it;
    here the storage answers under the app's own address (/_storage), so any other origin would turn drem's address
    into an open redirect. drem's own forms carry none; a relative path ("/..." but not "//host") stays allowed."""
    for name in ("success_action_redirect", "redirect"):
        target = fields.get(name)
        if target is None:
            continue
        if not target.startswith("/") or target.startswith("//") or "\\" in target or not target.isprintable():
            return _denied(f"Invalid according to Policy: {name} may only name a path on this site.")
    return None


def _bucket_of(environ: Mapping[str, Any]) -> str:
    path = environ.get("PATH_INFO", "").strip("/")
    if path:
        return path.split("/", 1)[0]
    return environ.get("HTTP_HOST", "").split(".", 1)[0]  # virtual-hosted style: bucket.host


def _check_conditions(conditions: list[Any], fields: Mapping[str, str], file_size: int) -> Refusal | None:
    covered = {"bucket"}
    for condition in conditions:
        if isinstance(condition, dict) and len(condition) == 1:
            (name, value), = condition.items()
            operator, field, expected = "eq", str(name).lower(), value
        elif _is_size_range(condition):
            try:
                low, high = int(condition[1]), int(condition[2])
            except (TypeError, ValueError):
                return _malformed(condition)
            if file_size > high:
                return _too_large(file_size, high)
            if file_size < low:
                return Refusal("400 Bad Request", "EntityTooSmall",
                               "Your proposed upload is smaller than the minimum allowed size",
                               (("ProposedSize", str(file_size)), ("MinSizeAllowed", str(low))))
            continue
        elif isinstance(condition, list) and len(condition) == 3 and str(condition[1]).startswith("$"):
            operator, field, expected = str(condition[0]).lower(), str(condition[1])[1:].lower(), condition[2]
        else:
            return _malformed(condition)
        if not isinstance(expected, str) or operator not in ("eq", "starts-with"):
            return _malformed(condition)
        actual = fields.get(field, "")
        holds = actual == expected if operator == "eq" else actual.startswith(expected)
        if not holds:
            return _denied(f"Invalid according to Policy: Policy Condition failed: {json.dumps(condition)}")
        covered.add(field)
    extra = sorted(name for name in fields
                   if name not in covered and name not in _EXEMPT_FIELDS and not name.startswith("x-ignore-"))
    if extra:
        return _denied(f"Invalid according to Policy: Extra input fields: {', '.join(extra)}")
    if "key" not in covered:
        return _denied("Invalid according to Policy: the policy has no condition on the key.")
    return None


def _is_size_range(condition: Any) -> bool:
    return isinstance(condition, list) and len(condition) == 3 and str(condition[0]).lower() == "content-length-range"


def _malformed(condition: Any) -> Refusal:
    return Refusal("400 Bad Request", "InvalidPolicyDocument",
                   f"Invalid Policy: Invalid Condition: {json.dumps(condition, default=str)[:200]}")


def _too_large(size: int, maximum: int) -> Refusal:
    return Refusal("400 Bad Request", "EntityTooLarge", "Your proposed upload exceeds the maximum allowed size",
                   (("ProposedSize", str(size)), ("MaxSizeAllowed", str(maximum))))


def refusal_response(refusal: Refusal, start_response: Callable[..., Any]) -> list[bytes]:
    body = refusal.body()
    start_response(refusal.status, [("Content-Type", "application/xml"), ("Content-Length", str(len(body))),
                                    ("Connection", "close")])
    return [body]
