"""The learning booth on AWS (drem_infra.booth_service), read from the real app's synthesised template (synthesised
with `booth=True`, what `make deploy BOOTH=1` passes): one Fargate task with the app server and the trainer, reached
through the live pages' load balancer for exactly the booth's routes, with the functions' data permissions; and its
image, built from drem's own code and a hashed lock whose packages serve the booth's routes and train."""
from __future__ import annotations

import fnmatch
import json
import os
import socket
import subprocess
import time
from pathlib import Path

import pytest

from drem_infra import booth_service, live_pages, permissions
from tests.infra import image_steps

pytestmark = pytest.mark.infra

REPO_ROOT = Path(__file__).resolve().parents[2]
CACHING_DISABLED = "4135ea2d-6df8-44a3-9df3-4b5a84be39ad"  # AWS managed cache policy CachingDisabled
ALL_VIEWER_EXCEPT_HOST = "b689b0a8-53d0-40ab-baf2-68738e2966ac"  # managed origin request policy AllViewerExceptHost
TORCH_WHEELS = Path("/opt/wheels")  # where torch's CPU wheel lives on our machines (Makefile WHEELS)


def _booth(template, resource_type: str) -> dict[str, dict]:
    return {name: r for name, r in template.find_resources(resource_type).items() if name.startswith("Booth")}


def _only(found: dict[str, dict]) -> tuple[str, dict]:
    assert len(found) == 1, list(found)
    return next(iter(found.items()))


def test_one_task_runs_the_app_server_the_trainer_and_the_scrutineer_never_two_at_once(app_template):
    _, task = _only(_booth(app_template, "AWS::ECS::TaskDefinition"))
    props = task["Properties"]
    assert (props["Cpu"], props["Memory"]) == (str(booth_service.TASK_CPU), str(booth_service.TASK_MEMORY_MIB))
    containers = {c["Name"]: c for c in props["ContainerDefinitions"]}
    assert set(containers) == {"App", "Trainer", "Scrutineer"}
    app, trainer, scrutineer = containers["App"], containers["Trainer"], containers["Scrutineer"]
    assert app["Image"] == trainer["Image"] == scrutineer["Image"]
    assert all(c["Essential"] for c in containers.values())  # one that stops replaces the task
    assert app["Command"] == ["python", "-m", "drem_local.appserver", "--host", "0.0.0.0", "--port", "8080",
                              "--stage", "test", "--serve-only"]
    assert trainer["Command"] == ["python", "-m", "drem_local.workers.trainer"]
    assert scrutineer["Command"] == ["python", "-m", "drem_local.workers.scrutineer"]
    assert app["PortMappings"] == [{"ContainerPort": 8080, "Protocol": "tcp"}]
    assert "PortMappings" not in trainer and "PortMappings" not in scrutineer

    # The functions' settings (tables, buckets, user pool, public URL), so both run the app's code against the stage.
    functions = app_template.find_resources("AWS::Serverless::Function").values()
    function_env = next(iter(functions))["Properties"]["Environment"]["Variables"]
    # With the booth's scrutineering worker running, the functions queue every new model for a test drive.
    assert function_env["DREM_SCRUTINEERING_WORKER"] == "1"
    # All but the writer's wake-up secret of the live pages: the booth writes no board (drem_infra.live_pages).
    function_env = {k: v for k, v in function_env.items() if k != live_pages.WAKE_SECRET_ENV}
    for container in containers.values():
        env = {e["Name"]: e["Value"] for e in container["Environment"]}
        assert live_pages.WAKE_SECRET_ENV not in env and not container.get("Secrets")
        assert {k: v for k, v in env.items() if k in function_env} == function_env
        assert "AWS_DEFAULT_REGION" in env

    _, service = _only(_booth(app_template, "AWS::ECS::Service"))
    config = service["Properties"]["DeploymentConfiguration"]
    assert service["Properties"]["DesiredCount"] == 1
    assert (config["MinimumHealthyPercent"], config["MaximumPercent"]) == (0, 100)  # one process holds the drives
    assert _booth(app_template, "AWS::ApplicationAutoScaling::ScalableTarget") == {}
    live_cluster = [n for n in app_template.find_resources("AWS::ECS::Cluster") if n.startswith("Live")]
    assert service["Properties"]["Cluster"] == {"Ref": live_cluster[0]}


def test_cloudfront_sends_exactly_the_booths_routes_to_it_uncached_with_cookies(app_template):
    [distribution] = app_template.find_resources("AWS::CloudFront::Distribution").values()
    config = distribution["Properties"]["DistributionConfig"]
    behaviours = {b["PathPattern"]: b for b in config["CacheBehaviors"]}
    live_origin = behaviours[live_pages.PATH_PATTERN]["TargetOriginId"]
    for pattern in booth_service.BOOTH_PATHS:
        behaviour = behaviours[pattern]
        assert behaviour["TargetOriginId"] == live_origin  # the load balancer; its listener rules pick the booth
        assert set(behaviour["AllowedMethods"]) == {"GET", "HEAD", "OPTIONS", "PUT", "PATCH", "POST", "DELETE"}
        assert behaviour["CachePolicyId"] == CACHING_DISABLED
        assert behaviour["OriginRequestPolicyId"] == ALL_VIEWER_EXCEPT_HOST  # session cookie, CSRF header, query
        assert behaviour["ViewerProtocolPolicy"] == "redirect-to-https"
    assert len(config["CacheBehaviors"]) <= 25  # CloudFront's quota per distribution


def test_the_booths_paths_cover_every_booth_route_and_no_other(app_template):
    """CloudFront's `*` matches any characters, `/` included (fnmatch's does too)."""
    import app as chalice_app

    booth_modules = {"chalicelib.routes.booth", "chalicelib.routes.booth_pages"}
    routes = {path: {entry.view_function.__module__ for entry in methods.values()}
              for path, methods in chalice_app.app.routes.items()}
    booth_routes = {path for path, modules in routes.items() if modules & booth_modules}
    assert {"/api/tracks", "/api/drive", "/booth/drive/{track_id}", "/api/runs/{run_id}/drive"} <= booth_routes

    def sent_to_booth(path: str) -> bool:
        return any(fnmatch.fnmatchcase(path, pattern) for pattern in booth_service.BOOTH_PATHS)

    missing = sorted(p for p in booth_routes if not sent_to_booth(p) and p != "/api/models/{model_id}/active")
    assert missing == [], "booth routes the functions would answer without the simulator"
    captured = sorted(p for p, modules in routes.items() if sent_to_booth(p) and not modules & booth_modules)
    assert captured == [], "other routes the booth's container would take from the functions"


def test_the_load_balancer_routes_those_paths_to_the_booth_and_only_it_reaches_the_task(app_template):
    target_name, target_group = _only(_booth(app_template, "AWS::ElasticLoadBalancingV2::TargetGroup"))
    assert target_group["Properties"]["Port"] == 8080 and target_group["Properties"]["HealthCheckPath"] == "/healthz"
    rules = [r for name, r in app_template.find_resources("AWS::ElasticLoadBalancingV2::ListenerRule").items()
             if "Booth" in name]
    routed = []
    for rule in rules:
        props = rule["Properties"]
        assert props["Actions"] == [{"TargetGroupArn": {"Ref": target_name}, "Type": "forward"}]
        # Each rule also requires the stage's origin secret (tests/infra/test_live_scale_and_deploys.py).
        [condition] = [c for c in props["Conditions"] if c["Field"] != "http-header"]
        assert condition["Field"] == "path-pattern" and len(condition["PathPatternConfig"]["Values"]) <= 4
        routed += condition["PathPatternConfig"]["Values"]
    assert sorted(routed) == sorted(booth_service.BOOTH_PATHS)

    _, service = _only(_booth(app_template, "AWS::ECS::Service"))
    [task_group] = service["Properties"]["NetworkConfiguration"]["AwsvpcConfiguration"]["SecurityGroups"]
    ingress = [r["Properties"] for r in app_template.find_resources("AWS::EC2::SecurityGroupIngress").values()
               if r["Properties"]["GroupId"] == task_group]
    alb_group = [n for n in app_template.find_resources("AWS::EC2::SecurityGroup") if n.startswith("LiveLoadBalancer")]
    assert ingress and all(r["SourceSecurityGroupId"] == {"Fn::GetAtt": [alb_group[0], "GroupId"]}
                           and (r["FromPort"], r["ToPort"]) == (8080, 8080) for r in ingress)


def test_the_task_role_may_do_what_the_functions_may_with_the_data_and_nothing_else(app_template):
    roles = app_template.find_resources("AWS::IAM::Role")
    _, booth_role = _only({n: r for n, r in roles.items() if n.startswith("BoothTaskRole")})

    def grants(policies: list[dict]) -> set[tuple[str, str]]:
        found = set()
        for statement in (s for p in policies for s in p["PolicyDocument"]["Statement"]):
            actions = statement["Action"] if isinstance(statement["Action"], list) else [statement["Action"]]
            resources = statement["Resource"] if isinstance(statement["Resource"], list) else [statement["Resource"]]
            found |= {(a, json.dumps(r, sort_keys=True)) for a in actions for r in resources}
        return found

    functions = grants(roles["DefaultRole"]["Properties"]["Policies"])
    booth = grants(booth_role["Properties"]["Policies"])
    assert booth == {(a, r) for a, r in functions if a not in permissions.LOG_ACTIONS}
    assert booth_role["Properties"]["AssumeRolePolicyDocument"]["Statement"][0]["Principal"] == {
        "Service": "ecs-tasks.amazonaws.com"}


def test_the_booth_is_opt_in_on_the_deploy_command_line():
    def deploy_context(*args: str) -> str:
        dry = subprocess.run(["make", "-n", "deploy", "STAGE=x", *args], cwd=REPO_ROOT, capture_output=True,
                             text=True, timeout=60)
        assert dry.returncode == 0, dry.stderr
        return next(line for line in dry.stdout.splitlines() if " deploy drem-x " in line)

    assert "-c booth=true" in deploy_context("BOOTH=1")
    assert "booth" not in deploy_context()


# --- the image -------------------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def staged_image_context(tmp_path_factory):
    """The booth image's build context as `cdk synth` stages it (the booth and the live pages on a storage stack)."""
    out = tmp_path_factory.mktemp("booth-cdk") / "cdk.out"
    app, stack, live = image_steps.storage_stack_with_live_pages(out, "booth")
    booth_service.BoothService(stack, "Booth", stage="booth", environment=stack.app_environment(), live=live,
                               tables=stack.tables, buckets=stack.buckets, user_pool=stack.user_pool)
    app.synth()
    return image_steps.staged_context(out, "drem-booth", booth_service.DOCKERFILE)


def test_the_image_is_built_from_drems_own_code_only(staged_image_context):
    context, source = staged_image_context
    files = {str(p.relative_to(context)) for p in context.rglob("*") if p.is_file()}

    assert source["platform"] == "linux/amd64"
    assert {"booth/Dockerfile", "requirements/booth.txt", "functions/app.py", "functions/.chalice/config.json",
            "functions/chalicelib/routes/booth.py", "local/drem_local/appserver.py",
            "local/drem_local/workers/trainer.py", "sim/drem_sim/env.py", "sim/drem_sim/tracks/drem_oval.yaml",
            "infra_cdk/drem_infra/resources.py"} <= files
    assert {f.split("/")[0] for f in files} == {"booth", "requirements", "infra_cdk", "leaderboard", "archive", "web",
                                               "sim", "local", "functions"}
    assert "archive/drem_archive/member_names.py" in files  # the upload check's member vetting
    forbidden = (".venv/", ".drem", "node_modules/", "functions/vendor/", "cdk.out", "__pycache__", "static/vendor/",
                 "samples/", "functions/.chalice/deployments")
    assert not [f for f in files if any(part in f for part in forbidden)]
    assert [f for f in files if f.startswith("requirements/")] == ["requirements/booth.txt"]


def test_the_image_installs_only_hashed_wheels_torch_the_cpu_build(staged_image_context):
    context, _ = staged_image_context
    dockerfile = (context / booth_service.DOCKERFILE).read_text()
    lock = (context / "requirements" / "booth.txt").read_text()

    assert "pip install --require-hashes --no-deps --only-binary=:all:" in dockerfile
    names = image_steps.hashed_pins(lock)
    assert {"chalice", "boto3", "onnxruntime", "opencv-python-headless", "pymunk", "onnx", "numpy"} <= set(names)
    assert names["torch"] == "2.13.0+cpu"
    assert not [n for n in names if n.startswith(("nvidia-", "triton"))], "CUDA packages in the booth's lock"
    assert "USER 10001" in dockerfile


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


@pytest.mark.skipif(not (TORCH_WHEELS / "torch-2.13.0+cpu-cp311-cp311-manylinux_2_28_x86_64.whl").is_file() and
                    not os.environ.get("CI"), reason="torch's CPU wheel is not on this machine (/opt/wheels)")
def test_the_images_packages_serve_the_booth_routes_and_train(staged_image_context, tmp_path):
    """The Dockerfile's steps without Docker: its lock installed as it installs it (hashed wheels only; torch's CPU
    wheel from this machine's wheel directory instead of PyTorch's index), its COPY lines laid out under a stand-in
    /app, its PYTHONPATH. The app container's command then answers the booth's track list from the simulator, and
    the trainer's and the scrutineer's modules and torch import."""
    context, _ = staged_image_context
    root = tmp_path / "image"
    python = image_steps.install_lock(context / "requirements" / "booth.txt", tmp_path / "venv", TORCH_WHEELS)
    pythonpath = image_steps.lay_out(context, booth_service.DOCKERFILE, root)
    env = {"PATH": "/usr/bin:/bin", "PYTHONPATH": pythonpath, "AWS_DEFAULT_REGION": "us-east-1", "HOME": str(tmp_path),
           "DREM_STAGE": "booth"}

    trainer = subprocess.run([str(python), "-c",
                              "import torch, drem_local.workers.trainer, drem_sim.learn.pipeline\n"
                              "import drem_local.workers.scrutineer, drem_local.workers.scrutineer_drive\n"
                              "print(torch.__version__, drem_local.workers.trainer.__file__)"],
                             cwd=tmp_path, capture_output=True, text=True, timeout=300, env=env)
    assert trainer.returncode == 0, trainer.stderr
    version, location = trainer.stdout.split()
    assert version == "2.13.0+cpu" and location.startswith(str(root / "app" / "local"))

    port = _free_port()
    server = subprocess.Popen([str(python), "-m", "drem_local.appserver", "--host", "127.0.0.1",
                               "--port", str(port), "--stage", "booth", "--serve-only"], cwd=tmp_path, env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        import requests

        deadline, answer = time.monotonic() + 120, None
        while time.monotonic() < deadline and server.poll() is None:
            try:
                answer = requests.get(f"http://127.0.0.1:{port}/api/tracks", timeout=10)
                break
            except requests.ConnectionError:
                time.sleep(0.2)
        assert answer is not None, f"the app container's command did not serve:\n{server.communicate(timeout=5)[0]}"
        assert answer.status_code == 200, answer.text
        assert "drem_oval" in {track["track_id"] for track in answer.json()["tracks"]}
    finally:
        server.terminate()
        server.wait(10)
