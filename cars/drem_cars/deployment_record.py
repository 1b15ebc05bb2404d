"""The public URL of an AWS deployment, from the record `make deploy STAGE=...` writes: `.drem-aws/STAGE.json`.

`drem car activate --aws` and `drem timer --aws` take their API URL from it, the way `drem export --aws` and
`drem import --aws` take the table names. A car has drem_cars only (no drem_local), so this reads the JSON itself;
its `public_url` (CloudFront's address or the custom domain) is the one thing a device needs. The record holds names
and URLs, never credentials, so copying it to a car or a timer is safe.
"""
from __future__ import annotations

import json
import os
from pathlib import Path

DEFAULT_DIR = Path(".drem-aws")  # relative to where the command runs, as for `drem aws` and export/import
DEFAULT_STAGE = "dev"  # `make deploy`'s default STAGE
STAGE_HELP = "with --aws: the deployed stage (default $DREM_STAGE, else dev, as for `make deploy`)"


class NoDeploymentRecord(RuntimeError):
    """No usable `.drem-aws/STAGE.json`; the message names the file and what writes it."""


def stage_or_default(stage: str | None) -> str:
    return stage or os.environ.get("DREM_STAGE") or DEFAULT_STAGE


def public_url(stage: str, directory: Path = DEFAULT_DIR) -> str:
    """The deployment's public URL (no trailing slash), or NoDeploymentRecord saying which file was looked for."""
    path = (directory / f"{stage}.json").absolute()
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise NoDeploymentRecord(
            f"no deployment record for stage {stage!r}: looked for {path}. `make deploy STAGE={stage}` writes it "
            f"(in .drem-aws/ of the folder it deploys from): run this there, copy that file into .drem-aws/ here, "
            f"or give the URL with --api") from None
    except (OSError, ValueError) as exc:
        raise NoDeploymentRecord(f"{path} is not a drem deployment record ({exc})") from None
    url = data.get("public_url") if isinstance(data, dict) else None
    if not isinstance(url, str) or not url.startswith(("https://", "http://")):
        raise NoDeploymentRecord(f"{path} holds no public URL (public_url): deploy the current version with "
                                 f"`make deploy STAGE={stage}`, or give the URL with --api")
    return url.rstrip("/")


def api_from_arguments(api: str | None, aws: bool, stage: str | None) -> str | None:
    """What `--api URL` / `--aws [--stage STAGE]` choose: the URL given, the recorded public URL, or None (neither).
    NoDeploymentRecord when the record is missing or unusable, or when --stage comes without --aws."""
    if aws:
        return public_url(stage_or_default(stage))
    if stage:
        raise NoDeploymentRecord("--stage goes with --aws (it picks the deployment record .drem-aws/STAGE.json)")
    return api
