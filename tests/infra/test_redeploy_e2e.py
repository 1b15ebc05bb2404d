"""One-pass deploys, end to end: the app's stack without a domain (`make deploy` as most organisers run it) deployed
into moto's CloudFormation, then deployed again with the same template (what every later `make deploy` does: one
`cdk deploy`, the same context). After each deploy a fresh instance of the packaged API function, with exactly the
environment the stack gave it, answers with the public URL: `Secure` cookies and no link to the local fallback
127.0.0.1. Before this change the first pass of every `make deploy` dropped the URL until a second pass.

The stack's SSM parameter takes the CloudFront distribution's domain, and moto creates no CloudFront distribution
(tests/infra/emulated_deploy.py, step 4), so the parameter is written here as CloudFormation would write it, with a
stand-in domain, exactly like the Cognito resources are provided through their API.
"""
from __future__ import annotations

import json
import time
import zipfile
from pathlib import Path
from typing import Any

import pytest
from botocore.exceptions import ClientError

from drem_infra import resources
from tests.infra import emulated_deploy
from tests.infra.conftest import STAGE
from tests.infra.lambda_runtime import LambdaFunction, runtime_dir

pytestmark = pytest.mark.infra

REGION = "us-east-1"
STACK = f"drem-{STAGE}"
CLOUDFRONT_URL = "https://d1234abcd5678e.cloudfront.net"  # stands in for the distribution moto cannot create
MAKEFILE = Path(__file__).resolve().parents[2] / "Makefile"


def _wait(cloudformation: Any, done: str, timeout_s: float = 120.0) -> dict[str, Any]:
    deadline = time.monotonic() + timeout_s
    while True:
        stack = cloudformation.describe_stacks(StackName=STACK)["Stacks"][0]
        if not stack["StackStatus"].endswith("_IN_PROGRESS"):
            assert stack["StackStatus"] == done, stack
            return stack
        assert time.monotonic() < deadline, f"stack still {stack['StackStatus']}"
        time.sleep(0.2)


def _login_page(function: LambdaFunction) -> dict[str, Any]:
    """GET /login through API Gateway's proxy event, as CloudFront forwards it (X-Forwarded-Prefix "/")."""
    headers = {"Accept": "text/html", "Host": "e2etest02.execute-api.us-east-1.amazonaws.com",
               "X-Forwarded-Prefix": "/", "X-Forwarded-Proto": "https"}
    event = {"resource": "/login", "path": "/login", "httpMethod": "GET", "headers": headers,
             "multiValueHeaders": {k: [v] for k, v in headers.items()}, "queryStringParameters": None,
             "multiValueQueryStringParameters": None, "pathParameters": None, "stageVariables": None,
             "requestContext": {"resourcePath": "/login", "httpMethod": "GET", "path": "/api/login", "stage": "api",
                                "apiId": "e2etest02", "requestId": "r1", "accountId": "123456789012",
                                "identity": {"sourceIp": "198.51.100.7"}},
             "body": None, "isBase64Encoded": False}
    return function.invoke(event)


def test_every_deploy_after_the_first_serves_the_public_url_from_its_first_request(
        cloudfront_template, cloud_assembly, durable_server_factory, tmp_path_factory):
    from drem_local.storage_keys import local_client
    from drem_local.token_key import key_path

    recipe = MAKEFILE.read_text().split("\ndeploy:", 1)[1].split("\n\n", 1)[0]
    assert recipe.count("$(CDK_RUN) deploy") == 1, "make deploy is one pass"

    server = durable_server_factory.start("e2e-redeploy", snapshot_interval=3600.0)

    def client(service: str) -> Any:
        return local_client(service, server.url, server.keys, REGION)

    template = cloudfront_template.to_json()
    account = client("sts").get_caller_identity()["Account"]
    emulated_deploy.bootstrap(client("ssm"), client("s3"), account, REGION)
    published = emulated_deploy.publish_assets(client("s3"), cloud_assembly, "drem-cloudfront", account, REGION)
    provided = emulated_deploy.provide_cognito(client("cognito-idp"), template["Resources"], REGION)
    emulated_deploy.provide_secrets(client("secretsmanager"), template["Resources"], provided)
    subset = emulated_deploy.deployable_subset(template, provided, emulated_deploy.moto_supported_types())
    parameters = [lid for lid, r in template["Resources"].items() if r["Type"] == "AWS::SSM::Parameter"]
    assert parameters and all(lid in subset.skipped for lid in parameters)  # it needs the distribution
    client("ssm").put_parameter(Name=resources.public_url_parameter(STAGE), Value=CLOUDFRONT_URL, Type="String")

    [code_key] = {template["Resources"][lid]["Properties"]["CodeUri"]["Key"] for lid in subset.translated}
    work = tmp_path_factory.mktemp("redeploy")
    with zipfile.ZipFile(published[code_key]) as archive:
        archive.extractall(work / "bundle")
    runtime = runtime_dir(work)
    cloudformation = client("cloudformation")
    body = json.dumps(subset.template)
    for attempt, (deploy, done) in enumerate(((cloudformation.create_stack, "CREATE_COMPLETE"),
                                              (cloudformation.update_stack, "UPDATE_COMPLETE"))):
        try:
            deploy(StackName=STACK, TemplateBody=body, Capabilities=["CAPABILITY_IAM", "CAPABILITY_AUTO_EXPAND"])
            _wait(cloudformation, done)
        except ClientError as exc:  # CloudFormation's answer to an unchanged template: the stack stays as it is
            assert attempt == 1 and "No updates are to be performed" in str(exc), exc
        physical = {r["LogicalResourceId"]: r.get("PhysicalResourceId", "")
                    for r in cloudformation.describe_stack_resources(StackName=STACK)["StackResources"]}
        configuration = client("lambda").get_function_configuration(FunctionName=physical["APIHandler"])
        variables = configuration["Environment"]["Variables"]
        assert "DREM_PUBLIC_URL" not in variables
        assert variables["DREM_PUBLIC_URL_PARAMETER"] == resources.public_url_parameter(STAGE)
        extra = {"AWS_REGION": REGION, "AWS_DEFAULT_REGION": REGION, "AWS_ENDPOINT_URL": server.url,
                 **server.keys.environment(), "DREM_STATE_DIR": str(work / f"state-{attempt}"),
                 resources.TOKEN_SIGNING_KEY_ENV: str(key_path(server.state_dir))}
        function = LambdaFunction(work / "bundle", runtime, configuration, extra, work / f"api-{attempt}.log")
        try:  # a fresh instance: what the first request after a deploy meets
            reply = _login_page(function)
        finally:
            function.close()
        assert reply["statusCode"] == 200, reply
        cookies = [c for values in (reply.get("multiValueHeaders") or {}).values() for c in values
                   if "=" in str(c) and "Path=" in str(c)]
        assert cookies and all("Secure" in cookie for cookie in cookies), cookies
        assert "127.0.0.1" not in reply["body"]
