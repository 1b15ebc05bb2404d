"""Alarms reach someone: every alarm of a stage (the functions' errors and throttles, the API stage's rejected requests
and server errors, the live pages') notifies the stage's one SNS topic when it goes off and when it clears, and
`make deploy ... ALARM_EMAIL=ops@example.org` subscribes that address to it. Read from the real app's synthesised
template (tests/infra/conftest.py); the email option from storage-only stacks, which synthesise in seconds."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

os.environ.setdefault("JSII_SILENCE_WARNING_END_OF_LIFE_NODE_VERSION", "20")

from drem_infra import stack as drem_stack  # noqa: E402

pytestmark = pytest.mark.infra

REPO_ROOT = Path(__file__).resolve().parents[2]
OPS = "ops+drem@example.org"


def _topic(template) -> str:
    topics = template.find_resources("AWS::SNS::Topic")
    assert len(topics) == 1, f"one alarm topic per stage: {list(topics)}"
    return next(iter(topics))


def _alarms(template) -> list[dict]:
    return [a["Properties"] for a in template.find_resources("AWS::CloudWatch::Alarm").values()]


def test_every_alarm_of_the_stage_notifies_its_one_topic_when_it_fires_and_when_it_clears(app_template):
    topic = _topic(app_template)
    alarms = _alarms(app_template)
    functions = app_template.find_resources("AWS::Serverless::Function")

    watched = sorted(f"{a['Namespace']}/{a['MetricName']}" for a in alarms)
    assert watched == sorted(
        [f"AWS/Lambda/{m}" for _ in functions for m in ("Errors", "Throttles")]
        + ["AWS/ApiGateway/4XXError", "AWS/ApiGateway/5XXError"]
        + ["AWS/ApplicationELB/UnHealthyHostCount", "AWS/ApplicationELB/HTTPCode_Target_5XX_Count",
           "AWS/ApplicationELB/HTTPCode_ELB_5XX_Count"])
    for alarm in alarms:
        assert alarm["AlarmActions"] == [{"Ref": topic}], alarm["AlarmDescription"]
        assert alarm["OKActions"] == [{"Ref": topic}], alarm["AlarmDescription"]
        assert alarm.get("ActionsEnabled", True) is True
    # Subscribe more (a phone, a chat integration) by hand: the topic's ARN is a stack output.
    assert app_template.to_json()["Outputs"]["AlarmTopicArn"]["Value"] == {"Ref": topic}


def test_the_api_stage_alarms_on_rejected_requests_throttling_among_them_and_on_server_errors(app_template):
    [api] = app_template.find_resources("AWS::Serverless::Api").values()
    props = api["Properties"]
    alarms = {a["MetricName"]: a for a in _alarms(app_template) if a["Namespace"] == "AWS/ApiGateway"}

    assert set(alarms) == {"4XXError", "5XXError"}  # a throttled request is a 429, counted in 4XXError
    for alarm in alarms.values():
        # API Gateway names a REST API's metrics by the API's name and stage: these are this stack's API and stage.
        assert alarm["Dimensions"] == [{"Name": "ApiName", "Value": props["Name"]},
                                       {"Name": "Stage", "Value": props["StageName"]}]
        assert alarm["Statistic"] == "Sum" and alarm["Period"] == 300 and alarm["EvaluationPeriods"] == 1
        assert alarm["ComparisonOperator"] == "GreaterThanOrEqualToThreshold"
        assert alarm["TreatMissingData"] == "notBreaching"  # no traffic is not a problem
    assert props["Name"] == "drem-test" and props["DefinitionBody"]["info"]["title"] == props["Name"], \
        "stage-scoped, so two stages in one account are not counted together"
    # Throttling at the stage's rate limit crosses the 4xx line within seconds; ordinary 4xx (a few a minute) do not.
    rate_limit = props["MethodSettings"][0]["ThrottlingRateLimit"]
    assert 60 < alarms["4XXError"]["Threshold"] <= 2 * rate_limit
    assert alarms["5XXError"]["Threshold"] == drem_stack.API_5XX_PER_5_MINUTES


def test_without_alarm_email_the_topic_has_no_subscriber(template, app_template):
    assert app_template.find_resources("AWS::SNS::Subscription") == {}
    assert template.find_resources("AWS::SNS::Subscription") == {}
    _topic(template)  # the storage-only stack of a stage has its topic too (nothing notifies it yet)


def _storage_only(tmp_path: Path, alarm_email: str | None = None):
    import aws_cdk as cdk
    from aws_cdk.assertions import Template

    app = cdk.App(outdir=str(tmp_path / "cdk.out"))
    return Template.from_stack(drem_stack.DremStack(app, "drem-ops", stage="ops", alarm_email=alarm_email))


def test_alarm_email_subscribes_that_address_to_the_stages_topic(tmp_path):
    template = _storage_only(tmp_path, alarm_email=OPS)

    [subscription] = template.find_resources("AWS::SNS::Subscription").values()
    assert subscription["Properties"] == {"Protocol": "email", "Endpoint": OPS,
                                          "TopicArn": {"Ref": _topic(template)}}


@pytest.mark.parametrize("address", ["ops at example.org", "ops@example.org,dev@example.org", "Ops <ops@example.org>"])
def test_a_wrong_alarm_email_stops_the_synth_saying_what_to_fix(tmp_path, address):
    with pytest.raises(ValueError, match=r"ALARM_EMAIL=.* is not an email address"):
        _storage_only(tmp_path, alarm_email=address)


def test_make_deploy_passes_alarm_email_to_cdk_only_when_given():
    def deploy_lines(*settings: str) -> list[str]:
        dry_run = subprocess.run(["make", "-n", "deploy", "STAGE=ops", *settings], cwd=REPO_ROOT,
                                 capture_output=True, text=True, timeout=60)
        assert dry_run.returncode == 0, dry_run.stderr
        return [line for line in dry_run.stdout.splitlines() if "cdk deploy drem-ops" in line]

    with_email, without = deploy_lines(f"ALARM_EMAIL={OPS}"), deploy_lines()
    assert with_email and all(f"-c alarm_email='{OPS}'" in line for line in with_email)
    assert without and not [line for line in without if "alarm_email" in line]


def _cdk_app(tmp_path: Path, context: dict[str, str]) -> subprocess.CompletedProcess:
    """infra_cdk/app.py as `cdk synth` runs it: context and output folder from the CDK CLI's environment variables."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env.update(CDK_CONTEXT_JSON=json.dumps({"with_app": "false", **context}), CDK_OUTDIR=str(tmp_path / "cdk.out"))
    return subprocess.run([sys.executable, "app.py"], cwd=REPO_ROOT / "infra_cdk", env=env, capture_output=True,
                          text=True, timeout=300)


def test_the_cdk_app_takes_alarm_email_from_the_context_make_deploy_sets(tmp_path):
    synth = _cdk_app(tmp_path, {"stage": "ctx", "alarm_email": OPS})
    assert synth.returncode == 0, synth.stderr
    resources = json.loads((tmp_path / "cdk.out" / "drem-ctx.template.json").read_text())["Resources"]
    assert [r["Properties"]["Endpoint"] for r in resources.values() if r["Type"] == "AWS::SNS::Subscription"] == [OPS]

    wrong = _cdk_app(tmp_path, {"stage": "ctx", "alarm_email": "ops at example.org"})
    assert wrong.returncode != 0 and "Traceback" not in wrong.stderr
    assert "drem-ctx: ALARM_EMAIL='ops at example.org' is not an email address" in wrong.stderr
