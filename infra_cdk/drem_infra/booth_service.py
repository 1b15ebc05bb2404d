"""The learning booth on AWS (opt-in: `make deploy BOOTH=1`, context `booth=true`): one Fargate task, image
booth/Dockerfile, in the live pages' VPC behind their load balancer, served through the app's CloudFront distribution.

Why a container and not the Lambda functions: a live drive keeps the racer's simulator in one process between control
messages (chalicelib.domain.booth_drive.LiveDrives), 15 a second; training needs PyTorch (several hundred MB, past
Lambda's 250 MB bundle) and minutes of CPU per job; tracks, finalising and the run pictures need the simulator, NumPy
and OpenCV, which the Lambda bundle leaves out. So the task runs three containers of the one image:

- `app`: drem_local.appserver, the Chalice app exactly as `drem up` serves it (same routes, same auth: the user pool's
  tokens and the session cookie, verified in the app). CloudFront sends it only BOOTH_PATHS; everything else stays
  with the functions. ONE task, replaced in place on deploy (never two at once): a second task would split a racer's
  control messages between two processes, and only one holds the drive.
- `trainer`: drem_local.workers.trainer, the booth's worker (one job at a time, oldest first), polling the booth
  table's queue; a job it was running when the task stopped is queued again when it starts (TrainingService).
- `scrutineer`: drem_local.workers.scrutineer, the background test drive of every new model (issue 17): with the
  booth, the functions queue new models for it (`DREM_SCRUTINEERING_WORKER=1` in their settings), as `drem up` does.

Both get the functions' settings (`DremStack.app_environment`) and a task role with the functions' data permissions
(tables, the models and runs buckets, the user pool's admin calls: drem_infra.permissions, which
tests/infra/test_iam_policy.py checks against the code). 2 vCPU, 4 GB: the app's simulators (at most 6 drives) and
one training job.
"""
from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import aws_cdk as cdk
from aws_cdk import aws_cloudfront as cloudfront
from aws_cdk import aws_cognito as cognito
from aws_cdk import aws_dynamodb as dynamodb
from aws_cdk import aws_ecr_assets as ecr_assets
from aws_cdk import aws_ecs as ecs
from aws_cdk import aws_elasticloadbalancingv2 as elbv2
from aws_cdk import aws_iam as iam
from aws_cdk import aws_logs as logs
from aws_cdk import aws_s3 as s3
from constructs import Construct

from drem_infra import permissions, resources
from drem_infra.live_pages import LivePages

REPO_ROOT = Path(__file__).resolve().parents[2]
DOCKERFILE = "booth/Dockerfile"
# What the image build may see (Docker ignore syntax, an allow-list): drem's own packages and the booth's lock only.
BOOTH_IMAGE_FILES: tuple[str, ...] = (
    "*",
    "!booth",
    "!requirements/booth.txt",
    "!infra_cdk/drem_infra/__init__.py",
    "!infra_cdk/drem_infra/resources.py",
    "!leaderboard/drem_leaderboard",
    "!archive/drem_archive",
    "!web/drem_web",
    "!sim/drem_sim",
    "!local/drem_local",
    "!functions/app.py",
    "!functions/chalicelib",
    "!functions/.chalice/config.json",
    "**/__pycache__",
    "**/*.pyc",
    "web/drem_web/static/vendor",
    "sim/drem_sim/samples",
)

# The booth's pages and API (functions/chalicelib/routes/booth.py, booth_pages.py), as CloudFront path patterns:
# every route there that needs the simulator, a live drive or the runs' pictures. The rest of the app stays on Lambda.
BOOTH_PATHS: tuple[str, ...] = (
    "/booth*", "/api/tracks*", "/api/drive", "/api/runs*", "/api/training-jobs*", "/api/metrics/runs*",
)
CONTAINER_PORT = 8080
HEALTH_PATH = "/healthz"
TASK_CPU = 2048  # 2 vCPU
TASK_MEMORY_MIB = 4096
LOG_RETENTION = logs.RetentionDays.ONE_MONTH
# An ALB listener rule takes at most 5 condition values: the origin secret header and 4 path patterns; the booth's
# paths fill two rules, tried before the live pages' rule.
RULE_PRIORITY = 10
PATTERNS_PER_RULE = 4


class BoothService(Construct):
    """The booth's task, its three containers, its routing from the live pages' load balancer and CloudFront."""

    def __init__(self, scope: Construct, construct_id: str, *, stage: str, environment: Mapping[str, str],
                 live: LivePages, tables: Mapping[str, dynamodb.Table], buckets: Mapping[str, s3.Bucket],
                 user_pool: cognito.UserPool) -> None:
        super().__init__(scope, construct_id)
        stack = cdk.Stack.of(self)
        self.stage = stage
        self.log_group = logs.LogGroup(self, "Logs", retention=LOG_RETENTION, removal_policy=cdk.RemovalPolicy.DESTROY)
        self.task_role = self._task_role(tables, buckets, user_pool)
        task = ecs.FargateTaskDefinition(
            self, "Task", cpu=TASK_CPU, memory_limit_mib=TASK_MEMORY_MIB, task_role=self.task_role,
            runtime_platform=ecs.RuntimePlatform(cpu_architecture=ecs.CpuArchitecture.X86_64,
                                                 operating_system_family=ecs.OperatingSystemFamily.LINUX))
        image = ecs.ContainerImage.from_asset(
            str(REPO_ROOT), file=DOCKERFILE, exclude=list(BOOTH_IMAGE_FILES), ignore_mode=cdk.IgnoreMode.DOCKER,
            platform=ecr_assets.Platform.LINUX_AMD64)
        settings = {**environment, "AWS_DEFAULT_REGION": stack.region}
        task.add_container(
            "App", image=image, environment=settings, essential=True,
            command=["python", "-m", "drem_local.appserver", "--host", "0.0.0.0", "--port", str(CONTAINER_PORT),
                     "--stage", stage, "--serve-only"],
            port_mappings=[ecs.PortMapping(container_port=CONTAINER_PORT)],
            logging=ecs.LogDrivers.aws_logs(stream_prefix="booth-app", log_group=self.log_group))
        task.add_container(
            "Trainer", image=image, environment=settings, essential=True,
            command=["python", "-m", "drem_local.workers.trainer"],
            logging=ecs.LogDrivers.aws_logs(stream_prefix="booth-trainer", log_group=self.log_group))
        task.add_container(
            "Scrutineer", image=image, environment=settings, essential=True,
            command=["python", "-m", "drem_local.workers.scrutineer"],
            logging=ecs.LogDrivers.aws_logs(stream_prefix="booth-scrutineer", log_group=self.log_group))
        self.service = ecs.FargateService(
            self, "Service", cluster=live.cluster, task_definition=task, desired_count=1, assign_public_ip=True,
            vpc_subnets=live.public_subnets,
            # Never two tasks: the old one stops before the new one starts (a deploy ends the drives in progress).
            min_healthy_percent=0, max_healthy_percent=100,
            circuit_breaker=ecs.DeploymentCircuitBreaker(rollback=True))
        self.target_group = elbv2.ApplicationTargetGroup(
            self, "Targets", vpc=live.vpc, port=CONTAINER_PORT, protocol=elbv2.ApplicationProtocol.HTTP,
            targets=[self.service.load_balancer_target(container_name="App", container_port=CONTAINER_PORT)],
            deregistration_delay=cdk.Duration.seconds(10),
            health_check=elbv2.HealthCheck(path=HEALTH_PATH, healthy_http_codes="200",
                                           interval=cdk.Duration.seconds(15), timeout=cdk.Duration.seconds(5),
                                           healthy_threshold_count=2, unhealthy_threshold_count=3))
        for index, start in enumerate(range(0, len(BOOTH_PATHS), PATTERNS_PER_RULE)):
            live.listener.add_target_groups(
                f"Booth{index}", priority=RULE_PRIORITY + index, target_groups=[self.target_group],
                conditions=[live.from_cloudfront(), elbv2.ListenerCondition.path_patterns(
                    list(BOOTH_PATHS[start:start + PATTERNS_PER_RULE]))])

    def _task_role(self, tables: Mapping[str, dynamodb.Table], buckets: Mapping[str, s3.Bucket],
                   user_pool: cognito.UserPool) -> iam.Role:
        """The functions' data permissions (drem_infra.permissions), nothing more: it runs the same code."""
        statements = [
            iam.PolicyStatement(actions=list(permissions.TABLE_ACTIONS),
                                resources=[arn for t in tables.values() for arn in (t.table_arn,
                                                                                     f"{t.table_arn}/index/*")]),
            iam.PolicyStatement(actions=list(permissions.USER_POOL_ACTIONS), resources=[user_pool.user_pool_arn]),
        ]
        statements += [iam.PolicyStatement(actions=list(actions), resources=[buckets[logical].arn_for_objects("*")])
                       for logical, actions in permissions.BUCKET_OBJECT_ACTIONS.items()]
        statements += [iam.PolicyStatement(actions=list(actions), resources=[buckets[logical].bucket_arn])
                       for logical, actions in permissions.BUCKET_ACTIONS.items()]
        statements.append(iam.PolicyStatement(actions=list(permissions.PARAMETER_ACTIONS), resources=[
            cdk.Stack.of(self).format_arn(service="ssm", resource="parameter",
                                          resource_name=resources.public_url_parameter(self.stage).lstrip("/"))]))
        return iam.Role(self, "TaskRole", assumed_by=iam.ServicePrincipal("ecs-tasks.amazonaws.com"),
                        description="drem learning booth: the app's data permissions for drives and training",
                        inline_policies={"DremBooth": iam.PolicyDocument(statements=statements)})

    def serve_through(self, distribution: cloudfront.Distribution, live: LivePages) -> None:
        """BOOTH_PATHS of the app's distribution to the load balancer: uncached, every method, with the viewer's
        cookies, query and headers but its Host (the same origin request policy as the functions' behaviour)."""
        for pattern in BOOTH_PATHS:
            distribution.add_behavior(
                pattern, live.origin, viewer_protocol_policy=cloudfront.ViewerProtocolPolicy.REDIRECT_TO_HTTPS,
                allowed_methods=cloudfront.AllowedMethods.ALLOW_ALL,
                cache_policy=cloudfront.CachePolicy.CACHING_DISABLED,
                origin_request_policy=cloudfront.OriginRequestPolicy.ALL_VIEWER_EXCEPT_HOST_HEADER)
