"""Issue #34 on AWS, read from the synthesised templates: one-pass deploys (the functions read the public URL from the
stack's SSM parameter), only this stage's CloudFront reaches the live load balancer, the live server outlasts the load
balancer's idle connections and scales on its streams, functions end before API Gateway gives up, the upload checker
has its own concurrency, and spectators' polls have their own throttle budget."""
from __future__ import annotations

import json
from typing import Any

import pytest

from drem_infra import live_pages, resources
from drem_infra import stack as drem_stack

pytestmark = pytest.mark.infra


def _functions(template: Any) -> dict[str, dict]:
    return template.find_resources("AWS::Serverless::Function")


def _live(template: Any, resource_type: str) -> list[dict]:
    return [r for name, r in template.find_resources(resource_type).items() if not name.startswith("Booth")]


def test_without_a_domain_the_functions_read_cloudfronts_url_from_the_stacks_parameter(cloudfront_template):
    """The first deploy and every redeploy hand the functions the same environment: no pass without the URL."""
    parameter_name = resources.public_url_parameter("test")
    for function in _functions(cloudfront_template).values():
        variables = function["Properties"]["Environment"]["Variables"]
        assert "DREM_PUBLIC_URL" not in variables
        assert variables["DREM_PUBLIC_URL_PARAMETER"] == parameter_name
    [parameter] = cloudfront_template.find_resources("AWS::SSM::Parameter").values()
    assert parameter["Properties"]["Name"] == parameter_name
    value = json.dumps(parameter["Properties"]["Value"])
    [distribution] = cloudfront_template.find_resources("AWS::CloudFront::Distribution")
    assert '"https://"' in value and distribution in value and "DomainName" in value
    outputs = cloudfront_template.to_json()["Outputs"]
    assert distribution in json.dumps(outputs["PublicUrl"]["Value"]), "the recorded URL is CloudFront's, at once"


def test_the_functions_may_read_only_their_own_parameter(cloudfront_template):
    role = cloudfront_template.find_resources("AWS::IAM::Role")["DefaultRole"]
    statements = [s for p in role["Properties"]["Policies"] for s in p["PolicyDocument"]["Statement"]]
    [ssm] = [s for s in statements if any(a.startswith("ssm:") for a in ([s["Action"]] if isinstance(
        s["Action"], str) else s["Action"]))]
    assert ssm["Action"] == "ssm:GetParameter"
    assert "parameter/drem/test/public-url" in json.dumps(ssm["Resource"])


def test_with_a_known_url_the_functions_get_it_directly(app_template):
    for function in _functions(app_template).values():
        variables = function["Properties"]["Environment"]["Variables"]
        assert variables["DREM_PUBLIC_URL"].startswith("https://") and "DREM_PUBLIC_URL_PARAMETER" not in variables


def test_functions_end_before_api_gateway_gives_up_and_the_upload_checker_has_its_own_concurrency(app_template):
    functions = _functions(app_template)
    assert all(f["Properties"]["Timeout"] < 29 for f in functions.values()), "API Gateway's integration limit: 29 s"
    upload = [f for f in functions.values()
              if f["Properties"]["Handler"] == f"app.{resources.UPLOAD_COMPLETE_FUNCTION}"]
    assert [f["Properties"]["ReservedConcurrentExecutions"] for f in upload] == [drem_stack.UPLOAD_RESERVED_CONCURRENCY]
    others = [f for f in functions.values() if f not in upload]
    assert others and all("ReservedConcurrentExecutions" not in f["Properties"] for f in others)


def test_only_requests_carrying_the_stages_secret_get_past_the_load_balancer(app_template):
    [listener] = app_template.find_resources("AWS::ElasticLoadBalancingV2::Listener").values()
    [default] = listener["Properties"]["DefaultActions"]
    assert default["Type"] == "fixed-response" and default["FixedResponseConfig"]["StatusCode"] == "403"
    # (the other secret is the live tasks' peer secret, tests/infra/test_live_pages.py)
    [secret_id] = [s for s in app_template.find_resources("AWS::SecretsManager::Secret") if "OriginSecret" in s]
    rules = app_template.find_resources("AWS::ElasticLoadBalancingV2::ListenerRule").values()
    assert len(rules) >= 2  # the live pages and the learning booth (this template has BOOTH=1)
    for rule in rules:
        conditions = rule["Properties"]["Conditions"]
        headers = [c["HttpHeaderConfig"] for c in conditions if c["Field"] == "http-header"]
        assert [h["HttpHeaderName"] for h in headers] == [live_pages.ORIGIN_SECRET_HEADER]
        assert secret_id in json.dumps(headers) and "resolve:secretsmanager" in json.dumps(headers)
        assert sum(len(c.get("Values", [])) + len(c.get("PathPatternConfig", {}).get("Values", []))
                   + len(c.get("HttpHeaderConfig", {}).get("Values", [])) for c in conditions) <= 5
    config = next(iter(app_template.find_resources("AWS::CloudFront::Distribution").values()))
    origins = [o for o in config["Properties"]["DistributionConfig"]["Origins"]
               if "LoadBalancer" in json.dumps(o["DomainName"])]
    assert origins
    for origin in origins:
        headers = {h["HeaderName"]: json.dumps(h["HeaderValue"]) for h in origin["OriginCustomHeaders"]}
        assert secret_id in headers[live_pages.ORIGIN_SECRET_HEADER]


def test_the_live_server_keeps_idle_connections_longer_than_the_load_balancer(app_template):
    [alb] = _live(app_template, "AWS::ElasticLoadBalancingV2::LoadBalancer")
    idle = int({a["Key"]: a["Value"] for a in alb["Properties"]["LoadBalancerAttributes"]}[
        "idle_timeout.timeout_seconds"])
    [task] = _live(app_template, "AWS::ECS::TaskDefinition")
    [container] = task["Properties"]["ContainerDefinitions"]
    env = {e["Name"]: e["Value"] for e in container["Environment"]}
    assert float(env["DREM_LIVE_KEEPALIVE_S"]) > idle


def test_live_pages_scale_on_the_streams_they_carry_as_well_as_cpu(app_template):
    policies = [p["Properties"]["TargetTrackingScalingPolicyConfiguration"]
                for p in app_template.find_resources("AWS::ApplicationAutoScaling::ScalingPolicy").values()]
    [streams] = [p for p in policies if "CustomizedMetricSpecification" in p]
    metric = streams["CustomizedMetricSpecification"]
    assert (metric["Namespace"], metric["MetricName"], metric["Statistic"]) == (
        live_pages.STREAMS_METRIC_NAMESPACE, live_pages.STREAMS_METRIC_NAME, "Average")
    assert streams["TargetValue"] == live_pages.STREAMS_TARGET_PER_TASK
    [task] = _live(app_template, "AWS::ECS::TaskDefinition")
    env = {e["Name"]: e["Value"] for e in task["Properties"]["ContainerDefinitions"][0]["Environment"]}
    assert env["DREM_LIVE_METRICS_NAMESPACE"] == metric["Namespace"]
    assert [d["Value"] for d in metric["Dimensions"]] == [env["DREM_LIVE_METRICS_STAGE"]]


def test_spectators_polls_have_their_own_smaller_throttle_budget(app_template):
    [api] = app_template.find_resources("AWS::Serverless::Api").values()
    settings = {(s["ResourcePath"], s["HttpMethod"]): s for s in api["Properties"]["MethodSettings"]}
    default = settings[("/*", "*")]
    paths = set(api["Properties"]["DefinitionBody"]["paths"])
    for path in drem_stack.PUBLIC_POLL_PATHS:
        assert path in paths, f"{path} is not a route of the API"
        own = settings[("/" + path.replace("/", "~1"), "GET")]
        assert own["ThrottlingRateLimit"] < default["ThrottlingRateLimit"]
    assert "/api/timing/strip-events" in paths
    assert not any("timing" in path for path, _ in settings), "timers keep the stage's per-method budget"
