"""The app's configuration: one pydantic model over the environment contract, read lazily.

Chalice sets `.chalice/config.json` variables only while a handler runs, so nothing here reads `os.environ` at import.
`get_settings()` caches the first read; tests call `get_settings.cache_clear()` after changing the environment.
"""
from __future__ import annotations

import os
from collections.abc import Callable, Mapping
from functools import lru_cache
from pathlib import Path
from urllib.parse import urlsplit

from pydantic import BaseModel, ConfigDict, Field, field_validator

from chalicelib import base_path
from drem_infra import resources


class Settings(BaseModel):
    model_config = ConfigDict(frozen=True)

    region: str
    stage: str = "local"
    user_pool_id: str | None = None
    user_pool_client_id: str | None = None
    # Set only locally (the durable moto server); None means real AWS endpoints.
    endpoint_url: str | None = None
    # The address people use, with the sub-path the site lives under if any (https://example.org/drem): every
    # absolute link (QR codes, landing and overlay addresses, activation commands) starts with it.
    public_url: str = "http://127.0.0.1:8000"
    # The path prefix the site is served under when no proxy header or API Gateway stage says so (chalicelib.base_path).
    base_path: str = ""
    state_dir: Path = Path(".drem")
    # Local stacks: the installation's token signing key (the only key local tokens may be signed with). None on AWS,
    # where Cognito's published JWKS is trusted.
    token_key_file: Path | None = None
    # The live server (drem_live) the public pages' live regions subscribe to: its origin locally
    # (http://host:8002); unset on AWS, where CloudFront routes /live/* to it on the pages' own origin.
    live_url: str | None = None
    # Where the live server's processes listen for "this event changed" (chalicelib.live_wake); "" = it only polls.
    live_wake_dir: str = ""
    # On AWS: the secret the writer's POST to the live origin's /live/wake carries (chalicelib.live_wake_http); "" =
    # no wake-ups over HTTP.
    live_wake_secret: str = Field(default="", repr=False)
    # A scrutineering worker drives queued models although this process has no simulator: on AWS, the learning booth's
    # task runs one (drem_infra.booth_service), so the functions queue new models for it.
    scrutineering_worker: bool = False
    # How often a car's long poll re-reads its assignment from storage, for writes its own process did not make (a
    # write in the same process wakes it at once: chalicelib.domain.assignment_signals). On AWS every write is made
    # elsewhere (another Lambda), so this interval is how late a car hears of a change there.
    assignment_recheck_s: float = Field(default=5.0, gt=0.0, le=20.0)

    @classmethod
    def from_env(cls, env: Mapping[str, str]) -> Settings:
        endpoint_url = env.get("AWS_ENDPOINT_URL") or None
        state_dir = env.get("DREM_STATE_DIR") or ".drem"
        token_key_file = env.get(resources.TOKEN_SIGNING_KEY_ENV) or (
            str(Path(state_dir) / resources.TOKEN_SIGNING_KEY_FILE) if endpoint_url else None)
        values = {
            "region": env.get("AWS_DEFAULT_REGION") or env.get("AWS_REGION") or "us-east-1",
            "stage": env.get("DREM_STAGE") or "local",
            "user_pool_id": env.get("DREM_USER_POOL_ID") or None,
            "user_pool_client_id": env.get("DREM_USER_POOL_CLIENT_ID") or None,
            "endpoint_url": endpoint_url,
            "public_url": env.get("DREM_PUBLIC_URL") or "http://127.0.0.1:8000",
            "base_path": env.get("DREM_BASE_PATH") or "",
            "state_dir": state_dir,
            "token_key_file": token_key_file,
            "live_url": _http_origin_or_none(env.get("DREM_LIVE_URL") or ""),
            "live_wake_dir": env.get("DREM_LIVE_WAKE_DIR") or "",
            "live_wake_secret": env.get("DREM_LIVE_WAKE_SECRET") or "",
            "scrutineering_worker": env.get(resources.SCRUTINEERING_WORKER_ENV) == "1",
            "assignment_recheck_s": env.get(resources.ASSIGNMENT_RECHECK_ENV) or 5.0,
        }
        settings = cls.model_validate(values)
        if settings.base_path and urlsplit(settings.public_url).path in ("", "/"):
            # Absolute links (QR codes, landing and overlay addresses, activation commands) need the sub-path too.
            settings = settings.model_copy(update={"public_url": settings.public_url.rstrip("/") + settings.base_path})
        return settings

    @field_validator("live_wake_secret")
    @classmethod
    def _long_wake_secret(cls, value: str) -> str:
        if value and len(value) < 16:
            raise ValueError("DREM_LIVE_WAKE_SECRET must be a secret of at least 16 characters")
        return value

    @field_validator("base_path")
    @classmethod
    def _plain_base_path(cls, value: str) -> str:
        if not value:
            return ""
        normalised = base_path.normalise(value)
        if normalised is None:
            raise ValueError(f"DREM_BASE_PATH must be a plain path such as /drem, not {value!r}")
        return normalised

    @property
    def cookie_secure(self) -> bool:
        # Browsers drop Secure cookies on plain http, which would make local sign-in impossible.
        return self.public_url.lower().startswith("https://")

    @property
    def live_stream_base(self) -> str | None:
        """The prefix of the live server's URLs for the pages ("" = the pages' own origin); None = no live server, the
        live regions poll the app. Locally only an explicit DREM_LIVE_URL means one runs (drem up sets it)."""
        if self.live_url:
            return self.live_url
        return None if self.endpoint_url else ""

    @property
    def live_origin(self) -> str | None:
        """The live server's origin when it is another one than the pages' (CSP connect-src must allow it)."""
        if not self.live_url:
            return None
        parts = urlsplit(self.live_url)
        return f"{parts.scheme}://{parts.netloc}"

    @property
    def local_identity(self) -> bool:
        """The user pool is drem's local Cognito (tokens pinned to the installation key, no email delivery)."""
        return self.token_key_file is not None

    @property
    def drive_dir(self) -> Path | None:
        """Where a local stack's app keeps the booth's live drives while they are driven: under the state dir, so a
        drive survives the app being killed and can still be saved (chalicelib.domain.booth_drive). None on AWS."""
        return Path(self.state_dir) / "drives" if self.endpoint_url else None

    @property
    def issuer(self) -> str:
        # Cognito (and moto) always issue for the AWS host, even when the API is served from a local endpoint.
        return f"https://cognito-idp.{self.region}.amazonaws.com/{self.user_pool_id}"

    @property
    def jwks_url(self) -> str:
        if self.endpoint_url:
            return f"{self.endpoint_url.rstrip('/')}/{self.user_pool_id}/.well-known/jwks.json"
        return f"{self.issuer}/.well-known/jwks.json"

    @property
    def storage_label(self) -> str:
        return self.endpoint_url or "aws"

    def table(self, logical: str) -> str:
        return resources.table_name(self.stage, logical)

    def bucket(self, logical: str) -> str:
        return resources.bucket_name(self.stage, logical)


def _http_origin_or_none(url: str) -> str | None:
    """An http(s) URL without a trailing slash; anything else (it ends up in the CSP and in pages) is no URL."""
    parts = urlsplit(url.strip())
    if parts.scheme not in ("http", "https") or not parts.netloc or any(c in url for c in " ;,'\"<>"):
        return None
    return url.strip().rstrip("/")


# Names the SSM parameter holding the public URL, when the deploy could not put it in DREM_PUBLIC_URL: CloudFront's
# domain is known only once the distribution exists, and the functions cannot refer to it (a dependency cycle).
PUBLIC_URL_PARAMETER_ENV = "DREM_PUBLIC_URL_PARAMETER"
# Reads a parameter (name, settings without it) -> its value; set by the composition root (chalicelib.services), so
# this module needs no AWS client.
_parameter_reader: Callable[[str, Settings], str] | None = None


def use_parameter_reader(reader: Callable[[str, Settings], str] | None) -> None:
    global _parameter_reader
    _parameter_reader = reader
    get_settings.cache_clear()


@lru_cache(maxsize=1)
def get_settings() -> Settings:
    """The settings from the environment. On AWS the public URL may come from the stack's SSM parameter, read once per
    process; a failed read raises (that request fails, the next one reads again) rather than serving the local
    fallback URL, whose links and cookies would be wrong."""
    settings = Settings.from_env(os.environ)
    parameter = os.environ.get(PUBLIC_URL_PARAMETER_ENV) or ""
    if parameter and not os.environ.get("DREM_PUBLIC_URL") and _parameter_reader is not None:
        url = _http_origin_or_none(_parameter_reader(parameter, settings))
        if url is None:
            raise RuntimeError(f"SSM parameter {parameter} does not hold an http(s) URL")
        settings = Settings.from_env({**os.environ, "DREM_PUBLIC_URL": url})
    return settings
