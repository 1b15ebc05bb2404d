"""The AWS deployment of drem, built from `drem_infra.resources` (so AWS and the local stack cannot drift apart).

Importing this module needs aws-cdk-lib (the `infra` extra); `drem_infra.resources` does not, which is why this is
a separate module that nothing in the Lambda bundle imports. Synth makes no AWS calls.
"""
from __future__ import annotations

import contextlib
import json
import os
import re
import sys
from collections.abc import Iterator
from pathlib import Path

import aws_cdk as cdk
from aws_cdk import aws_apigateway as apigateway
from aws_cdk import aws_certificatemanager as acm
from aws_cdk import aws_cloudfront as cloudfront
from aws_cdk import aws_cloudfront_origins as origins
from aws_cdk import aws_cloudwatch as cloudwatch
from aws_cdk import aws_cloudwatch_actions as cloudwatch_actions
from aws_cdk import aws_cognito as cognito
from aws_cdk import aws_dynamodb as dynamodb
from aws_cdk import aws_events as events
from aws_cdk import aws_events_targets as targets
from aws_cdk import aws_iam as iam
from aws_cdk import aws_lambda as lambda_
from aws_cdk import aws_logs as logs
from aws_cdk import aws_s3 as s3
from aws_cdk import aws_secretsmanager as secretsmanager
from aws_cdk import aws_sns as sns
from aws_cdk import aws_sns_subscriptions as sns_subscriptions
from aws_cdk import aws_ssm as ssm
from constructs import Construct

from drem_infra import permissions, resources
from drem_infra.booth_service import BoothService
from drem_infra.live_pages import WAKE_SECRET_ENV, LivePages
from drem_infra.resources import BucketSpec, TableSpec

# How long the functions' logs are kept (CloudWatch keeps them forever, and bills for them, unless told otherwise).
LOG_RETENTION = logs.RetentionDays.ONE_MONTH
# API Gateway stage throttling: well above an event's staff and timer traffic, far below the regional default
# (10,000 rps), so a runaway client cannot take the account's whole API quota.
API_RATE_LIMIT_RPS = 200
API_BURST_LIMIT = 400
# The public pages' polling fallback (and the JSON polls): at most this, per route, whatever the crowd.
PUBLIC_POLL_PATHS = ("/leaderboard/{event_id}/live", "/overlay/{event_id}/live", "/api/leaderboard/{event_id}",
                     "/api/overlay/{event_id}")
PUBLIC_POLL_RATE_LIMIT_RPS = 50
PUBLIC_POLL_BURST_LIMIT = 100
# API Gateway gives up on an integration after 29 s: a function must finish (or fail with its own message) before.
API_FUNCTION_TIMEOUT_S = 28
# The upload checker (the models bucket's EventBridge rule) may use at most this many instances, and always has them,
# so a burst of uploads never takes the API's concurrency (`-c upload_concurrency=0` leaves it unreserved: needed on a
# new account whose concurrency quota is below 100 + this).
UPLOAD_RESERVED_CONCURRENCY = 2
# Alarms on the API stage (AWS/ApiGateway, per ApiName and Stage), each over 5 minutes. API Gateway has no throttle
# metric: a request over the limits above is answered 429 and counted in 4XXError, together with the app's own 4xx
# (401 after a session expires, 403, 404 for a mistyped address, 400/422 for a form error), of which ordinary use
# makes a few a minute. 300 in 5 minutes is one a second on average: throttling at API_RATE_LIMIT_RPS rejects
# requests by the hundred each second, so a few seconds of it cross the line, and a day of ordinary mistakes never
# does (a client or scanner hammering the API with rejected requests does, which deserves a look too).
API_4XX_PER_5_MINUTES = 300
# The app answers 5xx only when something is broken: an unhandled exception (Chalice turns it into a 500 that the
# Lambda Errors alarm does not see), a function crash or timeout (502/504), API Gateway failing to invoke it. One is
# in the logs; five in 5 minutes means a page or a device keeps failing (the live pages' 5xx alarms use 5 as well).
API_5XX_PER_5_MINUTES = 5
# `make deploy ALARM_EMAIL=ops@example.org`: one address subscribed to the stage's alarm topic.
_PLAIN_EMAIL_ADDRESS = re.compile(r"^[^@\s<>,;]+@[^@\s<>,;]+\.[^@\s<>,;]+$")
# The header the app reads its base path from (chalicelib.base_path.FORWARDED_PREFIX_HEADER).
FORWARDED_PREFIX_HEADER = "X-Forwarded-Prefix"
# The app's security headers (chalicelib.security_headers) on the one answer API Gateway gives by itself.
# `make deploy SES_FROM=... SES_IDENTITY_ARN=...`: an SES identity (an address or its domain) verified in SES.
_SES_IDENTITY_ARN = re.compile(r"^arn:aws[a-z-]*:ses:[a-z0-9-]+:\d{12}:identity/[^\s/]+$")
_EMAIL_ADDRESS = re.compile(r"^(?:[^<>]*<)?[^@\s<>]+@[^@\s<>]+\.[^@\s<>]+>?$")
# Shown by `cdk deploy` (so by `make deploy`) when racers sign up themselves and Cognito's own sender is used.
DEFAULT_SENDER_WARNING = (
    "Self sign-up emails a confirmation code, and Cognito's default sender allows only about 50 emails a day: "
    "set SES_FROM and SES_IDENTITY_ARN to send through Amazon SES (docs/deploy.md, Email).")
NOT_FOUND_HEADERS = {"Content-Security-Policy": "default-src 'none'; frame-ancestors 'none'",
                     "X-Content-Type-Options": "nosniff", "X-Frame-Options": "DENY",
                     "Referrer-Policy": "same-origin", "Strict-Transport-Security": "max-age=31536000"}


class DremStack(cdk.Stack):
    """Tables, buckets and the user pool; with `functions_dir`, also the Chalice app wired to them, behind a
    CloudFront distribution (the public URL: CloudFront maps / to the API's stage and tells the app its base path).

    `public_url` is the URL people use (QR codes, activation commands, Secure cookies). CloudFront's own domain is
    only known after the first deploy, and the functions cannot reference the distribution that fronts their own
    API (a dependency cycle), so `make deploy` passes it in on a second deploy; with `domain_name` (and an ACM
    `certificate_arn` in us-east-1) it is known from the start.

    Every alarm notifies the stage's one SNS topic (output AlarmTopicArn); `alarm_email` subscribes an address."""

    def __init__(self, scope: Construct, construct_id: str, *, stage: str,
                 functions_dir: Path | None = None, public_url: str | None = None,
                 domain_name: str | None = None, certificate_arn: str | None = None,
                 ses_from: str | None = None, ses_identity_arn: str | None = None,
                 alarm_email: str | None = None, booth: bool = False,
                 upload_concurrency: int = UPLOAD_RESERVED_CONCURRENCY, **kwargs) -> None:
        super().__init__(scope, construct_id, **kwargs)
        self.stage = stage
        self.with_booth = booth
        # Every alarm of the stage notifies this one topic (see _notify_on_every_alarm).
        self.alarm_topic = self._alarm_topic(alarm_email)
        self.ses_from, self.ses_identity_arn = ses_from, ses_identity_arn
        self.domain_name = domain_name
        self.upload_concurrency = upload_concurrency
        self.public_url = public_url or (f"https://{domain_name}" if domain_name else None)
        self.tables = {spec.logical: self._table(spec) for spec in resources.TABLES}
        self.buckets = {spec.logical: self._bucket(spec) for spec in resources.BUCKETS}
        self.user_pool, self.user_pool_client = self._user_pool()
        # The writer (the functions) wakes the live tasks through CloudFront with this secret (drem_infra.live_pages).
        self.live_wake_secret = self._live_wake_secret() if functions_dir is not None else None
        self.app = self._chalice_app(functions_dir) if functions_dir is not None else None
        self.distribution = self._distribution(certificate_arn) if self.app is not None else None
        if self.distribution is not None:
            self._public_url_parameter(self.distribution)
        # The live pages' push server (Fargate behind an ALB) at /live/* of the same distribution (same origin).
        self.live = (LivePages(self, "Live", stage=stage, environment=self.app_environment(), tables=self.tables,
                               wake_secret=self.live_wake_secret)
                     if self.distribution is not None and self.live_wake_secret is not None else None)
        if self.live is not None and self.distribution is not None:
            self.live.serve_through(self.distribution)
        # The learning booth (drives, training) in a container beside the live pages: opt-in, it costs by the hour.
        booth_environment = self.app_environment(public_url_parameter=True)
        self.booth = (BoothService(self, "Booth", stage=stage, environment=booth_environment, live=self.live,
                                   tables=self.tables, buckets=self.buckets, user_pool=self.user_pool)
                      if self.with_booth and self.live is not None else None)
        if self.booth is not None and self.live is not None and self.distribution is not None:
            self.booth.serve_through(self.distribution, self.live)
        self._notify_on_every_alarm()
        self._outputs()

    # --- storage ------------------------------------------------------------------------------------------------

    def _table(self, spec: TableSpec) -> dynamodb.Table:
        def key(name: str) -> dynamodb.Attribute:
            return dynamodb.Attribute(name=name, type=dynamodb.AttributeType.STRING)

        table = dynamodb.Table(
            self, f"{spec.logical.capitalize()}Table",
            # No table_name: CloudFormation names it after the stack (drem-{stage}-...) plus a unique suffix, so a
            # table retained by `make destroy` never collides with the next deploy. The app gets the name through
            # DREM_TABLE_<LOGICAL>, the CLI through the stack outputs.
            partition_key=key(spec.pk),
            sort_key=key(spec.sk),
            billing_mode=dynamodb.BillingMode.PAY_PER_REQUEST,
            stream=dynamodb.StreamViewType.NEW_AND_OLD_IMAGES if spec.stream else None,
            point_in_time_recovery_specification=dynamodb.PointInTimeRecoverySpecification(
                point_in_time_recovery_enabled=True),
            removal_policy=cdk.RemovalPolicy.RETAIN,
        )
        for gsi in spec.gsis:
            table.add_global_secondary_index(index_name=gsi.name, partition_key=key(gsi.pk), sort_key=key(gsi.sk),
                                             projection_type=dynamodb.ProjectionType.ALL)
        return table

    def _bucket(self, spec: BucketSpec) -> s3.Bucket:
        cors = resources.BROWSER_UPLOAD_CORS
        return s3.Bucket(
            self, f"{spec.logical.capitalize()}Bucket",
            # No bucket_name: S3 names are global, so CloudFormation picks a unique one and the app gets it
            # through DREM_BUCKET_<LOGICAL>.
            block_public_access=s3.BlockPublicAccess.BLOCK_ALL,
            enforce_ssl=True,
            encryption=s3.BucketEncryption.S3_MANAGED,
            cors=[s3.CorsRule(
                allowed_origins=list(cors.allowed_origins),
                allowed_methods=[s3.HttpMethods(m) for m in cors.allowed_methods],
                allowed_headers=list(cors.allowed_headers),
                exposed_headers=list(cors.expose_headers),
                max_age=cors.max_age_seconds,
            )] if spec.cors else None,
            event_bridge_enabled=spec.eventbridge,
            removal_policy=cdk.RemovalPolicy.RETAIN,
        )

    # --- identity -----------------------------------------------------------------------------------------------

    def _user_pool(self) -> tuple[cognito.UserPool, cognito.UserPoolClient]:
        spec = resources.USER_POOL
        policy = spec.password_policy
        pool = cognito.UserPool(
            self, "UserPool",
            user_pool_name=resources.user_pool_name(self.stage),
            self_sign_up_enabled=spec.self_sign_up,
            sign_in_aliases=cognito.SignInAliases(username=True),
            sign_in_case_sensitive=False,
            auto_verify=cognito.AutoVerifiedAttrs(email="email" in spec.auto_verified_attributes),
            standard_attributes=cognito.StandardAttributes(
                email=cognito.StandardAttribute(required="email" in spec.required_attributes, mutable=True)),
            custom_attributes={a.name: cognito.StringAttribute(mutable=a.mutable) for a in spec.custom_attributes},
            password_policy=cognito.PasswordPolicy(
                min_length=policy.minimum_length,
                require_lowercase=policy.require_lowercase,
                require_uppercase=policy.require_uppercase,
                require_digits=policy.require_digits,
                require_symbols=policy.require_symbols,
                temp_password_validity=cdk.Duration.days(policy.temporary_password_validity_days),
            ),
            account_recovery=cognito.AccountRecovery.EMAIL_ONLY,
            removal_policy=cdk.RemovalPolicy.RETAIN,
        )
        self._email_sender(pool, spec.self_sign_up)
        client = pool.add_client(
            "WebClient",
            user_pool_client_name=resources.client_name(self.stage),
            generate_secret=spec.generate_secret,
            # The app signs users in with the API flows (USER_PASSWORD_AUTH, refresh) and serves its own pages; it
            # uses no hosted UI, so no OAuth flows, scopes or callback URLs (CDK's default enables the implicit
            # grant with https://example.com).
            disable_o_auth=True,
            prevent_user_existence_errors=True,
        )
        # Set the Cognito names verbatim so the template says exactly what resources.py says.
        cfn_client = client.node.default_child
        cfn_client.add_property_override("ExplicitAuthFlows", list(spec.explicit_auth_flows))
        cfn_client.add_property_override("ReadAttributes", list(spec.read_attributes))
        cfn_client.add_property_override("WriteAttributes", list(spec.write_attributes))
        for group in spec.groups:
            cognito.CfnUserPoolGroup(self, f"{group.capitalize()}Group", user_pool_id=pool.user_pool_id,
                                     group_name=group)
        return pool, client

    def _email_sender(self, pool: cognito.UserPool, self_sign_up: bool) -> None:
        """Through Amazon SES when given a verified identity (DEVELOPER: Cognito sends with the account's SES quota,
        through its service-linked role); otherwise Cognito's default sender, with a warning if racers sign up."""
        if not self.ses_from and not self.ses_identity_arn:
            if self_sign_up:
                cdk.Annotations.of(pool).add_warning_v2("drem:email-default-sender", DEFAULT_SENDER_WARNING)
            return
        if not self.ses_from or not self.ses_identity_arn:
            raise ValueError("SES_FROM and SES_IDENTITY_ARN go together: the sender address and the ARN of its "
                             "verified SES identity (arn:aws:ses:REGION:ACCOUNT:identity/ADDRESS-OR-DOMAIN)")
        if not _EMAIL_ADDRESS.match(self.ses_from):
            raise ValueError(f"SES_FROM={self.ses_from!r} is not an email address (drem@example.org, or "
                             "'drem <drem@example.org>')")
        if not _SES_IDENTITY_ARN.match(self.ses_identity_arn):
            raise ValueError(f"SES_IDENTITY_ARN={self.ses_identity_arn!r} is not an SES identity ARN "
                             "(arn:aws:ses:REGION:ACCOUNT:identity/ADDRESS-OR-DOMAIN)")
        pool.node.default_child.add_property_override("EmailConfiguration", {
            "EmailSendingAccount": "DEVELOPER", "From": self.ses_from, "SourceArn": self.ses_identity_arn})

    # --- alarms -------------------------------------------------------------------------------------------------

    def _alarm_topic(self, alarm_email: str | None) -> sns.Topic:
        """The stage's alarm topic, with `alarm_email` subscribed (AWS mails it a link to confirm first). No topic
        policy: SNS's default one lets this account's CloudWatch alarms publish, and a KMS-encrypted topic would need a
        key policy for CloudWatch, so it stays unencrypted (it carries alarm names and states, no event data)."""
        topic = sns.Topic(self, "AlarmTopic", display_name=f"drem {self.stage} alarms")
        if alarm_email:
            if not _PLAIN_EMAIL_ADDRESS.match(alarm_email):
                raise ValueError(f"ALARM_EMAIL={alarm_email!r} is not an email address (one address, e.g. "
                                 "ops@example.org)")
            topic.add_subscription(sns_subscriptions.EmailSubscription(alarm_email))
        return topic

    def _notify_on_every_alarm(self) -> None:
        """Every CloudWatch alarm in the stack, whichever construct made it (the functions', the API's, the live
        pages'), notifies the alarm topic when it goes off and when it clears."""
        action = cloudwatch_actions.SnsAction(self.alarm_topic)
        for construct in self.node.find_all():
            if isinstance(construct, cloudwatch.Alarm):
                construct.add_alarm_action(action)
                construct.add_ok_action(action)

    # --- application --------------------------------------------------------------------------------------------

    def app_environment(self, *, public_url_parameter: bool = False) -> dict[str, str]:
        """The app's settings. `public_url_parameter`: without a URL known at synth, name the stack's SSM parameter
        the app then reads it from at run time (the functions and the booth, whose roles may read it): the same on
        every deploy, so no deploy ever serves the local fallback URL (docs/deploy.md)."""
        env = resources.stage_environment(
            self.stage, self.user_pool.user_pool_id, self.user_pool_client.user_pool_client_id,
            {logical: t.table_name for logical, t in self.tables.items()},
            {logical: b.bucket_name for logical, b in self.buckets.items()},
        )
        if self.public_url:
            env["DREM_PUBLIC_URL"] = self.public_url
        elif public_url_parameter:
            env["DREM_PUBLIC_URL_PARAMETER"] = resources.public_url_parameter(self.stage)
        # The live pages' EventSource base: empty means the page's own origin (CloudFront routes /live/* to them).
        env["DREM_LIVE_URL"] = ""
        if self.with_booth:  # its task runs the scrutineering worker, so the functions queue new models for it
            env[resources.SCRUTINEERING_WORKER_ENV] = "1"
        # A car's long poll runs in one Lambda and staff's assignment in another, which cannot wake it: the poll's
        # storage re-read is all there is, so it runs every second (one GetItem per waiting car per second).
        env[resources.ASSIGNMENT_RECHECK_ENV] = "1"
        return env

    def _live_wake_secret(self) -> secretsmanager.Secret:
        return secretsmanager.Secret(
            self, "LiveWakeSecret", description=f"drem {self.stage}: the writer's wake-up of the live pages' tasks",
            generate_secret_string=secretsmanager.SecretStringGenerator(exclude_punctuation=True, password_length=40))

    def _writer_wakes_the_live_pages(self, env: dict[str, str]) -> dict[str, str]:
        """The functions POST each changed event to the public origin's /live/wake with the wake secret
        (chalicelib.live_wake_http): a CloudFormation dynamic reference, resolved at deploy time (the same pattern as
        the origin secret). Whoever can read the functions' configuration can read the tables too, and the secret
        only makes the live server re-read public data (at most once per wake window per channel)."""
        assert self.live_wake_secret is not None
        return {**env, WAKE_SECRET_ENV: self.live_wake_secret.secret_value.unsafe_unwrap()}

    def _public_url_parameter(self, distribution: cloudfront.Distribution) -> ssm.StringParameter:
        """The public URL where the functions read it at run time (CloudFront's domain is known only now)."""
        return ssm.StringParameter(
            self, "PublicUrlParameter", parameter_name=resources.public_url_parameter(self.stage),
            string_value=self.public_url or f"https://{distribution.distribution_domain_name}",
            description=f"drem {self.stage}: the URL people use (QR codes, links, Secure cookies)")

    def _distribution(self, certificate_arn: str | None) -> cloudfront.Distribution:
        """Everything through CloudFront: /static/* cached at the edge, the rest passed to the API uncached (with
        cookies, query strings and headers, but not the viewer's Host, which API Gateway must see as its own)."""
        assert self.app is not None  # a distribution is made only with the app
        api_domain = f"{self.app.get_resource('RestAPI').ref}.execute-api.{self.region}.{self.url_suffix}"
        # The site is at CloudFront's root: X-Forwarded-Prefix "/" tells the app not to put the stage ("/api") in its
        # links (chalicelib.base_path). CloudFront overwrites a viewer's header of that name with this one
        # (CloudFront Developer Guide, "Add custom headers to origin requests").
        api = origins.HttpOrigin(api_domain, origin_path="/api", custom_headers={FORWARDED_PREFIX_HEADER: "/"},
                                 protocol_policy=cloudfront.OriginProtocolPolicy.HTTPS_ONLY)
        certificate = (acm.Certificate.from_certificate_arn(self, "Certificate", certificate_arn)
                       if certificate_arn else None)
        additional_behaviors = {"/static/*": cloudfront.BehaviorOptions(
            origin=api,
            viewer_protocol_policy=cloudfront.ViewerProtocolPolicy.REDIRECT_TO_HTTPS,
            cache_policy=cloudfront.CachePolicy.CACHING_OPTIMIZED,
        ), "/event/*/logo": self._logo_behavior(api_domain)}  # chalicelib/routes/event_logos.py
        return cloudfront.Distribution(
            self, "Distribution",
            comment=f"drem {self.stage}",
            default_behavior=cloudfront.BehaviorOptions(
                origin=api,
                viewer_protocol_policy=cloudfront.ViewerProtocolPolicy.REDIRECT_TO_HTTPS,
                allowed_methods=cloudfront.AllowedMethods.ALLOW_ALL,
                cache_policy=cloudfront.CachePolicy.CACHING_DISABLED,
                origin_request_policy=cloudfront.OriginRequestPolicy.ALL_VIEWER_EXCEPT_HOST_HEADER,
            ),
            additional_behaviors=additional_behaviors,
            domain_names=[self.domain_name] if self.domain_name and certificate else None,
            certificate=certificate,
            price_class=cloudfront.PriceClass.PRICE_CLASS_100,
            http_version=cloudfront.HttpVersion.HTTP2_AND_3,
        )

    def _logo_behavior(self, api_domain: str) -> cloudfront.BehaviorOptions:
        """An event's logo, cached at the edge by its ?v= (the pages link the current version, so a new logo is a new
        URL); nothing of the viewer's reaches the app, which answers every viewer the same bytes."""
        # Chalice refuses a binary answer (400) unless the request's Accept matches a binary type, and a cache policy
        # forwards no viewer header: this origin always asks with Accept */* (CloudFront overwrites a viewer's header
        # of a custom header's name: CloudFront Developer Guide, "Add custom headers to origin requests").
        origin = origins.HttpOrigin(api_domain, origin_path="/api",
                                    custom_headers={FORWARDED_PREFIX_HEADER: "/", "Accept": "*/*"},
                                    protocol_policy=cloudfront.OriginProtocolPolicy.HTTPS_ONLY)
        cache_policy = cloudfront.CachePolicy(
            self, "LogoCachePolicy",
            comment=f"drem {self.stage} event logos: keyed by version only",
            query_string_behavior=cloudfront.CacheQueryStringBehavior.allow_list("v"),
            header_behavior=cloudfront.CacheHeaderBehavior.none(),
            cookie_behavior=cloudfront.CacheCookieBehavior.none(),
            min_ttl=cdk.Duration.seconds(0), default_ttl=cdk.Duration.days(1), max_ttl=cdk.Duration.days(365),
        )
        return cloudfront.BehaviorOptions(origin=origin, cache_policy=cache_policy,
                                          viewer_protocol_policy=cloudfront.ViewerProtocolPolicy.REDIRECT_TO_HTTPS)

    def _chalice_app(self, functions_dir: Path):
        # Imported here: packaging imports the app, which needs its runtime deps; the storage-only stack does not.
        from chalice.cdk import Chalice
        from chalice.utils import to_cfn_resource_name

        env = self._writer_wakes_the_live_pages(self.app_environment(public_url_parameter=True))
        with _packaging_leaves_no_trace():
            app = Chalice(self, "App", source_dir=str(functions_dir),
                          stage_config={"environment_variables": env, "lambda_timeout": API_FUNCTION_TIMEOUT_S})
        self._unknown_paths_are_not_found(app)
        sam = json.loads(Path(app._sam_package_dir, "sam.json").read_text())  # the template Chalice just wrote
        functions = [name for name, r in sam["Resources"].items() if r["Type"] == "AWS::Serverless::Function"]
        log_groups = self._log_groups(app, functions)
        self._least_privilege(app, log_groups)
        self._alarms(app, functions)
        api = sam["Resources"].get("RestAPI")
        if api is not None:
            rest_api = app.get_resource("RestAPI")
            # API Gateway applies a stage's throttle to each method on its own ("per-API, per-stage throttling limits
            # are applied at the API method level", API Gateway developer guide, "Throttle requests to your REST
            # APIs"): timers and staff never share a bucket with spectators. The spectators' polling fallback gets
            # a smaller budget of its own, so phones refused by the live server cannot hold the functions'
            # concurrency that timers and staff need.
            rest_api.add_property_override("MethodSettings", [{
                "ResourcePath": "/*", "HttpMethod": "*",
                "ThrottlingRateLimit": API_RATE_LIMIT_RPS, "ThrottlingBurstLimit": API_BURST_LIMIT},
                *({"ResourcePath": _method_setting_path(path), "HttpMethod": "GET",
                   "ThrottlingRateLimit": PUBLIC_POLL_RATE_LIMIT_RPS, "ThrottlingBurstLimit": PUBLIC_POLL_BURST_LIMIT}
                  for path in PUBLIC_POLL_PATHS)])
            # API Gateway's metrics name a REST API by its name, which Chalice leaves at the app's ("drem") for every
            # stage: a stage-scoped name keeps two stages of one account apart in the API alarms.
            api_name = f"drem-{self.stage}"
            rest_api.add_property_override("Name", api_name)
            rest_api.add_property_override("DefinitionBody.info.title", api_name)
            # API Gateway decodes a base64 (binary) Lambda answer only when the viewer's *first* Accept type is one of
            # the API's binary media types, and a browser's first is text/html (a PDF link) or image/avif (an <img>):
            # "to return binary media when you can't control the order of Accept header values, such as requests
            # from a browser, set your API's binary media types to */*" (AWS API Gateway developer guide, "Binary
            # media types for REST APIs"). Which answers are binary stays the app's decision (app.api.binary_types:
            # Chalice base64-encodes only those); request bodies then all arrive base64-encoded, which Chalice's
            # Request.raw_body decodes.
            rest_api.add_property_override("DefinitionBody.x-amazon-apigateway-binary-media-types", ["*/*"])
            self._api_alarms(api_name, api["Properties"]["StageName"])
        upload_fn = to_cfn_resource_name(resources.UPLOAD_COMPLETE_FUNCTION)
        if upload_fn in sam["Resources"] and self.upload_concurrency > 0:
            app.get_resource(upload_fn).add_property_override("ReservedConcurrentExecutions",
                                                              self.upload_concurrency)
        if upload_fn in sam["Resources"]:
            for spec in resources.BUCKETS:
                if spec.eventbridge:
                    self._route_uploads(self.buckets[spec.logical], app.get_function(upload_fn))
        return app

    def _log_groups(self, app, functions: list[str]) -> list[logs.LogGroup]:
        """One log group per function, with retention; each function is told to log there."""
        groups = []
        for name in functions:
            group = logs.LogGroup(self, f"{name}Logs", retention=LOG_RETENTION,
                                  removal_policy=cdk.RemovalPolicy.DESTROY)
            app.get_resource(name).add_property_override("LoggingConfig", {"LogGroup": group.log_group_name})
            groups.append(group)
        return groups

    def _least_privilege(self, app, log_groups: list[logs.LogGroup]) -> None:
        """Replace Chalice's default role policy (logs on arn:*:logs:*:*:*) with exactly drem_infra.permissions."""
        tables = list(self.tables.values())
        statements = [
            iam.PolicyStatement(actions=list(permissions.LOG_ACTIONS),
                                resources=[f"{g.log_group_arn}" for g in log_groups]),
            iam.PolicyStatement(actions=list(permissions.TABLE_ACTIONS),
                                resources=[arn for t in tables for arn in (t.table_arn, f"{t.table_arn}/index/*")]),
            iam.PolicyStatement(actions=list(permissions.USER_POOL_ACTIONS), resources=[self.user_pool.user_pool_arn]),
        ]
        for logical, actions in permissions.BUCKET_OBJECT_ACTIONS.items():
            statements.append(iam.PolicyStatement(actions=list(actions),
                                                  resources=[self.buckets[logical].arn_for_objects("*")]))
        for logical, actions in permissions.BUCKET_ACTIONS.items():
            statements.append(iam.PolicyStatement(actions=list(actions), resources=[self.buckets[logical].bucket_arn]))
        statements.append(iam.PolicyStatement(actions=list(permissions.PARAMETER_ACTIONS), resources=[
            self.format_arn(service="ssm", resource="parameter",
                            resource_name=resources.public_url_parameter(self.stage).lstrip("/"))]))
        document = iam.PolicyDocument(statements=statements)
        app.get_resource("DefaultRole").add_property_override(
            "Policies", [{"PolicyName": "DremApp", "PolicyDocument": self.resolve(document.to_json())}])

    def _alarms(self, app, functions: list[str]) -> None:
        """Errors and throttles of every function, so a broken deploy or a quota problem reaches the alarm topic."""
        for name in functions:
            function_name = app.get_resource(name).ref
            for metric_name in ("Errors", "Throttles"):
                metric = cloudwatch.Metric(namespace="AWS/Lambda", metric_name=metric_name, statistic="Sum",
                                           period=cdk.Duration.minutes(5),
                                           dimensions_map={"FunctionName": function_name})
                metric.create_alarm(self, f"{name}{metric_name}Alarm", threshold=1, evaluation_periods=1,
                                    alarm_description=f"drem {self.stage}: {name} {metric_name.lower()} in 5 minutes",
                                    treat_missing_data=cloudwatch.TreatMissingData.NOT_BREACHING)

    def _api_alarms(self, api_name: str, stage_name: str) -> None:
        """Rejected requests (throttling shows here, as 429s) and server errors of the API stage."""
        for metric_name, threshold, what in (
                ("4XXError", API_4XX_PER_5_MINUTES, "requests rejected (4xx, throttled 429s among them)"),
                ("5XXError", API_5XX_PER_5_MINUTES, "server errors (5xx)")):
            metric = cloudwatch.Metric(namespace="AWS/ApiGateway", metric_name=metric_name, statistic="Sum",
                                       period=cdk.Duration.minutes(5),
                                       dimensions_map={"ApiName": api_name, "Stage": stage_name})
            metric.create_alarm(self, f"Api{metric_name[0]}xxAlarm", threshold=threshold, evaluation_periods=1,
                                comparison_operator=cloudwatch.ComparisonOperator.GREATER_THAN_OR_EQUAL_TO_THRESHOLD,
                                alarm_description=f"drem {self.stage}: {threshold} or more API {what} in 5 minutes",
                                treat_missing_data=cloudwatch.TreatMissingData.NOT_BREACHING)

    def _unknown_paths_are_not_found(self, app) -> None:  # noqa: ANN001 - chalice.cdk.Chalice
        """API Gateway answers a path no route matches with 403 "Missing Authentication Token"; make it the 404 it
        is (the local app server does the same through the app's own not-found routes)."""
        apigateway.CfnGatewayResponse(
            self, "UnknownPathIsNotFound", rest_api_id=app.get_resource("RestAPI").ref,
            response_type="MISSING_AUTHENTICATION_TOKEN", status_code="404",
            # API Gateway answers these before the app (and its security headers) runs: give them the same headers.
            response_parameters={f"gatewayresponse.header.{name}": f"'{value}'"
                                 for name, value in NOT_FOUND_HEADERS.items()},
            response_templates={
                "application/json": '{"error": {"code": "NotFound", "message": "There is no route at this path; '
                                    'GET /api/docs lists every route."}}',
                "text/html": "<!doctype html><title>Not found · drem</title><h1>Not found</h1>"
                             "<p>There is no page at this address. <a href=\"/\">Start page</a></p>"})

    def _route_uploads(self, bucket: s3.Bucket, function) -> None:
        rule = events.Rule(
            self, "UploadCompleteRule",
            description="A browser finished uploading a model archive: validate it.",
            event_pattern=events.EventPattern(
                source=["aws.s3"],
                detail_type=["Object Created"],
                detail={"bucket": {"name": [bucket.bucket_name]},
                        "object": {"key": [{"prefix": resources.UPLOADS_PREFIX}]}},
            ),
            targets=[targets.LambdaFunction(function)],
        )
        # The function is imported from Chalice's template, so CDK cannot add this permission by itself.
        lambda_.CfnPermission(self, "UploadCompleteInvokePermission", action="lambda:InvokeFunction",
                              function_name=function.function_arn, principal="events.amazonaws.com",
                              source_arn=rule.rule_arn)

    def _outputs(self) -> None:
        cdk.CfnOutput(self, "Stage", value=self.stage)
        cdk.CfnOutput(self, "Region", value=self.region)
        cdk.CfnOutput(self, "AlarmTopicArn", value=self.alarm_topic.topic_arn)
        if self.distribution is not None:
            cdk.CfnOutput(self, "DistributionUrl", value=f"https://{self.distribution.distribution_domain_name}")
            cdk.CfnOutput(self, "PublicUrl",
                          value=self.public_url or f"https://{self.distribution.distribution_domain_name}")
        cdk.CfnOutput(self, "UserPoolId", value=self.user_pool.user_pool_id)
        cdk.CfnOutput(self, "UserPoolClientId", value=self.user_pool_client.user_pool_client_id)
        for logical, table in self.tables.items():
            cdk.CfnOutput(self, f"{logical.capitalize()}TableName", value=table.table_name)
        for logical, bucket in self.buckets.items():
            cdk.CfnOutput(self, f"{logical.capitalize()}BucketName", value=bucket.bucket_name)


def _method_setting_path(path: str) -> str:
    """A resource path as a stage's MethodSettings names it: every "/" of the path written "~1", after a leading "/"
    (AWS::ApiGateway::Stage MethodSetting ResourcePath: "/resource/subresource" is "/~1resource~1subresource")."""
    return "/" + path.replace("/", "~1")


@contextlib.contextmanager
def _packaging_leaves_no_trace() -> Iterator[None]:
    """Chalice packages the app in-process: it imports `app`/`chalicelib` from the source dir and copies the stage's
    environment variables (CDK tokens here) into os.environ. Undo both, so a synth inside a longer-lived process (a
    test session, a notebook) does not leave it pointing at unresolved tokens or at the packaged copy of the app."""
    saved_env, saved_path = dict(os.environ), list(sys.path)
    # Modules already imported are set aside, so packaging imports its own copies: registering the app's blueprints
    # in another Chalice app consumes their route options (Chalice pops `methods` from each deferred registration),
    # and a later `import app` in this process would then register every route as GET.
    ours = lambda name: name == "app" or name.split(".")[0] == "chalicelib"  # noqa: E731
    saved_modules = {name: module for name, module in sys.modules.items() if ours(name)}
    for name in saved_modules:
        del sys.modules[name]
    try:
        yield
    finally:
        os.environ.clear()
        os.environ.update(saved_env)
        sys.path[:] = saved_path
        for name in [n for n in sys.modules if ours(n)]:
            del sys.modules[name]
        sys.modules.update(saved_modules)
