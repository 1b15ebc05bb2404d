"""The synthesized AWS stack matches drem_infra.resources: every expectation below is derived from it, so a change
to one without the other fails here. Synth is slow (seconds), so it happens once for the module."""
from __future__ import annotations

import json
import os
import textwrap
from pathlib import Path

import pytest

os.environ.setdefault("JSII_SILENCE_WARNING_END_OF_LIFE_NODE_VERSION", "20")

from drem_infra import resources  # noqa: E402

pytestmark = pytest.mark.infra

STAGE = "test"
REPO_ROOT = Path(__file__).resolve().parents[2]

# A stand-in Chalice project: it exercises the stack's wiring (env, grants, upload rule) without depending on the
# real app, which tests/infra/test_bundle.py packages and imports on its own.
WIRING_APP = textwrap.dedent(f"""
    from chalice import Chalice
    app = Chalice(app_name="drem")

    @app.route("/")
    def index():
        return {{}}

    @app.lambda_function(name="{resources.UPLOAD_COMPLETE_FUNCTION}")
    def upload_complete(event, context):
        return None
""")


@pytest.fixture(scope="module")
def templates(tmp_path_factory):
    import aws_cdk as cdk
    from aws_cdk.assertions import Template

    from drem_infra.stack import DremStack

    work = tmp_path_factory.mktemp("cdk")
    project = work / "functions"
    (project / ".chalice").mkdir(parents=True)
    (project / "chalicelib").mkdir()
    (project / "chalicelib" / "__init__.py").write_text("")
    (project / "app.py").write_text(WIRING_APP)
    (project / "requirements.txt").write_text("")
    (project / ".chalice" / "config.json").write_text(
        (REPO_ROOT / "functions" / ".chalice" / "config.json").read_text())

    cwd = os.getcwd()
    os.chdir(work)  # the Chalice construct writes chalice.out/ into the working directory
    try:
        app = cdk.App(outdir=str(work / "cdk.out"))
        storage_only = DremStack(app, "drem-storage", stage=STAGE)
        with_app = DremStack(app, "drem-app", stage=STAGE, functions_dir=project)
        app.synth()
        return Template.from_stack(storage_only), Template.from_stack(with_app)
    finally:
        os.chdir(cwd)


@pytest.fixture(scope="module")
def template(templates):
    return templates[0]


@pytest.fixture(scope="module")
def app_template(templates):
    return templates[1]


def _of_type(template, resource_type: str) -> dict:
    return template.find_resources(resource_type)


def _key_schema(pk: str, sk: str) -> list[dict]:
    return [{"AttributeName": pk, "KeyType": "HASH"}, {"AttributeName": sk, "KeyType": "RANGE"}]


def test_every_table_has_the_defined_keys_indexes_and_name(template):
    tables = {t["Properties"]["TableName"]: t["Properties"] for t in _of_type(template, "AWS::DynamoDB::Table").values()}

    assert set(tables) == {f"drem-{STAGE}-{spec.logical}" for spec in resources.TABLES}
    for spec in resources.TABLES:
        props = tables[resources.table_name(STAGE, spec.logical, env={})]
        assert props["KeySchema"] == _key_schema(spec.pk, spec.sk)
        assert props["BillingMode"] == "PAY_PER_REQUEST"
        assert {a["AttributeName"] for a in props["AttributeDefinitions"]} == set(spec.key_attributes)
        indexes = {g["IndexName"]: g["KeySchema"] for g in props.get("GlobalSecondaryIndexes", [])}
        assert indexes == {g.name: _key_schema(g.pk, g.sk) for g in spec.gsis}
        assert ("StreamSpecification" in props) == spec.stream


def test_every_bucket_is_private_ssl_only_and_accepts_browser_uploads(template):
    buckets = _of_type(template, "AWS::S3::Bucket")
    cors = resources.BROWSER_UPLOAD_CORS

    assert len(buckets) == len(resources.BUCKETS)
    for bucket in buckets.values():
        props = bucket["Properties"]
        assert props["PublicAccessBlockConfiguration"] == {
            "BlockPublicAcls": True, "BlockPublicPolicy": True, "IgnorePublicAcls": True, "RestrictPublicBuckets": True}
        rule = props["CorsConfiguration"]["CorsRules"][0]
        assert rule["AllowedOrigins"] == list(cors.allowed_origins)
        assert sorted(rule["AllowedMethods"]) == sorted(cors.allowed_methods)
    policies = _of_type(template, "AWS::S3::BucketPolicy").values()
    assert len(policies) == len(resources.BUCKETS)
    for policy in policies:
        denies = [s for s in policy["Properties"]["PolicyDocument"]["Statement"] if s["Effect"] == "Deny"]
        assert any(s["Condition"] == {"Bool": {"aws:SecureTransport": "false"}} for s in denies)
    notifications = _of_type(template, "Custom::S3BucketNotifications").values()
    sends_to_eventbridge = {n["Properties"]["BucketName"]["Ref"] for n in notifications
                            if "EventBridgeConfiguration" in n["Properties"]["NotificationConfiguration"]}
    expected = {logical_id for logical_id in buckets for spec in resources.BUCKETS
                if spec.eventbridge and logical_id.startswith(f"{spec.logical.capitalize()}Bucket")}
    assert sends_to_eventbridge == expected and expected


def test_user_pool_groups_policy_and_attributes_match_the_definition(template):
    spec = resources.USER_POOL
    pools = list(_of_type(template, "AWS::Cognito::UserPool").values())
    assert len(pools) == 1
    pool = pools[0]["Properties"]

    assert pool["UserPoolName"] == resources.user_pool_name(STAGE)
    policy = pool["Policies"]["PasswordPolicy"]
    assert policy == {
        "MinimumLength": spec.password_policy.minimum_length,
        "RequireLowercase": spec.password_policy.require_lowercase,
        "RequireUppercase": spec.password_policy.require_uppercase,
        "RequireNumbers": spec.password_policy.require_digits,
        "RequireSymbols": spec.password_policy.require_symbols,
        "TemporaryPasswordValidityDays": spec.password_policy.temporary_password_validity_days,
    }
    schema = {a["Name"]: a for a in pool["Schema"]}
    for attribute in spec.custom_attributes:
        assert schema[attribute.name]["AttributeDataType"] == attribute.data_type
        assert schema[attribute.name]["Mutable"] == attribute.mutable
    assert schema["email"]["Required"] is True
    assert pool["AdminCreateUserConfig"]["AllowAdminCreateUserOnly"] is (not spec.self_sign_up)

    groups = [g["Properties"]["GroupName"] for g in _of_type(template, "AWS::Cognito::UserPoolGroup").values()]
    assert sorted(groups) == sorted(resources.GROUPS)


def test_web_client_has_exactly_the_defined_flows_and_no_secret(template):
    spec = resources.USER_POOL
    clients = list(_of_type(template, "AWS::Cognito::UserPoolClient").values())
    assert len(clients) == 1
    client = clients[0]["Properties"]

    assert client["ClientName"] == resources.client_name(STAGE)
    assert sorted(client["ExplicitAuthFlows"]) == sorted(spec.explicit_auth_flows)
    assert client["GenerateSecret"] is spec.generate_secret
    assert sorted(client["ReadAttributes"]) == sorted(spec.read_attributes)


def test_app_functions_get_the_environment_contract_for_every_resource(app_template):
    functions = _of_type(app_template, "AWS::Serverless::Function")
    expected = {"DREM_STAGE", "DREM_USER_POOL_ID", "DREM_USER_POOL_CLIENT_ID",
                *(resources.table_env_var(t.logical) for t in resources.TABLES),
                *(resources.bucket_env_var(b.logical) for b in resources.BUCKETS)}

    assert functions
    for function in functions.values():
        variables = function["Properties"]["Environment"]["Variables"]
        assert set(variables) >= expected
        assert variables["DREM_STAGE"] == STAGE


def test_app_role_may_read_and_write_every_table_and_bucket(app_template):
    statements = [s for p in _of_type(app_template, "AWS::IAM::Policy").values()
                  if {"Ref": "DefaultRole"} in p["Properties"].get("Roles", [])
                  for s in p["Properties"]["PolicyDocument"]["Statement"]]
    granted = str(statements)

    for logical_id, table in _of_type(app_template, "AWS::DynamoDB::Table").items():
        assert logical_id in granted, f"no grant for table {table['Properties']['TableName']}"
    for logical_id in _of_type(app_template, "AWS::S3::Bucket"):
        assert logical_id in granted, f"no grant for bucket {logical_id}"
    actions = {a for s in statements for a in (s["Action"] if isinstance(s["Action"], list) else [s["Action"]])}
    assert {"dynamodb:PutItem", "dynamodb:Query", "s3:PutObject", "cognito-idp:AdminCreateUser"} <= actions


def test_model_uploads_trigger_the_upload_complete_function(app_template):
    rules = list(_of_type(app_template, "AWS::Events::Rule").values())
    upload_rules = [r["Properties"] for r in rules
                    if r["Properties"]["EventPattern"].get("detail-type") == ["Object Created"]]
    assert len(upload_rules) == 1
    rule = upload_rules[0]
    target_function = rule["Targets"][0]["Arn"]["Fn::GetAtt"][0]
    functions = _of_type(app_template, "AWS::Serverless::Function")

    assert functions[target_function]["Properties"]["Handler"] == f"app.{resources.UPLOAD_COMPLETE_FUNCTION}"
    assert rule["EventPattern"]["detail"]["object"]["key"] == [{"prefix": resources.UPLOADS_PREFIX}]
    models_bucket = rule["EventPattern"]["detail"]["bucket"]["name"][0]["Ref"]
    assert models_bucket in _of_type(app_template, "AWS::S3::Bucket")
    permissions = [p["Properties"] for p in _of_type(app_template, "AWS::Lambda::Permission").values()
                   if p["Properties"]["Principal"] == "events.amazonaws.com"]
    assert [p["FunctionName"] for p in permissions] == [{"Fn::GetAtt": [target_function, "Arn"]}]


def test_an_unknown_path_is_a_404_not_api_gateways_403(app_template):
    responses = [r["Properties"] for r in _of_type(app_template, "AWS::ApiGateway::GatewayResponse").values()]
    [missing] = [r for r in responses if r["ResponseType"] == "MISSING_AUTHENTICATION_TOKEN"]
    assert missing["StatusCode"] == "404"
    assert missing["RestApiId"] == {"Ref": "RestAPI"}
    assert json.loads(missing["ResponseTemplates"]["application/json"])["error"]["code"] == "NotFound"
    assert "Not found" in missing["ResponseTemplates"]["text/html"]


def test_synth_reads_no_local_name_overrides(monkeypatch):
    # A developer's DREM_TABLE_* must never rename a deployed table.
    monkeypatch.setenv("DREM_TABLE_EVENTS", "my-local-events")
    assert resources.table_name(STAGE, "events", env={}) == f"drem-{STAGE}-events"
    assert resources.table_name(STAGE, "events") == "my-local-events"


def test_synth_leaves_this_process_as_it_found_it(app_template):
    # The Chalice construct packaged an app in this process; later tests must not see its tokens or its modules.
    import sys
    leaked = {k: v for k, v in os.environ.items() if "${Token[" in v}
    assert leaked == {}
    packaged = [name for name, mod in sys.modules.items()
                if (name == "app" or name.startswith("chalicelib")) and "cdk" in str(getattr(mod, "__file__", ""))]
    assert packaged == []
