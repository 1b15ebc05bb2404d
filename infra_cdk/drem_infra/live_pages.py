"""The live pages on AWS: the live-page server (`python -m drem_live`, live/Dockerfile) on ECS Fargate behind an
Application Load Balancer, served through the app's CloudFront distribution at `/live/*`.

Spectators hold one Server-Sent-Events stream each; the server reads the materialised boards and overlays once per
channel and pushes each change to every viewer, so a spectator costs data transfer, not requests (bench/aws_cost.py).

- Network: a VPC with public subnets for the task and isolated subnets for the load balancer, and no NAT gateway (a
  NAT costs more a day than the whole live design); the task gets a public IP to reach DynamoDB and ECR.
- CloudFront reaches the load balancer as a **VPC origin**: the load balancer is internal (no public address, in the
  isolated subnets), and CloudFront connects to it from network interfaces it places in this VPC, over AWS's own
  network. No hop of a viewer's request crosses the internet unencrypted: the viewer's is HTTPS, CloudFront's to the
  load balancer stays inside AWS (the booth's session and refresh cookies travel this way). HTTPS to the load
  balancer would need a certificate for a domain it answers on, which a stage without a custom domain does not
  have. The load balancer's security group admits only this VPC's own addresses (where CloudFront's VPC-origin
  interfaces live) on port 80; nothing on the internet can open a connection to it at all.
- CloudFront `/live/*`: CachingDisabled (every stream and JSON read goes to the server; no request collapsing), with
  an origin request policy forwarding all viewer headers (so the viewer's `Accept-Encoding` reaches the server, which
  gzips each message once for everyone), the query string, and no cookies (public pages; session cookies stay with
  the app). See `serve_through` for why this combination and not a cache policy with compression.
- Timeouts: the server sends a heartbeat every 15 s (HEARTBEAT_SECONDS), so CloudFront's origin read timeout (the gap
  it tolerates between two packets), its keep-alive, and the load balancer's idle timeout all outlast a missed one.
  The server keeps an idle connection open longer than the load balancer does (SERVER_KEEPALIVE_SECONDS), so it is
  always the load balancer that closes one, never the server under a request the load balancer is sending (a 502).
- Only this stage's distribution gets through the load balancer: CloudFront adds a secret header (ORIGIN_SECRET_HEADER,
  a value generated in Secrets Manager at deploy time) to every origin request, and the listener forwards only requests
  that carry it (anything else: 403), so even something else inside the VPC is refused.
- The writer wakes the tasks: the functions (outside the VPC, so they cannot reach a task) POST each changed event id
  to the public origin's WAKE_PATH, through CloudFront (its own uncached POST behaviour) and the load balancer, to one
  task, with the stage's wake secret (Secrets Manager, handed to both); that task wakes its own viewers' channels and
  relays the wake-up to the other tasks on the peer port (drem_live.wake_route, drem_live.video_peers). Woken, a task
  polls storage only as the fallback (every 250 ms instead of 100 ms; bench/aws_cost.py).
- Scaling: on CPU and on the streams each task carries (the server publishes its open streams as a CloudWatch metric
  through its log, embedded metric format), so a task full of quiet streams scales out too.
"""
from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import aws_cdk as cdk
from aws_cdk import aws_cloudfront as cloudfront
from aws_cdk import aws_cloudfront_origins as origins
from aws_cdk import aws_cloudwatch as cloudwatch
from aws_cdk import aws_dynamodb as dynamodb
from aws_cdk import aws_ec2 as ec2
from aws_cdk import aws_ecr_assets as ecr_assets
from aws_cdk import aws_ecs as ecs
from aws_cdk import aws_elasticloadbalancingv2 as elbv2
from aws_cdk import aws_iam as iam
from aws_cdk import aws_logs as logs
from aws_cdk import aws_secretsmanager as secretsmanager
from aws_cdk import aws_servicediscovery as servicediscovery
from constructs import Construct

from drem_infra import permissions

REPO_ROOT = Path(__file__).resolve().parents[2]
DOCKERFILE = "live/Dockerfile"
# What the image build may see: an allow-list over the repository (Docker ignore syntax), so the staged build context
# never holds .venv, node_modules, .drem (local state and signing keys), .drem-aws or cdk.out.
LIVE_IMAGE_FILES: tuple[str, ...] = (
    "*",
    "!live",
    "!requirements/live.txt",
    "!infra_cdk/drem_infra/__init__.py",
    "!infra_cdk/drem_infra/resources.py",
    "!leaderboard/drem_leaderboard",
    "!archive/drem_archive",
    "!web/drem_web",
    "!functions/chalicelib",
    "**/__pycache__",
    "**/*.pyc",
    "web/drem_web/static/vendor",
)

VIEWER_ADDRESS_HEADER = "CloudFront-Viewer-Address"  # "address:port" of the viewer, added by CloudFront
PATH_PATTERN = "/live/*"
PREVIEW_PATH_PATTERN = "/live/video/cars/*"  # staff previews: the one live route that reads the session cookies
CAR_UPLOAD_PATH_PATTERN = "/live/video/car/*"  # a car's frames (POST) and its demand poll, with its device credential
SESSION_COOKIES = ("drem_session", "drem_refresh")  # chalicelib.auth.cookies SESSION_COOKIE, REFRESH_COOKIE
HEALTH_PATH = "/live/healthz"
CONTAINER_PORT = 8080
# The live server's SSE heartbeat (a comment line every 15 s); the timeouts below are set against it.
HEARTBEAT_SECONDS = 15
ORIGIN_READ_TIMEOUT = cdk.Duration.seconds(60)  # CloudFront's maximum without a quota increase; 4 heartbeats
ORIGIN_KEEPALIVE_TIMEOUT = cdk.Duration.seconds(60)
ALB_IDLE_TIMEOUT = cdk.Duration.seconds(120)
# A stream keeps its connection open, so a replaced task would otherwise wait the default 300 s before stopping;
# viewers reconnect (EventSource retries by itself) to the new one.
DEREGISTRATION_DELAY = cdk.Duration.seconds(30)
# One small task serves a 2,000-spectator event (bench/aws_cost.py); CPU autoscaling adds tasks up to max_tasks.
TASK_CPU = 512  # 0.5 vCPU
TASK_MEMORY_MIB = 1024
MIN_TASKS = 1
MAX_TASKS = 4
CPU_TARGET_PERCENT = 60
# Streams one live process writes a change to within 750 ms on one core (the 1 s lap-to-screen budget less the
# quiet floor): its CPU per delivered message, 75 us, measured by `bench/live_latency.py --capacity` (2026-11-27, one
# process pinned to one core, 2,000 streams; CPU time, which the shared machine's load does not inflate).
MEASURED_STREAMS_PER_CORE = 10_000
# Streams per task the connection scaling aims at: the measured figure for the task's 0.5 vCPU, with a fifth left
# for a crowd arriving within the minute scaling takes, below the server's cap per process (drem_live.limits, 5,000).
STREAMS_TARGET_PER_TASK = int(MEASURED_STREAMS_PER_CORE * TASK_CPU / 1024 * 0.8)
STREAMS_METRIC_NAMESPACE = "drem/live"
STREAMS_METRIC_NAME = "Streams"
SERVER_KEEPALIVE_SECONDS = 130  # longer than ALB_IDLE_TIMEOUT
ORIGIN_SECRET_HEADER = "X-Drem-Origin-Secret"
LIVE_RULE_PRIORITY = 50  # after the booth's rules (drem_infra.booth_service)
LOG_RETENTION = logs.RetentionDays.ONE_MONTH
ORIGIN_SUBNETS = "origin"  # the isolated subnets the internal load balancer lives in
# The cars' cameras across tasks (drem_live.video_peers): every task has an A record under one private DNS name, and
# takes the frames and viewer reports of the others on its own port, which only the service's own tasks reach.
PEER_PORT = 8081
PEER_NAMESPACE = "drem-live.internal"  # private to this stage's own VPC
PEER_SERVICE_NAME = "tasks"
PEER_DNS_TTL = cdk.Duration.seconds(10)  # a new task is found within this plus the server's re-resolve (5 s)
# drem_live.video_peers reads these (tests/infra/test_live_pages.py checks the names match).
PEERS_ENV = "DREM_LIVE_VIDEO_PEERS"
PEER_LISTEN_ENV = "DREM_LIVE_VIDEO_PEER_LISTEN"
PEER_SECRET_ENV = "DREM_LIVE_VIDEO_PEER_SECRET"
# chalicelib.live_wake reads these (tests/infra/test_live_pages.py checks the names match).
WAKE_PATH = "/live/wake"
WAKE_SECRET_ENV = "DREM_LIVE_WAKE_SECRET"


class LivePages(Construct):
    """The live-page service of one stage. `environment` is the app's (the same DREM_* settings the functions get);
    `tables` the stack's tables by logical name (the task role may read only those in permissions.LIVE_TABLE_ACTIONS);
    `wake_secret` the one the writer's wake-ups carry (the stack gives the functions the same).
    Context `live_max_tasks` raises the autoscaling ceiling (`make deploy LIVE_MAX_TASKS=8`)."""

    def __init__(self, scope: Construct, construct_id: str, *, stage: str, environment: Mapping[str, str],
                 tables: Mapping[str, dynamodb.Table], wake_secret: secretsmanager.ISecret) -> None:
        super().__init__(scope, construct_id)
        stack = cdk.Stack.of(self)
        self.vpc = ec2.Vpc(
            self, "Vpc", max_azs=2, nat_gateways=0,
            subnet_configuration=[
                ec2.SubnetConfiguration(name="public", subnet_type=ec2.SubnetType.PUBLIC, cidr_mask=24),
                # No route to the internet at all: a VPC origin must be in a private subnet (it costs nothing).
                ec2.SubnetConfiguration(name=ORIGIN_SUBNETS, subnet_type=ec2.SubnetType.PRIVATE_ISOLATED,
                                        cidr_mask=24)])
        self.log_group = logs.LogGroup(self, "Logs", retention=LOG_RETENTION, removal_policy=cdk.RemovalPolicy.DESTROY)
        self.task_role = self._task_role(tables)
        task = ecs.FargateTaskDefinition(
            self, "Task", cpu=TASK_CPU, memory_limit_mib=TASK_MEMORY_MIB, task_role=self.task_role,
            runtime_platform=ecs.RuntimePlatform(cpu_architecture=ecs.CpuArchitecture.X86_64,
                                                 operating_system_family=ecs.OperatingSystemFamily.LINUX))
        self.peer_secret = secretsmanager.Secret(
            self, "PeerSecret", description=f"drem {stage}: live tasks' shared secret for the cars' frames",
            generate_secret_string=secretsmanager.SecretStringGenerator(exclude_punctuation=True, password_length=40))
        task.add_container(
            "Server",
            image=ecs.ContainerImage.from_asset(
                str(REPO_ROOT), file=DOCKERFILE, exclude=list(LIVE_IMAGE_FILES), ignore_mode=cdk.IgnoreMode.DOCKER,
                platform=ecr_assets.Platform.LINUX_AMD64),
            # Per-viewer stream caps count CloudFront's viewer address: behind the ALB every connection comes from
            # CloudFront. Only CloudFront reaches the ALB, and it sets this header itself.
            environment={**environment, "AWS_DEFAULT_REGION": stack.region,
                         "DREM_LIVE_CLIENT_ADDRESS_HEADER": VIEWER_ADDRESS_HEADER,
                         "DREM_LIVE_KEEPALIVE_S": str(SERVER_KEEPALIVE_SECONDS),
                         "DREM_LIVE_METRICS_NAMESPACE": STREAMS_METRIC_NAMESPACE, "DREM_LIVE_METRICS_STAGE": stage,
                         PEERS_ENV: f"{PEER_SERVICE_NAME}.{PEER_NAMESPACE}:{PEER_PORT}",
                         PEER_LISTEN_ENV: f"0.0.0.0:{PEER_PORT}"},
            secrets={PEER_SECRET_ENV: ecs.Secret.from_secrets_manager(self.peer_secret),
                     WAKE_SECRET_ENV: ecs.Secret.from_secrets_manager(wake_secret)},
            port_mappings=[ecs.PortMapping(container_port=CONTAINER_PORT), ecs.PortMapping(container_port=PEER_PORT)],
            logging=ecs.LogDrivers.aws_logs(stream_prefix="live", log_group=self.log_group),
        )
        # The cluster, the public subnets and the load balancer's listener are shared with the learning booth's task
        # (drem_infra.booth_service), when the stage has one.
        self.cluster = ecs.Cluster(self, "Cluster", vpc=self.vpc)
        self.peer_namespace = servicediscovery.PrivateDnsNamespace(
            self, "PeerNamespace", name=PEER_NAMESPACE, vpc=self.vpc,
            description=f"drem {stage}: the live tasks find each other to share the cars' cameras")
        self.public_subnets = ec2.SubnetSelection(subnet_type=ec2.SubnetType.PUBLIC)
        self.service = ecs.FargateService(
            self, "Service", cluster=self.cluster, task_definition=task, desired_count=MIN_TASKS,
            assign_public_ip=True, vpc_subnets=self.public_subnets,
            min_healthy_percent=100, max_healthy_percent=200, circuit_breaker=ecs.DeploymentCircuitBreaker(
                rollback=True),
            cloud_map_options=ecs.CloudMapOptions(
                cloud_map_namespace=self.peer_namespace, name=PEER_SERVICE_NAME,
                dns_record_type=servicediscovery.DnsRecordType.A, dns_ttl=PEER_DNS_TTL))
        self.service.connections.allow_internally(ec2.Port.tcp(PEER_PORT), "live tasks share the cars' cameras")
        max_tasks = int(self.node.try_get_context("live_max_tasks") or MAX_TASKS)
        scaling = self.service.auto_scale_task_count(min_capacity=MIN_TASKS, max_capacity=max(MIN_TASKS, max_tasks))
        scaling.scale_on_cpu_utilization("Cpu", target_utilization_percent=CPU_TARGET_PERCENT)
        # Each task's open streams, averaged over the tasks (drem_live.metrics writes one figure a minute per task).
        self.streams_metric = cloudwatch.Metric(
            namespace=STREAMS_METRIC_NAMESPACE, metric_name=STREAMS_METRIC_NAME, dimensions_map={"Stage": stage},
            statistic="Average", period=cdk.Duration.minutes(1))
        scaling.scale_to_track_custom_metric("Streams", metric=self.streams_metric,
                                             target_value=STREAMS_TARGET_PER_TASK)
        self.origin_secret = secretsmanager.Secret(
            self, "OriginSecret", description=f"drem {stage}: the header CloudFront adds for the live load balancer",
            generate_secret_string=secretsmanager.SecretStringGenerator(exclude_punctuation=True, password_length=40))

        self.alb_security_group = ec2.SecurityGroup(
            self, "LoadBalancerSecurityGroup", vpc=self.vpc, allow_all_outbound=False,
            description=f"drem {stage} live pages: HTTP from the CloudFront VPC origin only")
        # CloudFront's VPC-origin interfaces sit in this VPC's subnets (security group CloudFront-VPCOrigins-Service-SG,
        # which exists only once the VPC origin does): the VPC's own range admits them, and nothing outside the VPC
        # can reach an internal load balancer anyway.
        self.alb_security_group.add_ingress_rule(ec2.Peer.ipv4(self.vpc.vpc_cidr_block), ec2.Port.tcp(80),
                                                 "CloudFront VPC origin (interfaces inside this VPC)")
        self.load_balancer = elbv2.ApplicationLoadBalancer(
            self, "LoadBalancer", vpc=self.vpc, internet_facing=False, security_group=self.alb_security_group,
            idle_timeout=ALB_IDLE_TIMEOUT, vpc_subnets=ec2.SubnetSelection(subnet_group_name=ORIGIN_SUBNETS))
        self.listener = self.load_balancer.add_listener(
            "Http", port=80, open=False, default_action=elbv2.ListenerAction.fixed_response(
                403, content_type="text/plain", message_body="Only drem's CloudFront distribution reaches this."))
        self.target_group = self.listener.add_targets(
            "Server", port=CONTAINER_PORT, protocol=elbv2.ApplicationProtocol.HTTP, targets=[self.service],
            priority=LIVE_RULE_PRIORITY, conditions=[self.from_cloudfront(), elbv2.ListenerCondition.path_patterns(
                [PATH_PATTERN])],
            deregistration_delay=DEREGISTRATION_DELAY,
            health_check=elbv2.HealthCheck(path=HEALTH_PATH, healthy_http_codes="200",
                                           interval=cdk.Duration.seconds(15), timeout=cdk.Duration.seconds(5),
                                           healthy_threshold_count=2, unhealthy_threshold_count=3))
        self._alarms(stage)

    def from_cloudfront(self) -> elbv2.ListenerCondition:
        """The condition every listener rule carries: the request has this stage's origin secret."""
        return elbv2.ListenerCondition.http_header(ORIGIN_SECRET_HEADER, [self.origin_secret_value()])

    def origin_secret_value(self) -> str:
        # A CloudFormation dynamic reference, resolved at deploy time: the value is in no template or output.
        return self.origin_secret.secret_value.unsafe_unwrap()

    def _task_role(self, tables: Mapping[str, dynamodb.Table]) -> iam.Role:
        """Only the reads the live server makes, only on the tables it reads (tests/infra/test_iam_policy.py)."""
        statements = [iam.PolicyStatement(actions=list(actions), resources=[tables[logical].table_arn])
                      for logical, actions in permissions.LIVE_TABLE_ACTIONS.items()]
        return iam.Role(self, "TaskRole", assumed_by=iam.ServicePrincipal("ecs-tasks.amazonaws.com"),
                        description="drem live pages: read the materialised boards, overlays, events and races",
                        inline_policies={"DremLiveReads": iam.PolicyDocument(statements=statements)})

    def _alarms(self, stage: str) -> None:
        """A task failing its health checks, and 5xx answers from the server or the load balancer itself."""
        five_minutes = cdk.Duration.minutes(5)
        unhealthy = self.target_group.metrics.unhealthy_host_count(period=cdk.Duration.minutes(1), statistic="Maximum")
        unhealthy.create_alarm(self, "UnhealthyHostsAlarm", threshold=1, evaluation_periods=3,
                               comparison_operator=cloudwatch.ComparisonOperator.GREATER_THAN_OR_EQUAL_TO_THRESHOLD,
                               alarm_description=f"drem {stage}: a live-page task fails its health check",
                               treat_missing_data=cloudwatch.TreatMissingData.NOT_BREACHING)
        server_5xx = self.target_group.metrics.http_code_target(elbv2.HttpCodeTarget.TARGET_5XX_COUNT,
                                                                period=five_minutes, statistic="Sum")
        alb_5xx = self.load_balancer.metrics.http_code_elb(elbv2.HttpCodeElb.ELB_5XX_COUNT, period=five_minutes,
                                                           statistic="Sum")
        for name, metric in (("Server5xxAlarm", server_5xx), ("LoadBalancer5xxAlarm", alb_5xx)):
            metric.create_alarm(self, name, threshold=5, evaluation_periods=1,
                                comparison_operator=cloudwatch.ComparisonOperator.GREATER_THAN_OR_EQUAL_TO_THRESHOLD,
                                alarm_description=f"drem {stage}: live pages answered 5xx in 5 minutes",
                                treat_missing_data=cloudwatch.TreatMissingData.NOT_BREACHING)

    def serve_through(self, distribution: cloudfront.Distribution) -> None:
        """Add the `/live/*` behaviour to the app's distribution.

        Why CachingDisabled + an all-viewer-headers origin request policy: a cache policy that enables gzip/brotli
        (which is what makes CloudFront normalise and forward Accept-Encoding) is rejected when its TTLs are all 0,
        and with a non-zero TTL identical stream URLs would be cacheable and subject to request collapsing; an
        origin request policy may not name Accept-Encoding in an allow-list (CloudFront rejects it; CDK refuses it
        too). With both compression flags off, CloudFront "treats the Accept-Encoding header the same as any other
        HTTP header in the viewer request" (CloudFront API reference, ParametersInCacheKeyAndForwardedToOrigin), so a
        policy forwarding all viewer headers passes the viewer's own Accept-Encoding to the server, and the server's
        gzip passes back untouched (`compress=False`: CloudFront compresses nothing itself)."""
        # A VPC origin: CloudFront reaches the internal load balancer over AWS's network, never the internet (HTTP
        # on that hop, as AWS's VPC-origin setup for a load balancer without a certificate of its own).
        self.origin = origins.VpcOrigin.with_application_load_balancer(
            self.load_balancer, protocol_policy=cloudfront.OriginProtocolPolicy.HTTP_ONLY, http_port=80,
            read_timeout=ORIGIN_READ_TIMEOUT, keepalive_timeout=ORIGIN_KEEPALIVE_TIMEOUT,
            custom_headers={ORIGIN_SECRET_HEADER: self.origin_secret_value()})
        policy = cloudfront.OriginRequestPolicy(
            self, "OriginRequestPolicy",
            comment="drem live pages: viewer headers (Accept-Encoding, Last-Event-ID, If-None-Match) and query",
            header_behavior=cloudfront.OriginRequestHeaderBehavior.all(VIEWER_ADDRESS_HEADER),
            query_string_behavior=cloudfront.OriginRequestQueryStringBehavior.all(),
            cookie_behavior=cloudfront.OriginRequestCookieBehavior.none())
        # More specific paths first (CloudFront takes the first behaviour that matches): a staff preview of a car's
        # camera carries the session cookies (and only those) for the server's staff check; a car's frames are POSTs.
        preview_policy = cloudfront.OriginRequestPolicy(
            self, "PreviewRequestPolicy", comment="drem live: a staff preview of a car's camera, with the session",
            header_behavior=cloudfront.OriginRequestHeaderBehavior.all(VIEWER_ADDRESS_HEADER),
            query_string_behavior=cloudfront.OriginRequestQueryStringBehavior.all(),
            cookie_behavior=cloudfront.OriginRequestCookieBehavior.allow_list(*SESSION_COOKIES))
        distribution.add_behavior(
            PREVIEW_PATH_PATTERN, self.origin,
            viewer_protocol_policy=cloudfront.ViewerProtocolPolicy.REDIRECT_TO_HTTPS,
            allowed_methods=cloudfront.AllowedMethods.ALLOW_GET_HEAD,
            cache_policy=cloudfront.CachePolicy.CACHING_DISABLED, origin_request_policy=preview_policy, compress=False)
        distribution.add_behavior(
            CAR_UPLOAD_PATH_PATTERN, self.origin,
            viewer_protocol_policy=cloudfront.ViewerProtocolPolicy.REDIRECT_TO_HTTPS,
            allowed_methods=cloudfront.AllowedMethods.ALLOW_ALL,
            cache_policy=cloudfront.CachePolicy.CACHING_DISABLED, origin_request_policy=policy, compress=False)
        # The writer's wake-ups: a POST, never cached, with every viewer header (the wake secret) passed on.
        distribution.add_behavior(
            WAKE_PATH, self.origin, viewer_protocol_policy=cloudfront.ViewerProtocolPolicy.HTTPS_ONLY,
            allowed_methods=cloudfront.AllowedMethods.ALLOW_ALL,
            cache_policy=cloudfront.CachePolicy.CACHING_DISABLED, origin_request_policy=policy, compress=False)
        distribution.add_behavior(
            PATH_PATTERN, self.origin, viewer_protocol_policy=cloudfront.ViewerProtocolPolicy.REDIRECT_TO_HTTPS,
            allowed_methods=cloudfront.AllowedMethods.ALLOW_GET_HEAD,
            cache_policy=cloudfront.CachePolicy.CACHING_DISABLED, origin_request_policy=policy, compress=False)
