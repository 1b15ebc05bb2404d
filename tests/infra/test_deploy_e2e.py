"""End to end: the real app's synthesised template deployed into moto's CloudFormation (on drem's own storage server),
as far as moto goes, then the Lambda bundle that deploy uploaded driven with API Gateway proxy events against the
resources that stack created: the first admin (made by `drem aws admin`) signs in, registers a racer, creates an
event, runs and submits a race with a lap, and the public board shows the racer; a model archive posted with the
upload form is routed by the stack's EventBridge rule to the upload function, which judges it; then the stack is
destroyed (retained data stays) and deployed again without colliding.

How each deploy step is stood in for, and what moto cannot create, is in tests/infra/emulated_deploy.py; the test
prints the resources left out and checks that none of them is one the app needs.
"""
from __future__ import annotations

import base64
import fnmatch
import hashlib
import io
import json
import os
import subprocess
import sys
import time
import uuid
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from urllib.parse import parse_qs, urlsplit

import pytest
import requests
from botocore.exceptions import ClientError

from drem_infra import live_pages, resources
from tests.infra import emulated_deploy
from tests.infra.conftest import PUBLIC_URL, STAGE
from tests.infra.lambda_runtime import LambdaFunction, runtime_dir

pytestmark = pytest.mark.infra

REGION = "us-east-1"
STACK = f"drem-{STAGE}"  # what `make deploy STAGE=test` names it
DREM = Path(sys.executable).parent / "drem"
# What the app needs from the stack: storage, identity, its role and log groups, and the functions themselves.
NEEDED_TYPES = ("AWS::DynamoDB::Table", "AWS::S3::Bucket", "AWS::Cognito::UserPool", "AWS::Cognito::UserPoolClient",
                "AWS::Cognito::UserPoolGroup", "AWS::IAM::Role", "AWS::Logs::LogGroup", "AWS::Serverless::Function")


@dataclass
class Deployed:
    server: Any
    template: dict[str, Any]
    subset: emulated_deploy.Subset
    provided: emulated_deploy.Provided
    physical: dict[str, str]  # logical id -> physical id, for what moto's CloudFormation created
    outputs: dict[str, str]
    published: dict[str, Path]
    client: Any

    def resource_ids(self, resource_type: str) -> list[str]:
        return [lid for lid, r in self.template["Resources"].items() if r["Type"] == resource_type]


@pytest.fixture(scope="module")
def deployed(app_template, cloud_assembly, durable_server_factory):
    from drem_local.storage_keys import local_client

    # No periodic snapshots: the 38 MB bundle in the assets bucket would be pickled again every few seconds.
    server = durable_server_factory.start("e2e-deploy", snapshot_interval=3600.0)

    def client(service: str) -> Any:
        return local_client(service, server.url, server.keys, REGION)

    template = app_template.to_json()
    account = client("sts").get_caller_identity()["Account"]
    emulated_deploy.bootstrap(client("ssm"), client("s3"), account, REGION)
    published = emulated_deploy.publish_assets(client("s3"), cloud_assembly, "drem-app", account, REGION)
    return _deploy(server, client, template, published)


def _deploy(server: Any, client: Any, template: dict[str, Any], published: dict[str, Path]) -> Deployed:
    provided = emulated_deploy.provide_cognito(client("cognito-idp"), template["Resources"], REGION)
    emulated_deploy.provide_secrets(client("secretsmanager"), template["Resources"], provided)
    subset = emulated_deploy.deployable_subset(template, provided, emulated_deploy.moto_supported_types())
    cloudformation = client("cloudformation")
    cloudformation.create_stack(StackName=STACK, TemplateBody=json.dumps(subset.template),
                                Capabilities=["CAPABILITY_IAM", "CAPABILITY_AUTO_EXPAND"])
    stack = _wait_for_stack(cloudformation)
    physical = {r["LogicalResourceId"]: r.get("PhysicalResourceId", "")
                for r in cloudformation.describe_stack_resources(StackName=STACK)["StackResources"]}
    outputs = {o["OutputKey"]: o["OutputValue"] for o in stack.get("Outputs", [])}
    return Deployed(server, template, subset, provided, physical, outputs, published, client)


def _wait_for_stack(cloudformation: Any, timeout_s: float = 60.0) -> dict[str, Any]:
    deadline = time.monotonic() + timeout_s
    while True:
        stack = cloudformation.describe_stacks(StackName=STACK)["Stacks"][0]
        if not stack["StackStatus"].endswith("_IN_PROGRESS"):
            assert stack["StackStatus"] == "CREATE_COMPLETE", stack
            return stack
        assert time.monotonic() < deadline, f"stack still {stack['StackStatus']}"
        time.sleep(0.2)


def test_the_stack_creates_everything_the_app_needs_and_says_what_moto_cannot(deployed):
    template, subset, provided = deployed.template["Resources"], deployed.subset, deployed.provided
    print(f"\nLeft out of the emulated deploy ({len(subset.skipped)} of {len(template)} resources):")
    for logical_id, reason in sorted(subset.skipped.items()):
        print(f"  {logical_id:55} {template[logical_id]['Type']:40} {reason}")
    print(f"Created through the Cognito and Secrets Manager APIs (no moto CloudFormation model): "
          f"{sorted(provided.refs)}")
    print(f"Outputs not available: {subset.dropped_outputs}")

    supported = emulated_deploy.moto_supported_types()
    for logical_id, reason in subset.skipped.items():
        kind, _, cause = reason.partition(" ")
        if kind == "unsupported":
            assert cause == template[logical_id]["Type"] and cause not in supported
        else:  # left out only because something it refers to was
            assert cause in subset.skipped and cause in emulated_deploy.references(template[logical_id]) | \
                set(template[logical_id].get("DependsOn", []))
    needed = [lid for lid, r in template.items() if r["Type"] in NEEDED_TYPES]
    assert [lid for lid in needed if lid in subset.skipped] == []
    created = set(deployed.physical) | set(provided.refs)
    assert created == set(template) - set(subset.skipped)
    assert set(needed) <= created
    # The skipped resources really are absent from moto's stack, and everything else was created, not just listed.
    assert not set(subset.skipped) & set(deployed.physical)


def test_the_storage_is_what_the_template_defines(deployed):
    dynamodb, s3 = deployed.client("dynamodb"), deployed.client("s3")
    for spec in resources.TABLES:
        name = deployed.outputs[f"{spec.logical.capitalize()}TableName"]
        # Generated, stage-scoped names: a retained table never collides with the next deploy.
        assert name.startswith(f"{STACK}-{spec.logical.capitalize()}Table")
        table = dynamodb.describe_table(TableName=name)["Table"]
        assert [k["AttributeName"] for k in table["KeySchema"]] == [spec.pk, spec.sk]
        assert sorted(g["IndexName"] for g in table.get("GlobalSecondaryIndexes", [])) == sorted(
            g.name for g in spec.gsis)
    for spec in resources.BUCKETS:
        s3.head_bucket(Bucket=deployed.outputs[f"{spec.logical.capitalize()}BucketName"])


def test_the_functions_run_the_uploaded_bundle_with_the_stacks_names(deployed):
    lambda_ = deployed.client("lambda")
    functions = deployed.subset.translated
    assert sorted(functions) == sorted(deployed.resource_ids("AWS::Serverless::Function"))
    for logical_id in functions:
        configuration = lambda_.get_function_configuration(FunctionName=deployed.physical[logical_id])
        code_key = deployed.template["Resources"][logical_id]["Properties"]["CodeUri"]["Key"]
        bundle_sha = base64.b64encode(hashlib.sha256(deployed.published[code_key].read_bytes()).digest()).decode()
        assert configuration["CodeSha256"] == bundle_sha
        variables = configuration["Environment"]["Variables"]
        assert variables["DREM_USER_POOL_ID"] == deployed.outputs["UserPoolId"]
        assert variables["DREM_USER_POOL_CLIENT_ID"] == deployed.outputs["UserPoolClientId"]
        for spec in resources.TABLES:
            assert variables[resources.table_env_var(spec.logical)] == \
                deployed.outputs[f"{spec.logical.capitalize()}TableName"]
        for spec in resources.BUCKETS:
            assert variables[resources.bucket_env_var(spec.logical)] == \
                deployed.outputs[f"{spec.logical.capitalize()}BucketName"]
        assert variables["DREM_PUBLIC_URL"] == PUBLIC_URL
        # The writer's wake-up secret, resolved at deploy time: the very one the live tasks take from Secrets Manager.
        [wake_secret] = [lid for lid, r in deployed.template["Resources"].items()
                         if r["Type"] == "AWS::SecretsManager::Secret" and "LiveWakeSecret" in lid]
        shared = deployed.client("secretsmanager").get_secret_value(SecretId=deployed.provided.refs[wake_secret])
        assert variables[live_pages.WAKE_SECRET_ENV] == shared["SecretString"] and len(shared["SecretString"]) >= 32
        assert configuration["Role"].endswith(f"/{deployed.physical['DefaultRole']}")
        # moto keeps no LoggingConfig, so the function's log group is checked where the template names it.
        log_group = deployed.template["Resources"][logical_id]["Properties"]["LoggingConfig"]["LogGroup"]["Ref"]
        groups = deployed.client("logs").describe_log_groups(logGroupNamePrefix=deployed.physical[log_group])
        assert [g["retentionInDays"] for g in groups["logGroups"]] == [30], "logs are kept a month, not forever"


# --- driving the API handler -----------------------------------------------------------------------------------------

class ApiGateway:
    """What API Gateway hands the API function for a request (REST API, Lambda proxy integration).

    The resource is matched against the API's own definition (the RestAPI's DefinitionBody paths in the template),
    with chalice.local.RouteMatcher (aws/chalice chalice/local.py, which matches API Gateway's `{param}` paths the
    same way). The event has the proxy integration's input format (AWS docs, "Input format of a Lambda function for
    proxy integration"); Chalice reads requestContext.resourcePath / httpMethod, pathParameters,
    multiValueQueryStringParameters, headers, body and isBase64Encoded from it (aws/chalice chalice/app.py,
    `Request.__init__` and `RestAPIEventHandler._main_rest_api_handler`)."""

    STAGE_NAME = "api"

    def __init__(self, function: LambdaFunction, definition: dict[str, Any], api_id: str) -> None:
        from chalice.local import RouteMatcher

        self.function = function
        self.matcher = RouteMatcher(list(definition["paths"]))
        self.methods = {path: {m.upper() for m in ops} for path, ops in definition["paths"].items()}
        self.binary_types = [t.lower() for t in definition.get("x-amazon-apigateway-binary-media-types", [])]
        self.api_id = api_id

    def is_binary(self, media_type: str | None) -> bool:
        """Whether a media type is one of the API's binary media types (`*` a wildcard: "*/*", "image/*")."""
        if not media_type:
            return False
        kind, _, sub = media_type.split(";")[0].strip().lower().partition("/")
        return any(fnmatch.fnmatchcase(f"{kind}/{sub}", pattern) for pattern in self.binary_types)

    def request(self, method: str, url: str, body: Any = None, headers: dict[str, str] | None = None,
                raw: bytes | None = None) -> tuple[int, dict[str, str], Any]:
        """`body` is sent as JSON; `raw` as the bytes they are (with the Content-Type in `headers`). Binary media
        types (AWS API Gateway developer guide, "Content type conversions in API Gateway", Lambda proxy): a request
        whose Content-Type is one reaches the function base64-encoded; a base64 answer (isBase64Encoded) is decoded
        only when the *first* type of the request's Accept is one, else the viewer gets the base64 text."""
        parts = urlsplit(url)
        match = self.matcher.match_route(parts.path)
        assert method in self.methods[match.route] or "X-AMAZON-APIGATEWAY-ANY-METHOD" in self.methods[match.route], \
            f"the API defines no {method} {match.route}"
        query = parse_qs(parts.query) or None
        headers = {"Accept": "application/json", "Host": f"{self.api_id}.execute-api.{REGION}.amazonaws.com",
                   "User-Agent": "drem-e2e", "X-Forwarded-Proto": "https", **(headers or {})}
        payload_bytes = raw if raw is not None else None if body is None else json.dumps(body).encode()
        if body is not None:
            headers["Content-Type"] = "application/json"
        encoded = payload_bytes is not None and self.is_binary(headers.get("Content-Type"))
        if payload_bytes is None:
            text = None
        elif encoded:
            text = base64.b64encode(payload_bytes).decode("ascii")
        else:
            text = payload_bytes.decode("utf-8")
        event = {
            "resource": match.route, "path": parts.path, "httpMethod": method,
            "headers": headers, "multiValueHeaders": {k: [v] for k, v in headers.items()},
            "queryStringParameters": {k: v[-1] for k, v in query.items()} if query else None,
            "multiValueQueryStringParameters": query,
            "pathParameters": match.captured or None, "stageVariables": None,
            "requestContext": {
                "resourcePath": match.route, "httpMethod": method, "path": f"/{self.STAGE_NAME}{parts.path}",
                "stage": self.STAGE_NAME, "apiId": self.api_id, "resourceId": uuid.uuid4().hex[:6],
                "requestId": str(uuid.uuid4()), "accountId": "123456789012", "protocol": "HTTP/1.1",
                "requestTimeEpoch": int(time.time() * 1000),
                "identity": {"sourceIp": "198.51.100.7", "userAgent": "drem-e2e"},
            },
            "body": text, "isBase64Encoded": encoded,
        }
        reply = self.function.invoke(event)
        # API Gateway sends both maps' headers to the client (multiValueHeaders holds the repeated ones, e.g. cookies).
        headers = {k.lower(): v for k, v in (reply.get("headers") or {}).items()}
        headers.update({k.lower(): ", ".join(v) for k, v in (reply.get("multiValueHeaders") or {}).items()})
        # A proxy answer without Content-Type reaches the client as application/json (API Gateway's default).
        headers.setdefault("content-type", "application/json")
        payload = reply.get("body") or ""
        if reply.get("isBase64Encoded") and self.is_binary(first_accepted(event)):
            return reply["statusCode"], headers, base64.b64decode(payload)
        if payload and "json" in headers.get("content-type", ""):
            payload = json.loads(payload)
        return reply["statusCode"], headers, payload


def first_accepted(event: dict[str, Any]) -> str:
    """The first media type of the request's Accept header, the one API Gateway goes by."""
    return (event["headers"].get("Accept") or "").split(",")[0]


@pytest.fixture(scope="module")
def lambda_code(deployed, tmp_path_factory) -> tuple[Path, Path]:
    """The bundle both functions run (unzipped from the object the stack's functions were created from), and the
    directory of the Lambda runtime's own packages."""
    work = tmp_path_factory.mktemp("e2e-lambda")
    [code_key] = {deployed.template["Resources"][lid]["Properties"]["CodeUri"]["Key"]
                  for lid in deployed.subset.translated}
    with zipfile.ZipFile(deployed.published[code_key]) as archive:
        archive.extractall(work / "bundle")
    return work / "bundle", runtime_dir(work)


def _start(deployed, lambda_code: tuple[Path, Path], logical_id: str, log_dir: Path) -> LambdaFunction:
    from drem_local.token_key import key_path

    configuration = deployed.client("lambda").get_function_configuration(FunctionName=deployed.physical[logical_id])
    # AWS would give the function its role's credentials and Cognito's JWKS; here the storage server stands in for
    # AWS, so the function gets its endpoint and keys, and trusts the tokens signed with its key (drem's local mode).
    extra = {"AWS_REGION": REGION, "AWS_DEFAULT_REGION": REGION, "AWS_ENDPOINT_URL": deployed.server.url,
             **deployed.server.keys.environment(), "DREM_STATE_DIR": str(log_dir / "state"),
             resources.TOKEN_SIGNING_KEY_ENV: str(key_path(deployed.server.state_dir))}
    return LambdaFunction(*lambda_code, configuration, extra, log_dir / f"{logical_id}.log")


@pytest.fixture(scope="module")
def api(deployed, lambda_code, tmp_path_factory):
    function = _start(deployed, lambda_code, "APIHandler", tmp_path_factory.mktemp("api-handler"))
    definition = deployed.template["Resources"]["RestAPI"]["Properties"]["DefinitionBody"]
    yield ApiGateway(function, definition, api_id="e2etest01")
    function.close()


@pytest.fixture(scope="module")
def admin_password(deployed, tmp_path_factory) -> str:
    return _first_admin(deployed, tmp_path_factory.mktemp("drem-aws"))


def _first_admin(deployed, tmp_path: Path) -> str:
    """`make deploy`'s last steps: `drem aws record` from the stack outputs, then `drem aws admin`."""
    (tmp_path / "outputs.json").write_text(json.dumps({STACK: deployed.outputs}))
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "AWS_SESSION_TOKEN", "AWS_SECURITY_TOKEN")}
    env.update(AWS_ENDPOINT_URL=deployed.server.url, AWS_DEFAULT_REGION=REGION, **deployed.server.keys.environment())

    def drem(*args: str) -> subprocess.CompletedProcess:
        done = subprocess.run([str(DREM), "aws", *args], cwd=tmp_path, env=env, capture_output=True, text=True,
                              timeout=120)
        assert done.returncode == 0, done.stderr
        return done

    drem("record", "--stage", STAGE, "--outputs", "outputs.json")
    created = drem("admin", "--stage", STAGE).stdout
    return created.split("shown only now; change it after signing in): ")[1].split()[0]


def test_the_packaged_api_signs_in_records_a_race_and_shows_the_board(deployed, api, admin_password):
    password = admin_password

    status, headers, grant = api.request("POST", "/api/auth/token", {"username": "admin", "password": password})
    assert status == 200, grant
    admin = {"Authorization": f"Bearer {grant['access_token']}"}
    wrong, _, _ = api.request("POST", "/api/auth/token", {"username": "admin", "password": password + "x"})
    assert wrong == 401

    status, _, racer = api.request("POST", "/api/users", {"username": "vera", "email": "vera@example.org",
                                                          "country_code": "SE"}, admin)
    assert status == 201, racer
    status, _, event = api.request("POST", "/api/events", {
        "name": "Summit Stockholm 2026", "event_type": "AWS_SUMMIT", "date": "2026-05-14", "country_code": "SE",
        "race_config": {}, "tracks": [{"track_id": "1"}]}, admin)
    assert status == 201, event
    event_id = event["event_id"]
    status, _, race = api.request("POST", f"/api/events/{event_id}/races",
                                  {"track_id": "1", "racer_username": "vera"}, admin)
    assert status == 201, race
    commands = f"/api/events/{event_id}/races/{race['race_id']}/commands"
    for kind in ("start", "capture_lap", "end", "submit"):
        status, _, answer = api.request("POST", commands, {"kind": kind}, admin)
        assert status == 200, (kind, answer, api.function.log_tail())

    status, headers, board = api.request("GET", f"/api/leaderboard/{event_id}?track=1")
    assert status == 200, board
    assert board["event_id"] == event_id
    [entry] = board["entries"]
    assert (entry["username"], entry["position"], entry["laps"], entry["country_code"]) == ("vera", 1, 1, "SE")
    assert entry["fastest_lap_ms"] > 0
    unchanged, _, _ = api.request("GET", f"/api/leaderboard/{event_id}?track=1",
                                  headers={"If-None-Match": headers["etag"]})
    assert unchanged == 304
    # Read straight from the table the stack created: the race the API acknowledged is there.
    races_table = deployed.outputs["RacesTableName"]
    items = deployed.client("dynamodb").scan(TableName=races_table)["Items"]
    assert any(race["race_id"] in json.dumps(item) for item in items)


# What Chromium sends for a page (a link to a PDF too) and for an <img>: neither starts with the answer's type.
BROWSER_PAGE_ACCEPT = ("text/html,application/xhtml+xml,application/xml;q=0.9,image/avif,image/webp,image/apng,*/*;"
                       "q=0.8,application/signed-exchange;v=b3;q=0.7")
BROWSER_IMAGE_ACCEPT = "image/avif,image/webp,image/apng,image/svg+xml,image/*,*/*;q=0.8"


def test_a_logo_upload_and_printed_results_reach_a_browser_as_the_bytes_they_are(deployed, api, admin_password):
    from PIL import Image

    _, _, grant = api.request("POST", "/api/auth/token", {"username": "admin", "password": admin_password})
    admin = {"Authorization": f"Bearer {grant['access_token']}"}
    status, _, event = api.request("POST", "/api/events", {
        "name": "Binary Cup", "event_type": "AWS_SUMMIT", "date": "2026-05-14", "country_code": "SE",
        "race_config": {}, "tracks": [{"track_id": "1"}]}, admin)
    assert status == 201, event
    event_id = event["event_id"]
    upload = io.BytesIO()
    Image.new("RGB", (400, 100), (255, 153, 0)).save(upload, format="JPEG")

    status, _, saved = api.request("PUT", f"/api/events/{event_id}/logo", raw=upload.getvalue(),
                                   headers={**admin, "Content-Type": "image/jpeg"})
    assert status == 200, (saved, api.function.log_tail())
    assert (saved["width"], saved["height"]) == (400, 100)

    status, _, page = api.request("GET", f"/leaderboard/{event_id}", headers={"Accept": BROWSER_PAGE_ACCEPT})
    assert status == 200 and f"/event/{event_id}/logo?v={saved['version']}" in page  # pages stay text
    status, headers, image = api.request("GET", f"/event/{event_id}/logo?v={saved['version']}",
                                         headers={"Accept": BROWSER_IMAGE_ACCEPT})
    assert status == 200 and headers["content-type"] == "image/png", headers
    assert isinstance(image, bytes), "the browser got the image's base64 text"
    shown = Image.open(io.BytesIO(image))
    assert shown.size == (400, 100) and shown.convert("RGB").getpixel((200, 50))[0] > 240

    status, headers, pdf = api.request("GET", f"/api/events/{event_id}/results/summary.pdf",
                                       headers={**admin, "Accept": BROWSER_PAGE_ACCEPT})
    assert status == 200 and headers["content-type"] == "application/pdf"
    assert isinstance(pdf, bytes), "the browser got the PDF's base64 text"
    assert pdf[:5] == b"%PDF-"  # the document, not its base64 text


def test_a_model_upload_is_routed_by_the_stacks_rule_to_the_upload_function_and_judged(
        deployed, api, admin_password, lambda_code, tmp_path):
    from tests.unit.models_helpers import onnx_archive

    _, _, grant = api.request("POST", "/api/auth/token", {"username": "admin", "password": admin_password})
    admin = {"Authorization": f"Bearer {grant['access_token']}"}
    status, _, ticket = api.request("POST", "/api/models", {"filename": "e2e-model.tar.gz"}, admin)
    assert status == 201, ticket
    # The browser posts the archive with the presigned form; locally the form names the app's /_storage gateway of
    # the storage server (chalicelib.storage.clients.s3_presigner), which the public URL stands for here.
    upload = ticket["upload"]
    posted = requests.post(upload["url"].replace(PUBLIC_URL, deployed.server.url), data=upload["fields"],
                           files={"file": ("e2e-model.tar.gz", onnx_archive())}, timeout=30)
    assert posted.status_code in (200, 204), posted.text
    bucket, key = deployed.outputs["ModelsBucketName"], upload["fields"]["key"]
    size = deployed.client("s3").head_object(Bucket=bucket, Key=key)["ContentLength"]

    # What S3 sends EventBridge for the new object (AWS docs, "Amazon S3 event notifications with EventBridge",
    # Object Created), checked against the rule the stack created, which targets the upload function.
    events = deployed.client("events")
    rule = events.describe_rule(Name=deployed.physical[deployed.resource_ids("AWS::Events::Rule")[0]])
    [target] = events.list_targets_by_rule(Rule=rule["Name"])["Targets"]
    upload_function = deployed.client("lambda").get_function_configuration(
        FunctionName=deployed.physical["UploadComplete"])
    assert target["Arn"] == upload_function["FunctionArn"]
    event = {"version": "0", "id": str(uuid.uuid4()), "detail-type": "Object Created", "source": "aws.s3",
             "account": "123456789012", "time": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
             "region": REGION, "resources": [f"arn:aws:s3:::{bucket}"],
             "detail": {"version": "0", "bucket": {"name": bucket},
                        "object": {"key": key, "size": size, "etag": "0", "sequencer": "0"},
                        "request-id": "E2E", "requester": "123456789012", "source-ip-address": "198.51.100.7",
                        "reason": "PostObject"}}
    # moto serves no TestEventPattern; its own matcher (moto/events/models.py EventPattern, which routes PutEvents to
    # rules) decides instead, in this process.
    from moto.events.models import EventPattern
    assert EventPattern.load(rule["EventPattern"]).matches_event(event)
    assert not EventPattern.load(rule["EventPattern"]).matches_event(
        {**event, "detail": {**event["detail"], "object": {**event["detail"]["object"], "key": "models/x.tar.gz"}}})

    function = _start(deployed, lambda_code, "UploadComplete", tmp_path)
    try:
        judged = function.invoke(event)
    finally:
        function.close()
    model_id = ticket["model"]["model_id"]
    assert judged == {"model_id": model_id, "status": "AVAILABLE"}, function.log_tail()
    status, _, model = api.request("GET", f"/api/models/{model_id}", headers=admin)
    assert status == 200 and model["model"]["status"] == "AVAILABLE", model
    # The upload was moved out of uploads/ into the models the cars download.
    listed = deployed.client("s3").list_objects_v2(Bucket=bucket)
    keys = [o["Key"] for o in listed.get("Contents", [])]
    assert key not in keys and any(k.startswith("models/") and model_id in k for k in keys), keys

def test_destroy_keeps_the_data_and_the_next_deploy_of_the_stage_does_not_collide(deployed):
    """`make destroy` then `make deploy` of the same stage (this runs after the race above, in file order)."""
    cloudformation, dynamodb = deployed.client("cloudformation"), deployed.client("dynamodb")
    tables = {spec.logical: deployed.outputs[f"{spec.logical.capitalize()}TableName"] for spec in resources.TABLES}
    races_before = dynamodb.scan(TableName=tables["races"])["Count"]

    try:
        cloudformation.delete_stack(StackName=STACK)
    except ClientError as exc:
        # moto deletes in passes, not in CloudFormation's reverse dependency order, and gives up on a VPC whose
        # dependants it cannot delete (moto/cloudformation/parsing.py ResourceMap.delete re-raises the last error);
        # moto/cloudformation/models.py delete_stack has already removed the stack, as a finished delete would.
        assert exc.response["Error"]["Code"] == "DependencyViolation" and "vpc" in str(exc), exc
        print(f"\nmoto left networking behind on delete: {exc}")
    assert [s for s in cloudformation.list_stacks()["StackSummaries"]
            if s["StackName"] == STACK and s["StackStatus"] != "DELETE_COMPLETE"] == []
    # Retained: every table still there with its data, and the functions gone.
    assert dynamodb.scan(TableName=tables["races"])["Count"] == races_before > 0
    assert sorted(set(dynamodb.list_tables()["TableNames"]) & set(tables.values())) == sorted(tables.values())
    functions = {f["FunctionName"] for f in deployed.client("lambda").list_functions()["Functions"]}
    assert not functions & {deployed.physical["APIHandler"], deployed.physical["UploadComplete"]}

    again = _deploy(deployed.server, deployed.client, deployed.template, deployed.published)
    new_tables = {spec.logical: again.outputs[f"{spec.logical.capitalize()}TableName"] for spec in resources.TABLES}
    assert set(new_tables.values()).isdisjoint(tables.values())
    assert all(dynamodb.scan(TableName=name)["Count"] == 0 for name in new_tables.values())
    # Buckets too: S3 names are global, so a fixed one would collide with the retained bucket.
    buckets = [deployed.outputs[f"{spec.logical.capitalize()}BucketName"] for spec in resources.BUCKETS]
    new_buckets = [again.outputs[f"{spec.logical.capitalize()}BucketName"] for spec in resources.BUCKETS]
    assert set(buckets).isdisjoint(new_buckets)
    for name in buckets + new_buckets:
        deployed.client("s3").head_bucket(Bucket=name)
