"""The one definition of drem's AWS resources.

Everything that names or shapes a table, bucket or user pool reads it from here: the CDK stack (AWS), the local
bootstrap (moto), the app's storage adapters and the infra tests. Pure Python on purpose: this module is vendored
into the Lambda bundle, so it must not import boto3 or aws_cdk.
"""
from __future__ import annotations

import os
import secrets
import string
from collections.abc import Mapping
from dataclasses import dataclass, field


@dataclass(frozen=True)
class GsiSpec:
    name: str
    pk: str
    sk: str


@dataclass(frozen=True)
class TableSpec:
    logical: str
    pk: str = "pk"
    sk: str = "sk"
    gsis: tuple[GsiSpec, ...] = ()
    # Streams carry NEW_AND_OLD_IMAGES when enabled.
    stream: bool = False

    @property
    def key_attributes(self) -> tuple[str, ...]:
        """Every attribute that appears in a key schema (table or GSI), in first-seen order, each once."""
        names: list[str] = []
        for name in (self.pk, self.sk, *(a for g in self.gsis for a in (g.pk, g.sk))):
            if name not in names:
                names.append(name)
        return tuple(names)


@dataclass(frozen=True)
class CorsSpec:
    allowed_origins: tuple[str, ...] = ("*",)
    allowed_methods: tuple[str, ...] = ("GET", "HEAD", "POST", "PUT")
    allowed_headers: tuple[str, ...] = ("*",)
    expose_headers: tuple[str, ...] = ("ETag",)
    max_age_seconds: int = 3000


# Browsers upload straight to S3 with presigned POST/PUT from wherever the app is served (laptop IP, CloudFront).
# The presigned signature, not the origin, is what authorises an upload.
BROWSER_UPLOAD_CORS = CorsSpec()


@dataclass(frozen=True)
class BucketSpec:
    logical: str
    cors: bool = True
    # On AWS, "Object Created" events go to EventBridge so the app can validate uploads (Chalice cannot package
    # S3 notifications). Locally the app is told about uploads directly.
    eventbridge: bool = False


# Generated passwords use a few of the symbols Cognito counts as symbols: none is a quote, a backslash or a space.
PASSWORD_SYMBOLS = "!#%*+-=?@^_"


@dataclass(frozen=True)
class PasswordPolicy:
    minimum_length: int = 8
    require_lowercase: bool = True
    require_uppercase: bool = True
    require_digits: bool = True
    require_symbols: bool = True
    temporary_password_validity_days: int = 2

    def random_password(self, length: int = 16) -> str:
        """A random password this policy accepts: one character of each required class, the rest from all of them.

        It starts with a letter: a password starting with "-" is read as an option by `drem --password -x…`, and
        people copy these from a terminal into a command line."""
        classes = [chars for chars, required in ((string.ascii_lowercase, self.require_lowercase),
                                                 (string.ascii_uppercase, self.require_uppercase),
                                                 (string.digits, self.require_digits),
                                                 (PASSWORD_SYMBOLS, self.require_symbols)) if required]
        alphabet = string.ascii_letters + string.digits + PASSWORD_SYMBOLS
        chars = [secrets.choice(c) for c in classes]
        chars += [secrets.choice(alphabet) for _ in range(max(length, self.minimum_length) - len(chars) - 1)]
        secrets.SystemRandom().shuffle(chars)
        return secrets.choice(string.ascii_letters) + "".join(chars)


@dataclass(frozen=True)
class CustomAttributeSpec:
    name: str
    mutable: bool = True
    # Cognito custom attributes are String or Number; drem only needs strings.
    data_type: str = "String"


@dataclass(frozen=True)
class UserPoolSpec:
    groups: tuple[str, ...] = ("admin", "operator", "commentator", "registration", "racer")
    custom_attributes: tuple[CustomAttributeSpec, ...] = (CustomAttributeSpec("countryCode"),)
    password_policy: PasswordPolicy = field(default_factory=PasswordPolicy)
    # Exactly the flows the storage adapters call (InitiateAuth USER_PASSWORD_AUTH and REFRESH_TOKEN_AUTH);
    # tests/infra/test_user_pool.py derives them from the code.
    explicit_auth_flows: tuple[str, ...] = (
        "ALLOW_USER_PASSWORD_AUTH",
        "ALLOW_REFRESH_TOKEN_AUTH",
    )
    # Browsers and the CLI are public clients: a secret could not be kept.
    generate_secret: bool = False
    read_attributes: tuple[str, ...] = ("email", "email_verified", "custom:countryCode")
    write_attributes: tuple[str, ...] = ("email", "custom:countryCode")
    # Users sign in with a username; email is required and verified automatically.
    required_attributes: tuple[str, ...] = ("email",)
    auto_verified_attributes: tuple[str, ...] = ("email",)
    self_sign_up: bool = True


TABLES: tuple[TableSpec, ...] = (
    TableSpec("events"),
    TableSpec("races"),
    TableSpec("leaderboards"),
    TableSpec("profiles"),
    TableSpec("fleet"),
    # gsi1 lists every model newest first for operators (gsi1pk "MODELS", gsi1sk "{uploadedAt}#{modelId}").
    TableSpec("models", gsis=(GsiSpec("gsi1", "gsi1pk", "gsi1sk"),)),
    TableSpec("league"),
    # Per-user "tokens issued before this are revoked" records and the pending new-password sign-in steps.
    TableSpec("sessions"),
    # The learning booth (docs/learning.md): runs (`RUN#{runId}`), training jobs (`JOB#{jobId}`) and each racer's
    # active model version (`ACTIVE#{sub}`). gsi1 lists one racer's runs or jobs (`RUNS#{sub}` / `JOBS#{sub}`, by
    # creation time); gsi2 lists everyone's (`RUNS` / `JOBS`), for staff and for the training queue.
    TableSpec("booth", gsis=(GsiSpec("gsi1", "gsi1pk", "gsi1sk"), GsiSpec("gsi2", "gsi2pk", "gsi2sk"))),
)

BUCKETS: tuple[BucketSpec, ...] = (
    # uploads/{sub}/{modelId}.tar.gz -> validated into models/{sub}/..., rejected ones into quarantine/...
    BucketSpec("models", eventbridge=True),
    # runs/{track_id}/{date}/{run_id}/ from the simulator and cars.
    BucketSpec("runs"),
)

USER_POOL = UserPoolSpec()
GROUPS: tuple[str, ...] = USER_POOL.groups

TABLES_BY_LOGICAL: dict[str, TableSpec] = {t.logical: t for t in TABLES}
BUCKETS_BY_LOGICAL: dict[str, BucketSpec] = {b.logical: b for b in BUCKETS}


def _default_name(stage: str, logical: str) -> str:
    return f"drem-{stage}-{logical}"


def table_env_var(logical: str) -> str:
    return f"DREM_TABLE_{logical.upper()}"


def bucket_env_var(logical: str) -> str:
    return f"DREM_BUCKET_{logical.upper()}"


def table_name(stage: str, logical: str, env: Mapping[str, str] | None = None) -> str:
    """Physical table name: `DREM_TABLE_<LOGICAL>` from env if set, else `drem-{stage}-{logical}`."""
    if logical not in TABLES_BY_LOGICAL:
        raise KeyError(f"unknown table {logical!r}; defined tables: {sorted(TABLES_BY_LOGICAL)}")
    env = os.environ if env is None else env
    return env.get(table_env_var(logical)) or _default_name(stage, logical)


def bucket_name(stage: str, logical: str, env: Mapping[str, str] | None = None) -> str:
    """Physical bucket name: `DREM_BUCKET_<LOGICAL>` from env if set, else `drem-{stage}-{logical}`."""
    if logical not in BUCKETS_BY_LOGICAL:
        raise KeyError(f"unknown bucket {logical!r}; defined buckets: {sorted(BUCKETS_BY_LOGICAL)}")
    env = os.environ if env is None else env
    return env.get(bucket_env_var(logical)) or _default_name(stage, logical)


def user_pool_name(stage: str) -> str:
    return _default_name(stage, "users")


def client_name(stage: str) -> str:
    return _default_name(stage, "web")


# The Chalice function (`@app.lambda_function(name=...)`) that validates a finished browser upload. On AWS the CDK
# stack routes the models bucket's "Object Created" events under UPLOADS_PREFIX to it; the bucket's name is only
# known at deploy time, which is why the rule lives in CDK and not in an `@app.on_cw_event` pattern.
UPLOAD_COMPLETE_FUNCTION = "upload_complete"


def public_url_parameter(stage: str) -> str:
    """The SSM parameter the stack writes its public URL to, and the functions read it from at run time."""
    return f"/drem/{stage}/public-url"
UPLOADS_PREFIX = "uploads/"


def stage_environment(stage: str, user_pool_id: str, user_pool_client_id: str,
                      tables: Mapping[str, str], buckets: Mapping[str, str]) -> dict[str, str]:
    """The environment contract the app reads; the local stack and CDK both build it here."""
    env = {"DREM_STAGE": stage, "DREM_USER_POOL_ID": user_pool_id, "DREM_USER_POOL_CLIENT_ID": user_pool_client_id}
    env.update({table_env_var(logical): name for logical, name in tables.items()})
    env.update({bucket_env_var(logical): name for logical, name in buckets.items()})
    return env


# "1" when a scrutineering worker drives the queue although the app's own process has no simulator: the functions on
# AWS, when the stage has the learning booth's task (drem_infra.booth_service), which runs that worker.
SCRUTINEERING_WORKER_ENV = "DREM_SCRUTINEERING_WORKER"

# Seconds between a waiting car's storage re-reads of its assignment (chalicelib.domain.assignment_signals).
ASSIGNMENT_RECHECK_ENV = "DREM_ASSIGNMENT_RECHECK_S"

# Local stacks only: the per-installation RSA key the local Cognito signs tokens with and the app pins (0600 JWK in
# the state dir, generated at the first `drem up`). On AWS, Cognito's own keys (its JWKS) are used instead.
TOKEN_SIGNING_KEY_FILE = "token-signing-key.json"
TOKEN_SIGNING_KEY_ENV = "DREM_TOKEN_KEY_FILE"
