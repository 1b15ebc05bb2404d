"""Who may talk to the local storage server: only requests signed with the installation's keys.

Runs before the journal and before moto, for every request:
- `/moto-api/...` (moto's dashboard, `data.json` with every plaintext password, `reset`) is not served at all;
- CORS preflights are refused and moto's `Access-Control-*` answers are stripped: drem's pages never call storage
  from the browser across origins (uploads and downloads go through the app's same-origin gateway, below);
- a user pool's JWKS and OpenID configuration stay readable unsigned, as on AWS (they hold public keys only);
- everything else must carry a valid SigV4 signature (drem_local.durable.sigv4).
The app server forwards `/_storage/...` (presigned S3 GETs and upload forms from racers' browsers and cars on the
venue network) here unchanged; those must be presigned S3 requests, and are handed to moto without the prefix.
"""
from __future__ import annotations

import json
import re
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any
from xml.sax.saxutils import escape

from drem_local.durable.sigv4 import Refusal, raw_target, verify
from drem_local.storage_keys import StorageKeys

# The app server's same-origin path to storage (drem_local.appserver); chalicelib.storage.clients presigns for it.
GATEWAY_PATH = "/_storage"
_PUBLIC_COGNITO_PATH = re.compile(r"^/[\w-]+_[0-9A-Za-z]+/\.well-known/(jwks\.json|openid-configuration)$")


@dataclass
class StorageGuard:
    keys: StorageKeys

    def check(self, environ: dict[str, Any], body: bytes) -> Refusal | None:
        """None when the request may go on to moto (possibly rewritten in place); otherwise why not."""
        path = environ.get("PATH_INFO", "")
        method = environ.get("REQUEST_METHOD", "GET").upper()
        if path == "/moto-api" or path.startswith("/moto-api/"):
            return Refusal(404, "NotFound", "moto's admin API is not served by drem's storage server")
        if method == "OPTIONS":
            return Refusal(403, "AccessDenied", "cross-origin requests to drem's storage server are not allowed")
        if method in ("GET", "HEAD") and _PUBLIC_COGNITO_PATH.match(path):
            return None
        through_gateway = path == GATEWAY_PATH or path.startswith(GATEWAY_PATH + "/")
        verdict = verify(environ, body, self.keys)
        if isinstance(verdict, Refusal):
            return verdict
        if through_gateway:
            if verdict.form not in ("query", "post") or verdict.service != "s3":
                return Refusal(403, "AccessDenied", "only presigned downloads and upload forms pass the app's "
                                                    "storage gateway")
            _strip_gateway_prefix(environ)
        return None


def _strip_gateway_prefix(environ: dict[str, Any]) -> None:
    """What moto must see: the path without the prefix, and our own host (not the venue address the link named)."""
    environ["PATH_INFO"] = environ["PATH_INFO"][len(GATEWAY_PATH):] or "/"
    target = raw_target(environ)
    for key in ("RAW_URI", "REQUEST_URI"):
        if key in environ:
            environ[key] = target[len(GATEWAY_PATH):] or "/"
    environ["HTTP_HOST"] = f"{environ.get('SERVER_NAME', '127.0.0.1')}:{environ.get('SERVER_PORT', '80')}"


def without_cors(headers: list[tuple[str, str]]) -> list[tuple[str, str]]:
    return [(name, value) for name, value in headers if not name.lower().startswith("access-control-")]


def refuse(refusal: Refusal, environ: dict[str, Any], start_response: Callable[..., Any]) -> Iterable[bytes]:
    """The refusal in the error shape the caller's SDK parses: JSON for DynamoDB/Cognito, XML for S3."""
    if environ.get("HTTP_X_AMZ_TARGET"):
        body = json.dumps({"__type": refusal.code, "message": refusal.message}).encode()
        content_type = "application/x-amz-json-1.0"
    else:
        body = (f"<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<Error><Code>{escape(refusal.code)}</Code>"
                f"<Message>{escape(refusal.message)}</Message></Error>").encode()
        content_type = "application/xml"
    reason = {400: "Bad Request", 403: "Forbidden", 404: "Not Found", 507: "Insufficient Storage"}.get(refusal.status,
                                                                                                     "Error")
    start_response(f"{refusal.status} {reason}", [("Content-Type", content_type),
                                                  ("Content-Length", str(len(body))),
                                                  ("x-amzn-ErrorType", refusal.code)])
    return [body]
