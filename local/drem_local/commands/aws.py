"""`drem aws`: what `make deploy` does after `cdk deploy`, and what an organiser needs from a deployment.

    drem aws check                                         # before deploying: credentials, region, Node, Docker, ...
    drem aws record --stage S --outputs cdk-outputs.json   # write .drem-aws/S.json from the stack outputs
    drem aws admin --stage S [--username admin --email E]  # create the first admin; prints its password once
    drem aws show --stage S [--env]                        # the public URL, names; --env: shell export lines

AWS credentials come from the default chain (environment, ~/.aws, SSO), as for the CDK CLI.
"""
from __future__ import annotations

import argparse
import json
import shlex
import sys
from pathlib import Path

HELP = ("check this laptop can deploy (`make deploy` runs it first); after a deploy: record the stack outputs, create "
        "the first admin, show the deployment")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--dir", type=Path, default=Path(".drem-aws"),
                        help="where deployment records live (default .drem-aws)")
    actions = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    actions.add_parser("check", help="check credentials, region, Node.js, Docker, fonts and flag images before a "
                       "deploy; one sentence for each problem (exit 1 if any)")
    record = actions.add_parser("record", help="write .drem-aws/STAGE.json from `cdk deploy --outputs-file` JSON")
    record.add_argument("--stage", required=True)
    record.add_argument("--outputs", type=Path, required=True, help="the CDK outputs file")
    admin = actions.add_parser("admin", help="create the first admin (its password is printed once)")
    admin.add_argument("--stage", required=True)
    admin.add_argument("--username", default="admin")
    admin.add_argument("--email", default=None, help="the admin's email (default admin@drem.local)")
    show = actions.add_parser("show", help="the deployment's public URL and resource names")
    show.add_argument("--stage", required=True)
    show.add_argument("--env", action="store_true", help="print `export DREM_...=...` lines for a shell")


def run(args: argparse.Namespace) -> int:
    from drem_local.deployment import Deployment, DeploymentError

    if args.action == "check":
        return _check()
    try:
        if args.action == "record":
            deployment = Deployment.from_cdk_outputs(_read_json(args.outputs), args.stage)
            path = deployment.save(args.dir)
            print(f"Recorded deployment {args.stage} in {path}: {deployment.public_url}")
            return 0
        deployment = Deployment.load(args.stage, args.dir)
    except DeploymentError as exc:
        print(f"drem aws {args.action}: {exc}", file=sys.stderr)
        return 1
    if args.action == "admin":
        return _admin(deployment, args.username, args.email)
    if args.env:
        for name, value in sorted(deployment.environment().items()):
            print(f"export {name}={shlex.quote(value)}")
    else:
        print(json.dumps({"public_url": deployment.public_url, "region": deployment.region,
                          "user_pool_id": deployment.user_pool_id, "tables": deployment.tables,
                          "buckets": deployment.buckets}, indent=2))
    return 0


def _check() -> int:
    from drem_local.aws_preflight import run_checks

    checks = run_checks()
    for check in checks:
        print(f"{'ok ' if check.ok else 'NO '} {check.name}: {check.sentence}")
    problems = [check for check in checks if not check.ok]
    if problems:
        print(f"drem aws check: {len(problems)} problem{'s' if len(problems) > 1 else ''} to fix before deploying "
              "(nothing was built or uploaded).", file=sys.stderr)
        return 1
    print("Ready to deploy.")
    return 0


def _admin(deployment, username: str, email: str | None) -> int:
    from botocore.exceptions import BotoCoreError, ClientError

    from drem_local.bootstrap import StackOutputs, clients_for, ensure_admin

    outputs = StackOutputs(stage=deployment.stage, region=deployment.region, user_pool_id=deployment.user_pool_id,
                           user_pool_client_id=deployment.user_pool_client_id, tables=deployment.tables,
                           buckets=deployment.buckets)
    try:
        admin = ensure_admin(clients_for(None, deployment.region), outputs, username, email=email)
    except (BotoCoreError, ClientError) as exc:
        print(f"drem aws admin: the user pool refused ({exc})", file=sys.stderr)
        return 1
    if admin.created:
        print(f"Admin {admin.username} created. Password (shown only now; change it after signing in): "
              f"{admin.password}")
    else:
        print(f"Admin {admin.username} already exists; its password was not changed.")
    print(f"Sign in at {deployment.public_url}/login")
    return 0


def _read_json(path: Path) -> dict:
    from drem_local.deployment import DeploymentError

    try:
        return json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise DeploymentError(f"cannot read {path}: {exc}") from None
