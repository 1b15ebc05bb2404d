"""CDK entry point: `cdk synth` / `cdk deploy` from infra_cdk/ (see cdk.json).

Context:
  stage           (default "dev")   names resources drem-{stage}-*; one stack per stage.
  with_app        (default "true")  "false" deploys only tables, buckets and the user pool (no Chalice packaging).
  public_url      optional: the URL people use (QR codes, cookies); without it the functions read CloudFront's (or
                  the custom domain's) from the stack's SSM parameter /drem/{stage}/public-url at run time.
  upload_concurrency  (default 2) reserved concurrency of the upload checker; 0 on an account whose Lambda
                  concurrency quota is below 102.
  domain_name, certificate_arn      optional custom domain for CloudFront (an ACM certificate in us-east-1).
  ses_from, ses_identity_arn        optional: Cognito emails through Amazon SES from this verified identity.
  alarm_email     optional: an address subscribed to the stage's alarm topic (every alarm notifies that topic).
Before packaging the app this vendors drem_infra, drem_leaderboard and drem_web into functions/vendor/, so a
deployment never ships stale copies. The third-party wheels must already be there (`drem build`, which `make deploy`
runs): synth downloads nothing and makes no AWS calls.
"""
from __future__ import annotations

import os
from pathlib import Path

import aws_cdk as cdk

from drem_infra.lambda_bundle import LAMBDA_LOCK, dependencies_current, vendor_packages
from drem_infra.stack import DremStack

FUNCTIONS_DIR = Path(__file__).resolve().parent.parent / "functions"


def main() -> None:
    app = cdk.App()
    stage = app.node.try_get_context("stage") or "dev"
    with_app = str(app.node.try_get_context("with_app") or "true").lower() != "false"
    functions_dir = None
    if with_app:
        # Chalice packaging imports the app; that needs a region even though nothing calls AWS.
        os.environ.setdefault("AWS_DEFAULT_REGION", os.environ.get("CDK_DEFAULT_REGION", "us-east-1"))
        if not dependencies_current(FUNCTIONS_DIR):
            raise SystemExit(f"functions/vendor/ does not hold the wheels of {LAMBDA_LOCK.name}: run `drem build` "
                             "(or `make build`) first; synth never downloads packages")
        vendor_packages(FUNCTIONS_DIR)
        functions_dir = FUNCTIONS_DIR
        # The Chalice construct writes chalice.out/ into the working directory; keep it inside the (ignored) outdir.
        os.chdir(app.outdir)
    context = {name: app.node.try_get_context(name) or None
               for name in ("public_url", "domain_name", "certificate_arn", "ses_from", "ses_identity_arn",
                            "alarm_email")}
    booth = str(app.node.try_get_context("booth") or "false").lower() == "true"  # `make deploy BOOTH=1`
    upload_concurrency = app.node.try_get_context("upload_concurrency")
    if upload_concurrency is not None:
        context["upload_concurrency"] = int(upload_concurrency)
    try:
        DremStack(app, f"drem-{stage}", stage=stage, functions_dir=functions_dir, **context, booth=booth,
                  env=cdk.Environment(account=os.environ.get("CDK_DEFAULT_ACCOUNT"),
                                      region=os.environ.get("CDK_DEFAULT_REGION")))
    except ValueError as exc:  # a wrong option: say which, without a traceback
        raise SystemExit(f"drem-{stage}: {exc}") from None
    app.synth()


if __name__ == "__main__":
    main()
