"""`drem aws check`: everything `make deploy` needs, checked before anything is built or uploaded.

Each check answers in one plain sentence: what is missing and what to do. A deploy that would stop late (after
minutes of bundling, or halfway through CloudFormation) stops here instead, at once, with every problem listed.

- AWS credentials (the default chain: environment, ~/.aws, SSO) that AWS accepts (STS GetCallerIdentity);
- a region;
- Node.js of a supported major version (the CDK CLI and aws-cdk-lib's jsii runtime run on it; Node 20 reached its
  end of life on 2026-04-30, and jsii warns on every call);
- a running Docker engine (`cdk deploy` builds the live-page server's image, and the booth's with BOOTH=1);
- the PDF fonts (`drem build` copies them into the Lambda bundle);
- the flag images and htmx (copied from node_modules by `make install`; without them the pages lose their flags).
"""
from __future__ import annotations

import os
import re
import shutil
import subprocess
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

# The Node.js majors drem deploys with: 22 is the active LTS line (end of life 2027-04-30); 24 works too.
NODE_MAJORS = (22, 24)
NODE_PIN = "Node.js 22 LTS"
COMMAND_TIMEOUT_S = 20.0
STS_TIMEOUT_S = 10


@dataclass(frozen=True)
class Check:
    name: str
    ok: bool
    sentence: str


def credentials_and_region(session: Any = None) -> list[Check]:
    """Credentials that AWS accepts, and a region: two checks, as both come from the same AWS configuration."""
    import boto3
    from botocore.config import Config
    from botocore.exceptions import BotoCoreError, ClientError

    session = session or boto3.session.Session()
    # botocore reads AWS_DEFAULT_REGION and the profile; the CDK CLI also takes AWS_REGION.
    region = session.region_name or os.environ.get("AWS_REGION")
    region_check = (Check("region", True, f"AWS region: {region}.") if region else Check(
        "region", False, "No AWS region is set: run `export AWS_DEFAULT_REGION=eu-west-1` (your region) or add "
        "`region = ...` to your profile in ~/.aws/config, then run `make deploy` again."))
    if session.get_credentials() is None:
        return [Check("credentials", False, "No AWS credentials were found: run `aws configure` (or `aws sso login "
                      "--profile NAME` and `export AWS_PROFILE=NAME`), then run `make deploy` again."), region_check]
    config = Config(connect_timeout=STS_TIMEOUT_S, read_timeout=STS_TIMEOUT_S, retries={"total_max_attempts": 1})
    try:
        identity = session.client("sts", region_name=region or "us-east-1",
                                  config=config).get_caller_identity()
    except ClientError as error:
        code = error.response.get("Error", {}).get("Code", "an error")
        return [Check("credentials", False, f"AWS refused your credentials ({code}): they may have expired; sign in "
                      "again (`aws sso login`, or new keys with `aws configure`), then run `make deploy` again."),
                region_check]
    except BotoCoreError as error:
        return [Check("credentials", False, f"AWS could not be reached to check your credentials ({error}): check "
                      "this laptop's internet connection, then run `make deploy` again."), region_check]
    return [Check("credentials", True, f"AWS account {identity.get('Account')} as {identity.get('Arn')}."),
            region_check]


def node_version(run: Callable[[list[str]], str | None] | None = None) -> Check:
    run = run or _output
    text = run(["node", "--version"])
    if text is None:
        return Check("node", False, f"Node.js is not installed: install {NODE_PIN} (https://nodejs.org, or your "
                     "package manager's nodejs 22), then run `make deploy` again.")
    found = re.match(r"v?(\d+)\.", text.strip())
    major = int(found.group(1)) if found else 0
    if major not in NODE_MAJORS:
        return Check("node", False, f"Node.js {text.strip()} is not supported for deploying (the CDK needs "
                     f"{' or '.join(map(str, NODE_MAJORS))}): install {NODE_PIN}, then run `make deploy` again.")
    return Check("node", True, f"Node.js {text.strip()}.")


def docker_engine(run: Callable[[list[str]], str | None] | None = None) -> Check:
    run = run or _output
    if shutil.which("docker") is None and run is _output:
        return Check("docker", False, "Docker is not installed: the deploy builds the live-page server's container "
                     "image with it; install Docker (Desktop or Engine), start it, then run `make deploy` again.")
    version = run(["docker", "info", "--format", "{{.ServerVersion}}"])
    if not version or not version.strip():
        return Check("docker", False, "Docker is installed but its engine is not running: start Docker Desktop (or "
                     "`sudo systemctl start docker`), then run `make deploy` again.")
    return Check("docker", True, f"Docker engine {version.strip()}.")


def pdf_fonts() -> Check:
    from drem_local.app_source import use_app_source

    use_app_source()
    from chalicelib.formats.pdf_fonts import FONT_FILES, search_dirs

    missing = sorted(name for name in set(FONT_FILES.values())
                     if not any((folder / name).is_file() for folder in search_dirs()))
    if missing:
        return Check("fonts", False, f"The PDF fonts are missing ({', '.join(missing)}): run `sudo apt-get install "
                     "fonts-noto-core fonts-droid-fallback fonts-nanum` (or `make install`), then run `make deploy` "
                     "again.")
    return Check("fonts", True, "PDF fonts installed.")


def web_assets(static_dir: Path | None = None) -> Check:
    if static_dir is None:
        import drem_web

        static_dir = Path(drem_web.__file__).resolve().parent / "static"
    vendor = static_dir / "vendor"
    flags = list((vendor / "flags").glob("*.svg")) if (vendor / "flags").is_dir() else []
    missing = [what for what, present in (("the flag images", len(flags) > 200),
                                          ("htmx", (vendor / "htmx.min.js").is_file())) if not present]
    if missing:
        return Check("web assets", False, f"{' and '.join(missing).capitalize()} are missing from {vendor}: run "
                     "`make install` (it runs `npm ci` and copies them), then run `make deploy` again.")
    return Check("web assets", True, f"{len(flags)} flag images and htmx in place.")


def run_checks() -> list[Check]:
    return [*credentials_and_region(), node_version(), docker_engine(), pdf_fonts(), web_assets()]


def _output(command: list[str]) -> str | None:
    """The command's standard output, or None when it is missing, fails or hangs."""
    try:
        done = subprocess.run(command, capture_output=True, text=True, timeout=COMMAND_TIMEOUT_S)
    except (OSError, subprocess.TimeoutExpired):
        return None
    return done.stdout if done.returncode == 0 else None
