"""What `make deploy` relies on: CloudFront in front of the API (links are root-relative, so / must map to the
API's stage), the public URL reaching the app, a template CloudFormation accepts, and the `drem aws` steps that
record the outputs and create the first admin (run as the installed CLI, against a local Cognito)."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.infra.conftest import PUBLIC_URL

pytestmark = pytest.mark.infra

DREM = Path(sys.executable).parent / "drem"


def _distribution(app_template) -> dict:
    distributions = list(app_template.find_resources("AWS::CloudFront::Distribution").values())
    assert len(distributions) == 1
    return distributions[0]["Properties"]["DistributionConfig"]


def test_cloudfront_maps_the_site_root_to_the_api_stage_and_caches_only_static_files(app_template):
    config = _distribution(app_template)
    origin = config["Origins"][0]
    assert origin["OriginPath"] == "/api", "root-relative links must land on the API's stage"
    assert origin["CustomOriginConfig"]["OriginProtocolPolicy"] == "https-only"
    assert "RestAPI" in json.dumps(origin["DomainName"])

    default = config["DefaultCacheBehavior"]
    caching_disabled = "4135ea2d-6df8-44a3-9df3-4b5a84be39ad"  # AWS managed policy CachingDisabled
    all_viewer_except_host = "b689b0a8-53d0-40ab-baf2-68738e2966ac"  # AWS managed AllViewerExceptHostHeader
    assert default["CachePolicyId"] == caching_disabled
    assert default["OriginRequestPolicyId"] == all_viewer_except_host
    assert default["ViewerProtocolPolicy"] == "redirect-to-https"
    assert set(default["AllowedMethods"]) >= {"GET", "POST", "PUT", "DELETE"}
    static = {b["PathPattern"]: b for b in config["CacheBehaviors"]}["/static/*"]
    assert static["CachePolicyId"] != caching_disabled


def test_cloudfront_tells_the_app_the_site_is_at_its_root_so_links_do_not_carry_the_stage(app_template):
    from chalicelib import base_path

    origin = _distribution(app_template)["Origins"][0]
    headers = {h["HeaderName"]: h["HeaderValue"] for h in origin["OriginCustomHeaders"]}
    assert headers == {base_path.FORWARDED_PREFIX_HEADER: "/"}
    # What the app makes of it: the request reaches the execute-api host with the stage, yet the links start at "/".
    context = {"stage": "api", "domainName": "abc123.execute-api.eu-west-1.amazonaws.com", "path": "/api/console"}
    lowered = {name.lower(): value for name, value in headers.items()}
    assert base_path.for_request(lowered, context, "") == ""
    assert base_path.for_request({}, context, "") == "/api"  # the same request without CloudFront's header


def test_the_app_is_told_its_public_url_so_cookies_are_secure_and_qr_codes_point_there(app_template):
    functions = app_template.find_resources("AWS::Serverless::Function").values()
    assert {f["Properties"]["Environment"]["Variables"].get("DREM_PUBLIC_URL") for f in functions} == {PUBLIC_URL}
    outputs = app_template.to_json()["Outputs"]
    assert outputs["PublicUrl"]["Value"] == PUBLIC_URL
    assert "DistributionUrl" in outputs

    from chalicelib.settings import Settings
    assert Settings.from_env({"DREM_PUBLIC_URL": PUBLIC_URL}).cookie_secure


def test_the_template_passes_cfn_lint(app_template, tmp_path):
    path = tmp_path / "template.json"
    path.write_text(json.dumps(app_template.to_json()))
    lint = subprocess.run([str(Path(sys.executable).with_name("cfn-lint")), "--format", "parseable", str(path)],
                          capture_output=True, text=True, timeout=300)
    errors = [line for line in lint.stdout.splitlines() if ":E" in line]
    assert errors == [], "\n".join(errors)


def _cdk_outputs(stage: str, outputs) -> dict:
    """What `cdk deploy --outputs-file` writes for our stack, from a bootstrapped local stack's real resources."""
    stack = {"Stage": stage, "Region": outputs.region, "UserPoolId": outputs.user_pool_id,
             "UserPoolClientId": outputs.user_pool_client_id,
             "DistributionUrl": "https://d111111abcdef8.cloudfront.net", "PublicUrl": PUBLIC_URL}
    stack.update({f"{k.capitalize()}TableName": v for k, v in outputs.tables.items()})
    stack.update({f"{k.capitalize()}BucketName": v for k, v in outputs.buckets.items()})
    return {f"drem-{stage}": stack}


def test_drem_aws_records_the_outputs_and_creates_the_first_admin_once(durable_server_factory, tmp_path):
    from drem_local.bootstrap import clients_for, ensure_stack
    from drem_local.storage_keys import load

    server = durable_server_factory.start("aws-deploy")
    keys = load(server.state_dir)  # the local storage server stands in for AWS and accepts only these
    clients = clients_for(server.url, "us-east-1", keys)
    outputs = ensure_stack(clients, stage="deployed")
    (tmp_path / "outputs.json").write_text(json.dumps(_cdk_outputs("deployed", outputs)))
    # `drem aws` uses the default credential chain, as on a real account: here, the environment.
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "AWS_SESSION_TOKEN", "AWS_SECURITY_TOKEN")}
    env.update(AWS_ENDPOINT_URL=server.url, AWS_ACCESS_KEY_ID=keys.access_key_id,
               AWS_SECRET_ACCESS_KEY=keys.secret_access_key)

    def drem(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run([str(DREM), "aws", *args], cwd=tmp_path, env=env, capture_output=True, text=True,
                              timeout=120)

    recorded = drem("record", "--stage", "deployed", "--outputs", "outputs.json")
    assert recorded.returncode == 0, recorded.stderr
    record = json.loads((tmp_path / ".drem-aws" / "deployed.json").read_text())
    assert record["public_url"] == PUBLIC_URL and record["tables"] == outputs.tables

    first = drem("admin", "--stage", "deployed")
    assert first.returncode == 0, first.stderr
    password = first.stdout.split("shown only now; change it after signing in): ")[1].split()[0]
    token = clients.cognito.initiate_auth(ClientId=outputs.user_pool_client_id, AuthFlow="USER_PASSWORD_AUTH",
                                          AuthParameters={"USERNAME": "admin", "PASSWORD": password})
    assert token["AuthenticationResult"]["AccessToken"]
    groups = clients.cognito.admin_list_groups_for_user(UserPoolId=outputs.user_pool_id, Username="admin")
    assert [g["GroupName"] for g in groups["Groups"]] == ["admin"]

    again = drem("admin", "--stage", "deployed")
    assert again.returncode == 0 and "already exists; its password was not changed" in again.stdout
    shown = drem("show", "--stage", "deployed", "--env")
    assert f"export DREM_PUBLIC_URL={PUBLIC_URL}" in shown.stdout
    assert f"export DREM_USER_POOL_ID={outputs.user_pool_id}" in shown.stdout


def test_drem_aws_explains_a_missing_deployment(tmp_path):
    done = subprocess.run([str(DREM), "aws", "show", "--stage", "nowhere"], cwd=tmp_path, capture_output=True,
                          text=True, timeout=60)
    assert done.returncode == 1
    assert "make deploy STAGE=nowhere" in done.stderr and "Traceback" not in done.stderr


def test_event_logos_are_cached_at_the_edge_by_version_and_fetched_as_bytes_every_viewer_may_get(app_template):
    from app import app
    from chalice.app import _matches_content_type

    config = _distribution(app_template)
    logo = {b["PathPattern"]: b for b in config["CacheBehaviors"]}["/event/*/logo"]
    assert "/event/{event_id}/logo" in app.routes  # the pattern names the app's route
    policies = app_template.find_resources("AWS::CloudFront::CachePolicy")
    policy = next(p["Properties"]["CachePolicyConfig"] for name, p in policies.items()
                  if logo["CachePolicyId"] == {"Ref": name})
    key = policy["ParametersInCacheKeyAndForwardedToOrigin"]
    # A new logo is a new ?v= (the pages link the current one), so the version alone keys the cache: a viewer's
    # cookies or headers would only split it, and none of them changes the answer.
    assert key["QueryStringsConfig"] == {"QueryStringBehavior": "whitelist", "QueryStrings": ["v"]}
    assert key["HeadersConfig"]["HeaderBehavior"] == "none"
    assert key["CookiesConfig"]["CookieBehavior"] == "none"
    assert policy["MaxTTL"] >= 30 * 24 * 3600 and policy["MinTTL"] == 0
    assert "OriginRequestPolicyId" not in logo  # nothing of the viewer's reaches the app

    origin = next(o for o in config["Origins"] if o["Id"] == logo["TargetOriginId"])
    headers = {h["HeaderName"]: h["HeaderValue"] for h in origin["OriginCustomHeaders"]}
    assert origin["OriginPath"] == "/api" and headers["X-Forwarded-Prefix"] == "/"
    # Chalice answers a binary body only to a request whose Accept matches one of its binary types (else 400).
    assert _matches_content_type(headers["Accept"], app.api.binary_types)
