"""The live pages on AWS (drem_infra.live_pages), read from the real app's synthesised template: the push server on
Fargate behind a load balancer only CloudFront reaches, served uncached at /live/* of the app's own distribution with
timeouts that let a Server-Sent-Events stream live, its logs expiring and its failures alarmed. The task role is
checked against the code in tests/infra/test_iam_policy.py."""
from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

from drem_infra import live_pages
from tests.infra import image_steps

pytestmark = pytest.mark.infra

REPO_ROOT = Path(__file__).resolve().parents[2]
CACHING_DISABLED = "4135ea2d-6df8-44a3-9df3-4b5a84be39ad"  # AWS managed cache policy CachingDisabled


def _one(template, resource_type: str) -> tuple[str, dict]:
    """The one resource of this type outside the learning booth's construct (tests/infra/test_booth_service.py)."""
    found = {name: r for name, r in template.find_resources(resource_type).items() if not name.startswith("Booth")}
    assert len(found) == 1, f"{resource_type}: {list(found)}"
    return next(iter(found.items()))


def _live_behaviour(app_template) -> tuple[dict, dict]:
    config = _one(app_template, "AWS::CloudFront::Distribution")[1]["Properties"]["DistributionConfig"]
    behaviour = {b["PathPattern"]: b for b in config["CacheBehaviors"]}[live_pages.PATH_PATTERN]
    origin = {o["Id"]: o for o in config["Origins"]}[behaviour["TargetOriginId"]]
    return behaviour, origin


def test_live_pages_reach_the_load_balancer_uncached_with_the_viewers_accept_encoding(app_template):
    behaviour, origin = _live_behaviour(app_template)
    alb_id, _ = _one(app_template, "AWS::ElasticLoadBalancingV2::LoadBalancer")

    assert origin["DomainName"] == {"Fn::GetAtt": [alb_id, "DNSName"]}
    assert behaviour["CachePolicyId"] == CACHING_DISABLED, "every stream goes to the server, none is collapsed"
    assert behaviour["Compress"] is False, "the server's gzip passes through; CloudFront compresses nothing"
    assert behaviour["ViewerProtocolPolicy"] == "redirect-to-https"
    assert sorted(behaviour["AllowedMethods"]) == ["GET", "HEAD"]
    policies = app_template.find_resources("AWS::CloudFront::OriginRequestPolicy")
    policy = policies[behaviour["OriginRequestPolicyId"]["Ref"]]["Properties"]["OriginRequestPolicyConfig"]
    # With caching disabled, Accept-Encoding is an ordinary viewer header: only "all viewer headers" forwards it (an
    # allow-list may not name it). Cookies stay with the app: the live pages are public.
    # CloudFront's own viewer-address header too: the server caps streams per viewer address.
    assert policy["HeadersConfig"] == {"HeaderBehavior": "allViewerAndWhitelistCloudFront",
                                       "Headers": ["CloudFront-Viewer-Address"]}
    assert policy["QueryStringsConfig"] == {"QueryStringBehavior": "all"}
    assert policy["CookiesConfig"] == {"CookieBehavior": "none"}
    # The rest of the site still goes to the API as before.
    config = _one(app_template, "AWS::CloudFront::Distribution")[1]["Properties"]["DistributionConfig"]
    assert config["DefaultCacheBehavior"]["TargetOriginId"] != behaviour["TargetOriginId"]


def test_timeouts_outlast_the_heartbeat_so_a_quiet_stream_stays_open(app_template):
    _, origin = _live_behaviour(app_template)
    vpc_origin = origin["VpcOriginConfig"]
    heartbeat = live_pages.HEARTBEAT_SECONDS

    assert vpc_origin["OriginReadTimeout"] >= 2 * heartbeat, "a missed heartbeat must not cut the stream"
    assert vpc_origin["OriginKeepaliveTimeout"] >= heartbeat
    assert "ResponseCompletionTimeout" not in origin, "a stream has no total time limit"
    _, alb = _one(app_template, "AWS::ElasticLoadBalancingV2::LoadBalancer")
    attributes = {a["Key"]: a["Value"] for a in alb["Properties"]["LoadBalancerAttributes"]}
    assert int(attributes["idle_timeout.timeout_seconds"]) > 2 * heartbeat
    _, target_group = _one(app_template, "AWS::ElasticLoadBalancingV2::TargetGroup")
    props = target_group["Properties"]
    assert props["HealthCheckPath"] == live_pages.HEALTH_PATH and props["Port"] == live_pages.CONTAINER_PORT
    assert props["TargetType"] == "ip"


def test_one_small_fargate_task_in_public_subnets_and_no_nat_gateway(app_template):
    _, service = _one(app_template, "AWS::ECS::Service")
    props = service["Properties"]
    assert props["LaunchType"] == "FARGATE" and props["DesiredCount"] == 1
    network = props["NetworkConfiguration"]["AwsvpcConfiguration"]
    assert network["AssignPublicIp"] == "ENABLED", "without a NAT gateway the task reaches DynamoDB and ECR itself"
    assert app_template.find_resources("AWS::EC2::NatGateway") == {}
    subnets = app_template.find_resources("AWS::EC2::Subnet")
    public = {name for name, subnet in subnets.items() if subnet["Properties"]["MapPublicIpOnLaunch"]}
    assert {subnet["Ref"] for subnet in network["Subnets"]} == public
    _, task = _one(app_template, "AWS::ECS::TaskDefinition")
    assert int(task["Properties"]["Cpu"]) <= 1024 and int(task["Properties"]["Memory"]) <= 2048
    assert task["Properties"]["RuntimePlatform"]["CpuArchitecture"] == "X86_64"
    _, scaling = _one(app_template, "AWS::ApplicationAutoScaling::ScalableTarget")
    assert scaling["Properties"]["MinCapacity"] == 1 and scaling["Properties"]["MaxCapacity"] >= 1
    policies = [p["Properties"]["TargetTrackingScalingPolicyConfiguration"]
                for p in app_template.find_resources("AWS::ApplicationAutoScaling::ScalingPolicy").values()]
    assert [t["PredefinedMetricSpecification"]["PredefinedMetricType"] for t in policies
            if "PredefinedMetricSpecification" in t] == ["ECSServiceAverageCPUUtilization"]


def _routes_to_the_internet(app_template) -> set[str]:
    """Route tables with a route to the internet gateway (or any NAT): what a subnet needs to be reachable at all."""
    routes = app_template.find_resources("AWS::EC2::Route").values()
    return {json.dumps(r["Properties"]["RouteTableId"]) for r in routes
            if r["Properties"].get("DestinationCidrBlock") == "0.0.0.0/0"}


def test_the_load_balancer_is_internal_so_no_listener_serves_plain_http_to_the_internet(app_template):
    """CloudFront reaches it as a VPC origin; nothing on the internet can open a connection to it."""
    balancers = app_template.find_resources("AWS::ElasticLoadBalancingV2::LoadBalancer")
    assert balancers and all(b["Properties"]["Scheme"] == "internal" for b in balancers.values())
    listeners = app_template.find_resources("AWS::ElasticLoadBalancingV2::Listener").values()
    assert [(one["Properties"]["Protocol"], one["Properties"]["Port"]) for one in listeners] == [("HTTP", 80)]
    _, alb = _one(app_template, "AWS::ElasticLoadBalancingV2::LoadBalancer")
    subnets = app_template.find_resources("AWS::EC2::Subnet")
    associations = {a["Properties"]["SubnetId"]["Ref"]: json.dumps(a["Properties"]["RouteTableId"])
                    for a in app_template.find_resources("AWS::EC2::SubnetRouteTableAssociation").values()}
    for subnet in alb["Properties"]["Subnets"]:
        assert subnets[subnet["Ref"]]["Properties"]["MapPublicIpOnLaunch"] is False
        assert associations[subnet["Ref"]] not in _routes_to_the_internet(app_template), "an isolated subnet"


def test_booth_and_live_requests_cross_no_plain_hop(app_template):
    """Viewer to CloudFront: HTTPS. CloudFront to the load balancer: a VPC origin (AWS's network, never the internet),
    which the booth's session and refresh cookies travel too. Every other origin: HTTPS only."""
    behaviour, origin = _live_behaviour(app_template)
    alb_id, _ = _one(app_template, "AWS::ElasticLoadBalancingV2::LoadBalancer")
    assert "CustomOriginConfig" not in origin, "not a public custom origin"
    vpc_origin_id = origin["VpcOriginConfig"]["VpcOriginId"]["Fn::GetAtt"][0]
    endpoint = app_template.find_resources("AWS::CloudFront::VpcOrigin")[vpc_origin_id]["Properties"][
        "VpcOriginEndpointConfig"]
    assert endpoint["Arn"] == {"Ref": alb_id}
    config = _one(app_template, "AWS::CloudFront::Distribution")[1]["Properties"]["DistributionConfig"]
    assert all(b["ViewerProtocolPolicy"] == ("https-only" if b.get("PathPattern") == live_pages.WAKE_PATH
                                             else "redirect-to-https")
               for b in [config["DefaultCacheBehavior"], *config["CacheBehaviors"]])
    others = [o for o in config["Origins"] if o["Id"] != origin["Id"]]
    assert others and all(o["CustomOriginConfig"]["OriginProtocolPolicy"] == "https-only" for o in others)


def test_only_cloudfront_reaches_the_load_balancer_and_only_the_load_balancer_the_task(app_template):
    alb_id, alb = _one(app_template, "AWS::ElasticLoadBalancingV2::LoadBalancer")
    [alb_group] = [g["Fn::GetAtt"][0] for g in alb["Properties"]["SecurityGroups"]]
    groups = app_template.find_resources("AWS::EC2::SecurityGroup")
    ingress = [(gid, rule) for gid, g in groups.items() for rule in g["Properties"].get("SecurityGroupIngress", [])]
    ingress += [(r["Properties"]["GroupId"]["Fn::GetAtt"][0], r["Properties"])
                for r in app_template.find_resources("AWS::EC2::SecurityGroupIngress").values()]

    assert not any(isinstance(rule.get("CidrIp"), str) or "CidrIpv6" in rule for _, rule in ingress), \
        "no address range outside the VPC is admitted anywhere"
    [(_, to_alb)] = [(g, r) for g, r in ingress if g == alb_group]
    assert to_alb["FromPort"] == to_alb["ToPort"] == 80
    [vpc_id] = app_template.find_resources("AWS::EC2::VPC")
    assert to_alb["CidrIp"] == {"Fn::GetAtt": [vpc_id, "CidrBlock"]}, "CloudFront's VPC-origin interfaces, in the VPC"
    _, service = _one(app_template, "AWS::ECS::Service")
    [task_group] = [g["Fn::GetAtt"][0] for g in
                    service["Properties"]["NetworkConfiguration"]["AwsvpcConfiguration"]["SecurityGroups"]]
    to_task = [r for g, r in ingress if g == task_group]
    # The load balancer on the server's port; the service's own tasks, and nothing else, on the peer port.
    assert sorted((r["SourceSecurityGroupId"]["Fn::GetAtt"][0], r["FromPort"], r["ToPort"]) for r in to_task) == \
        sorted([(alb_group, live_pages.CONTAINER_PORT, live_pages.CONTAINER_PORT),
                (task_group, live_pages.PEER_PORT, live_pages.PEER_PORT)])


def test_the_container_gets_the_apps_settings_and_the_app_links_live_pages_to_its_own_origin(app_template):
    _, task = _one(app_template, "AWS::ECS::TaskDefinition")
    [container] = task["Properties"]["ContainerDefinitions"]
    env = {e["Name"]: e["Value"] for e in container["Environment"]}
    functions = app_template.find_resources("AWS::Serverless::Function").values()
    lambda_env = [f["Properties"]["Environment"]["Variables"] for f in functions]

    assert all(v["DREM_LIVE_URL"] == "" for v in lambda_env), "same origin: CloudFront routes /live/* to the server"
    assert all(v["DREM_ASSIGNMENT_RECHECK_S"] == "1" for v in lambda_env), "no wake-up between Lambdas: re-read often"
    for name in (n for n in lambda_env[0] if n.startswith("DREM_") and n != live_pages.WAKE_SECRET_ENV):
        assert env[name] == lambda_env[0][name], name
    assert "AWS_DEFAULT_REGION" in env
    assert env["DREM_LIVE_CLIENT_ADDRESS_HEADER"] == "CloudFront-Viewer-Address", "caps count viewers, not CloudFront"
    assert container["PortMappings"] == [{"ContainerPort": live_pages.CONTAINER_PORT, "Protocol": "tcp"},
                                         {"ContainerPort": live_pages.PEER_PORT, "Protocol": "tcp"}]


def test_the_live_server_logs_expire_and_failures_raise_alarms(app_template):
    _, task = _one(app_template, "AWS::ECS::TaskDefinition")
    [container] = task["Properties"]["ContainerDefinitions"]
    log = container["LogConfiguration"]
    groups = app_template.find_resources("AWS::Logs::LogGroup")
    assert log["LogDriver"] == "awslogs"
    assert groups[log["Options"]["awslogs-group"]["Ref"]]["Properties"]["RetentionInDays"] > 0
    assert all(g["Properties"].get("RetentionInDays", 0) > 0 for g in groups.values()), "no log group kept forever"

    alarms = [a["Properties"] for a in app_template.find_resources("AWS::CloudWatch::Alarm").values()]
    watched = {a["MetricName"] for a in alarms if a.get("Namespace") == "AWS/ApplicationELB"}
    assert watched == {"UnHealthyHostCount", "HTTPCode_Target_5XX_Count", "HTTPCode_ELB_5XX_Count"}


@pytest.fixture(scope="module")
def staged_image_context(tmp_path_factory):
    """The image's build context as `cdk synth` stages it."""
    out = tmp_path_factory.mktemp("live-cdk") / "cdk.out"
    app, _, _ = image_steps.storage_stack_with_live_pages(out, "live")
    app.synth()
    return image_steps.staged_context(out, "drem-live", live_pages.DOCKERFILE)


def test_the_image_is_built_from_drems_own_code_only(staged_image_context):
    context, source = staged_image_context
    files = {str(p.relative_to(context)) for p in context.rglob("*") if p.is_file()}

    assert source["dockerFile"] == live_pages.DOCKERFILE and source["platform"] == "linux/amd64"
    assert {"live/Dockerfile", "requirements/live.txt", "infra_cdk/drem_infra/resources.py",
            "functions/chalicelib/routes/public_pages.py", "functions/chalicelib/services.py"} <= files
    assert any(f.startswith("leaderboard/drem_leaderboard/") for f in files)
    assert any(f.startswith("web/drem_web/templates/") for f in files)
    tops = {f.split("/")[0] for f in files}
    assert tops == {"live", "requirements", "infra_cdk", "leaderboard", "archive", "web", "functions"}
    assert "archive/drem_archive/member_names.py" in files  # chalicelib's archive readers import it
    # No local state, keys, virtualenvs, vendored wheels or build output in what docker sees.
    forbidden = (".venv/", ".drem", "node_modules/", "functions/vendor/", "cdk.out", "__pycache__", "static/vendor/")
    assert not [f for f in files if any(part in f for part in forbidden)]
    assert not any(f.startswith("infra_cdk/drem_infra/") and f.endswith(("stack.py", "live_pages.py")) for f in files)


def test_the_image_installs_only_hashed_wheels_and_runs_the_live_server(staged_image_context):
    context, _ = staged_image_context
    dockerfile = (context / live_pages.DOCKERFILE).read_text()
    lock = (context / "requirements" / "live.txt").read_text()

    assert "pip install --require-hashes --no-deps --only-binary=:all: -r" in dockerfile
    assert {"aiohttp", "boto3", "chalice", "pydantic", "jinja2"} <= set(image_steps.hashed_pins(lock))
    assert 'CMD ["python", "-m", "drem_live", "--host", "0.0.0.0", "--port", "8080"]' in dockerfile
    assert "USER 10001" in dockerfile



def test_the_images_packages_import_and_render_the_live_routes(staged_image_context, tmp_path):
    """The Dockerfile's steps without Docker: its lock installed as it installs it (hashed wheels only, no resolving),
    its COPY lines laid out under a stand-in /app, its PYTHONPATH; the live routes then import and render."""
    context, _ = staged_image_context
    root = tmp_path / "image"
    python = image_steps.install_lock(context / "requirements" / "live.txt", tmp_path / "venv")
    pythonpath = image_steps.lay_out(context, live_pages.DOCKERFILE, root)

    probe = ("import aiohttp, boto3\n"
             "from chalicelib.routes import public_pages\n"
             "from drem_web import render\n"
             "html = render.fragment('leaderboard_live', rows=[], footers=[], summaries=[], poll_url='/x', token='1',"
             " scroll=True, t=lambda s: s, clock_at=0, page_ms=8000, pushed_screen=None).body\n"
             "assert html.lstrip().startswith('<section'), html\n"
             "print(public_pages.__file__)\n")
    run = subprocess.run([str(python), "-c", probe], cwd=tmp_path, capture_output=True, text=True,
                         timeout=120, env={"PATH": "/usr/bin:/bin", "PYTHONPATH": pythonpath,
                                           "AWS_DEFAULT_REGION": "us-east-1"})
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip().startswith(str(root / "app" / "functions" / "chalicelib"))


def _behaviours(app_template) -> list[dict]:
    config = _one(app_template, "AWS::CloudFront::Distribution")[1]["Properties"]["DistributionConfig"]
    return config["CacheBehaviors"]


def _request_policy(app_template, behaviour: dict) -> dict:
    policies = app_template.find_resources("AWS::CloudFront::OriginRequestPolicy")
    return policies[behaviour["OriginRequestPolicyId"]["Ref"]]["Properties"]["OriginRequestPolicyConfig"]


def test_a_staff_preview_carries_the_session_cookies_and_a_car_may_post_its_frames(app_template):
    from chalicelib.auth.cookies import REFRESH_COOKIE, SESSION_COOKIE

    behaviours = _behaviours(app_template)
    order = [b["PathPattern"] for b in behaviours]
    by_path = {b["PathPattern"]: b for b in behaviours}
    live_origin = by_path[live_pages.PATH_PATTERN]["TargetOriginId"]
    preview, upload = by_path["/live/video/cars/*"], by_path["/live/video/car/*"]
    # CloudFront takes the first behaviour that matches: both come before the public /live/* one.
    assert order.index("/live/video/cars/*") < order.index("/live/*") > order.index("/live/video/car/*")
    for behaviour in (preview, upload):
        assert behaviour["TargetOriginId"] == live_origin
        assert behaviour["CachePolicyId"] == CACHING_DISABLED
        assert behaviour["ViewerProtocolPolicy"] == "redirect-to-https"
    # Only the two session cookies, only on the preview route: the public streams still get no cookie at all.
    cookies = _request_policy(app_template, preview)["CookiesConfig"]
    assert cookies["CookieBehavior"] == "whitelist" and sorted(cookies["Cookies"]) == [REFRESH_COOKIE, SESSION_COOKIE]
    assert sorted(preview["AllowedMethods"]) == ["GET", "HEAD"]
    assert _request_policy(app_template, upload)["CookiesConfig"] == {"CookieBehavior": "none"}
    assert "POST" in upload["AllowedMethods"]
    headers = _request_policy(app_template, upload)["HeadersConfig"]["HeaderBehavior"]
    assert headers.startswith("allViewer"), "the car's Authorization and X-Frame-Time reach the server"


def test_the_staff_preview_check_has_its_settings_and_its_one_read_on_aws(app_template):
    """The preview resolves the session as the app does (drem_live.video_access): the user pool to verify the token
    against, and the user's revocation mark in the sessions table the task is told of, which its role may read."""
    _, task = _one(app_template, "AWS::ECS::TaskDefinition")
    [container] = task["Properties"]["ContainerDefinitions"]
    env = {e["Name"]: e["Value"] for e in container["Environment"]}
    assert {"DREM_USER_POOL_ID", "DREM_USER_POOL_CLIENT_ID", "AWS_DEFAULT_REGION"} <= set(env)
    sessions_table = env["DREM_TABLE_SESSIONS"]["Ref"]
    role_id = task["Properties"]["TaskRoleArn"]["Fn::GetAtt"][0]
    role = app_template.find_resources("AWS::IAM::Role")[role_id]["Properties"]
    statements = [s for p in role["Policies"] for s in p["PolicyDocument"]["Statement"]]
    on_sessions = [s for s in statements if s["Resource"] == {"Fn::GetAtt": [sessions_table, "Arn"]}]
    assert [s["Action"] for s in on_sessions] == ["dynamodb:GetItem"]


def test_every_live_task_finds_the_others_by_one_name_and_only_they_reach_its_peer_port(app_template):
    from drem_live import video_peers

    [(namespace_id, namespace)] = app_template.find_resources("AWS::ServiceDiscovery::PrivateDnsNamespace").items()
    [vpc_id] = app_template.find_resources("AWS::EC2::VPC")
    assert namespace["Properties"]["Vpc"] == {"Ref": vpc_id}, "private to the stage's own VPC"
    _, service = _one(app_template, "AWS::ECS::Service")
    [registry] = service["Properties"]["ServiceRegistries"]
    discovery = app_template.find_resources("AWS::ServiceDiscovery::Service")[
        registry["RegistryArn"]["Fn::GetAtt"][0]]["Properties"]
    assert discovery["Name"] == live_pages.PEER_SERVICE_NAME
    assert discovery["DnsConfig"]["NamespaceId"] == {"Fn::GetAtt": [namespace_id, "Id"]}
    assert [r["Type"] for r in discovery["DnsConfig"]["DnsRecords"]] == ["A"], "one address per task"
    assert discovery["DnsConfig"]["RoutingPolicy"] == "MULTIVALUE", "the name answers with every task"

    _, task = _one(app_template, "AWS::ECS::TaskDefinition")
    [container] = task["Properties"]["ContainerDefinitions"]
    env = {e["Name"]: e["Value"] for e in container["Environment"]}
    assert env[video_peers.PEERS_ENV] == \
        f"{live_pages.PEER_SERVICE_NAME}.{namespace['Properties']['Name']}:{live_pages.PEER_PORT}"
    assert env[video_peers.PEER_LISTEN_ENV] == f"0.0.0.0:{live_pages.PEER_PORT}"
    # The shared secret comes from Secrets Manager at start, never as plain text in the template.
    [secret] = [s for s in container["Secrets"] if s["Name"] == video_peers.PEER_SECRET_ENV]
    assert "Ref" in secret["ValueFrom"]
    assert video_peers.PEER_SECRET_ENV not in env


def _wake_secret_id(app_template) -> str:
    _, task = _one(app_template, "AWS::ECS::TaskDefinition")
    [container] = task["Properties"]["ContainerDefinitions"]
    [secret] = [s for s in container["Secrets"] if s["Name"] == live_pages.WAKE_SECRET_ENV]
    return secret["ValueFrom"]["Ref"]


def test_the_names_the_writer_and_the_live_server_read_match_the_stacks():
    from chalicelib import live_wake

    assert (live_pages.WAKE_PATH, live_pages.WAKE_SECRET_ENV) == (live_wake.WAKE_PATH, live_wake.WAKE_SECRET_ENV)


def test_every_function_gets_the_wake_secret_the_live_tasks_get_and_the_public_url_to_post_to(app_template,
                                                                                              cloudfront_template):
    """The writer (the functions, outside the VPC) wakes the live tasks with a POST to the public origin's /live/wake,
    carrying the secret the tasks take from Secrets Manager at start; the public URL is the deploy's (or, without a
    domain, the stack's SSM parameter that the functions read at run time)."""
    for template in (app_template, cloudfront_template):
        secret_id = _wake_secret_id(template)
        secret = template.find_resources("AWS::SecretsManager::Secret")[secret_id]["Properties"]
        assert secret["GenerateSecretString"]["PasswordLength"] >= 32
        _, task = _one(template, "AWS::ECS::TaskDefinition")
        [container] = task["Properties"]["ContainerDefinitions"]
        assert live_pages.WAKE_SECRET_ENV not in {e["Name"] for e in container["Environment"]}, "not as plain text"
        functions = template.find_resources("AWS::Serverless::Function").values()
        for variables in (f["Properties"]["Environment"]["Variables"] for f in functions):
            reference = json.dumps(variables[live_pages.WAKE_SECRET_ENV])
            # A dynamic reference to that same secret, resolved at deploy time: the value is in no template.
            assert "{{resolve:secretsmanager:" in reference and f'{{"Ref": "{secret_id}"}}' in reference
            assert variables.get("DREM_PUBLIC_URL") or variables.get("DREM_PUBLIC_URL_PARAMETER")


def test_the_wake_up_post_reaches_the_live_tasks_uncached_over_https_only(app_template):
    behaviours = _behaviours(app_template)
    order = [b["PathPattern"] for b in behaviours]
    by_path = {b["PathPattern"]: b for b in behaviours}
    wake, public = by_path[live_pages.WAKE_PATH], by_path[live_pages.PATH_PATTERN]
    assert order.index(live_pages.WAKE_PATH) < order.index(live_pages.PATH_PATTERN), "matched before /live/*"
    assert wake["TargetOriginId"] == public["TargetOriginId"], "the live load balancer, through the VPC origin"
    assert wake["CachePolicyId"] == CACHING_DISABLED, "every wake-up reaches a task; none is collapsed"
    assert "POST" in wake["AllowedMethods"]
    assert wake["ViewerProtocolPolicy"] == "https-only", "the secret never travels a plain hop, not even once"
    headers = _request_policy(app_template, wake)["HeadersConfig"]["HeaderBehavior"]
    assert headers.startswith("allViewer"), "the wake secret header reaches the server"
    assert _request_policy(app_template, wake)["CookiesConfig"] == {"CookieBehavior": "none"}
    # The load balancer's rule for /live/* (with CloudFront's origin secret) covers it: no rule of its own.
    rules = app_template.find_resources("AWS::ElasticLoadBalancingV2::ListenerRule").values()
    live_rules = [r for r in rules if any(c.get("Field") == "path-pattern" and live_pages.PATH_PATTERN in
                                          c["PathPatternConfig"]["Values"] for c in r["Properties"]["Conditions"])]
    assert len(live_rules) == 1
    assert any(c.get("Field") == "http-header" for c in live_rules[0]["Properties"]["Conditions"])
