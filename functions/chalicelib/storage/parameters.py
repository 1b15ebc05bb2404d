"""SSM Parameter Store: the deployed stack's public URL (`DREM_PUBLIC_URL_PARAMETER`), read once per process.

The stack writes the parameter from the CloudFront distribution (or the custom domain) on every deploy, so the
functions know their public URL from the first request of the first deploy on, and a redeploy never serves the local
fallback URL (docs/deploy.md).
"""
from __future__ import annotations

from typing import TYPE_CHECKING

from chalicelib.storage.aws_errors import call
from chalicelib.storage.clients import client_for

if TYPE_CHECKING:
    from chalicelib.settings import Settings


def read_parameter(name: str, settings: Settings) -> str:
    """The value of SSM parameter `name` (a client built from `settings`: get_settings is still being made)."""
    ssm = client_for("ssm", settings.region, settings.endpoint_url)
    return str(call(ssm, "get_parameter", "The stack's public URL parameter", Name=name)["Parameter"]["Value"])
