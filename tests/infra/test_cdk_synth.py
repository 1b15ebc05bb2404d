"""The synthesized AWS stack matches drem_infra.resources: every expectation below is derived from it, so a change
to one without the other fails here. Synth is slow (seconds), so it happens once per session
(tests/infra/conftest.py)."""
from __future__ import annotations

import json
import os

import pytest

os.environ.setdefault("JSII_SILENCE_WARNING_END_OF_LIFE_NODE_VERSION", "20")

from drem_infra import resources  # noqa: E402

pytestmark = pytest.mark.infra

STAGE = "test"  # the stage tests/infra/conftest.py synthesises


def _of_type(template, resource_type: str) -> dict:
    return template.find_resources(resource_type)


def _key_schema(pk: str, sk: str) -> list[dict]:
    return [{"AttributeName": pk, "KeyType": "HASH"}, {"AttributeName": sk, "KeyType": "RANGE"}]


def test_every_table_has_the_defined_keys_and_indexes_and_a_generated_name(template):
    found = _of_type(template, "AWS::DynamoDB::Table")
    tables = {spec.logical: next(t["Properties"] for logical_id, t in found.items()
                                 if logical_id.startswith(f"{spec.logical.capitalize()}Table"))
              for spec in resources.TABLES}

    assert len(found) == len(resources.TABLES)
    # Retained tables keep their data after `make destroy`; a fixed name would make the next deploy collide.
    assert all("TableName" not in props for props in tables.values())
    assert all(t["DeletionPolicy"] == "Retain" for t in found.values())
    for spec in resources.TABLES:
        props = tables[spec.logical]
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
    # No hosted UI, so no OAuth: CDK's default would enable the implicit grant with https://example.com.
    assert "AllowedOAuthFlows" not in client and "CallbackURLs" not in client
    assert client.get("AllowedOAuthFlowsUserPoolClient") in (None, False)
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
    # Answered before the app runs, so it carries the app's security headers itself.
    headers = {k.removeprefix("gatewayresponse.header."): v for k, v in missing["ResponseParameters"].items()}
    assert headers["X-Content-Type-Options"] == "'nosniff'" and headers["X-Frame-Options"] == "'DENY'"
    assert "default-src 'none'" in headers["Content-Security-Policy"]


def test_synth_reads_no_local_name_overrides(monkeypatch):
    # A developer's DREM_TABLE_* must never rename a deployed table.
    monkeypatch.setenv("DREM_TABLE_EVENTS", "my-local-events")
    assert resources.table_name(STAGE, "events", env={}) == f"drem-{STAGE}-events"
    assert resources.table_name(STAGE, "events") == "my-local-events"


def test_synth_leaves_the_apps_modules_and_blueprints_as_they_were(synthesised_in_this_process):
    # Packaging imports the app; Chalice consumes a blueprint's route options when registering it, so had the synth
    # reused this process's modules, a later `import app` would register POST routes as GET (duplicate routes).
    import sys

    from tests.infra.conftest import BEFORE_SYNTH
    before = BEFORE_SYNTH["app"]
    assert sys.modules["app"] is before
    assert sys.modules["chalicelib.routes.login"].bp is not None
    assert set(before.app.routes["/login"]) == {"GET", "POST"}


def test_synth_leaves_this_process_as_it_found_it(synthesised_in_this_process):
    # The Chalice construct packaged an app in this process; later tests must not see its tokens or its modules.
    import sys
    leaked = {k: v for k, v in os.environ.items() if "${Token[" in v}
    assert leaked == {}
    packaged = [name for name, mod in sys.modules.items()
                if (name == "app" or name.startswith("chalicelib")) and "cdk" in str(getattr(mod, "__file__", ""))]
    assert packaged == []
