"""The AWS deployment of drem, built from `drem_infra.resources` (so AWS and the local stack cannot drift apart).

Importing this module needs aws-cdk-lib (the `infra` extra); `drem_infra.resources` does not, which is why this is
a separate module that nothing in the Lambda bundle imports. Synth makes no AWS calls.
"""
from __future__ import annotations

import contextlib
import json
import os
import sys
from collections.abc import Iterator
from pathlib import Path

import aws_cdk as cdk
from aws_cdk import aws_apigateway as apigateway
from aws_cdk import aws_cognito as cognito
from aws_cdk import aws_dynamodb as dynamodb
from aws_cdk import aws_events as events
from aws_cdk import aws_events_targets as targets
from aws_cdk import aws_iam as iam
from aws_cdk import aws_lambda as lambda_
from aws_cdk import aws_s3 as s3
from constructs import Construct

from drem_infra import resources
from drem_infra.resources import BucketSpec, TableSpec

# What the app does with Cognito itself: staff registration, role changes, user listing, self-delete.
_APP_COGNITO_ACTIONS = (
    "cognito-idp:AdminCreateUser",
    "cognito-idp:AdminDeleteUser",
    "cognito-idp:AdminGetUser",
    "cognito-idp:AdminAddUserToGroup",
    "cognito-idp:AdminRemoveUserFromGroup",
    "cognito-idp:AdminListGroupsForUser",
    "cognito-idp:AdminUpdateUserAttributes",
    "cognito-idp:ListUsers",
    "cognito-idp:ListUsersInGroup",
)


class DremStack(cdk.Stack):
    """Tables, buckets and the user pool; with `functions_dir`, also the Chalice app wired to them."""

    def __init__(self, scope: Construct, construct_id: str, *, stage: str,
                 functions_dir: Path | None = None, **kwargs) -> None:
        super().__init__(scope, construct_id, **kwargs)
        self.stage = stage
        self.tables = {spec.logical: self._table(spec) for spec in resources.TABLES}
        self.buckets = {spec.logical: self._bucket(spec) for spec in resources.BUCKETS}
        self.user_pool, self.user_pool_client = self._user_pool()
        self.app = self._chalice_app(functions_dir) if functions_dir is not None else None
        self._outputs()

    # --- storage ------------------------------------------------------------------------------------------------

    def _table(self, spec: TableSpec) -> dynamodb.Table:
        def key(name: str) -> dynamodb.Attribute:
            return dynamodb.Attribute(name=name, type=dynamodb.AttributeType.STRING)

        table = dynamodb.Table(
            self, f"{spec.logical.capitalize()}Table",
            # env={} so a developer's local DREM_TABLE_* overrides never leak into a deployment.
            table_name=resources.table_name(self.stage, spec.logical, env={}),
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
        client = pool.add_client(
            "WebClient",
            user_pool_client_name=resources.client_name(self.stage),
            generate_secret=spec.generate_secret,
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

    # --- application --------------------------------------------------------------------------------------------

    def app_environment(self) -> dict[str, str]:
        return resources.stage_environment(
            self.stage, self.user_pool.user_pool_id, self.user_pool_client.user_pool_client_id,
            {logical: t.table_name for logical, t in self.tables.items()},
            {logical: b.bucket_name for logical, b in self.buckets.items()},
        )

    def _chalice_app(self, functions_dir: Path):
        # Imported here: packaging imports the app, which needs its runtime deps; the storage-only stack does not.
        from chalice.cdk import Chalice
        from chalice.utils import to_cfn_resource_name

        with _packaging_leaves_no_trace():
            app = Chalice(self, "App", source_dir=str(functions_dir),
                          stage_config={"environment_variables": self.app_environment()})
        # By name (Ref of the role Chalice's template defines), so the grant policy attaches to it directly.
        role = iam.Role.from_role_name(self, "AppRole", app.get_resource("DefaultRole").ref)
        for table in self.tables.values():
            table.grant_read_write_data(role)
        for bucket in self.buckets.values():
            bucket.grant_read_write(role)
        self.user_pool.grant(role, *_APP_COGNITO_ACTIONS)

        self._unknown_paths_are_not_found(app)
        sam = json.loads(Path(app._sam_package_dir, "sam.json").read_text())  # the template Chalice just wrote
        upload_fn = to_cfn_resource_name(resources.UPLOAD_COMPLETE_FUNCTION)
        if upload_fn in sam["Resources"]:
            for spec in resources.BUCKETS:
                if spec.eventbridge:
                    self._route_uploads(self.buckets[spec.logical], app.get_function(upload_fn))
        return app

    def _unknown_paths_are_not_found(self, app) -> None:  # noqa: ANN001 - chalice.cdk.Chalice
        """API Gateway answers a path no route matches with 403 "Missing Authentication Token"; make it the 404 it
        is (the local app server does the same through the app's own not-found routes)."""
        apigateway.CfnGatewayResponse(
            self, "UnknownPathIsNotFound", rest_api_id=app.get_resource("RestAPI").ref,
            response_type="MISSING_AUTHENTICATION_TOKEN", status_code="404",
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
        cdk.CfnOutput(self, "UserPoolId", value=self.user_pool.user_pool_id)
        cdk.CfnOutput(self, "UserPoolClientId", value=self.user_pool_client.user_pool_client_id)
        for logical, table in self.tables.items():
            cdk.CfnOutput(self, f"{logical.capitalize()}TableName", value=table.table_name)
        for logical, bucket in self.buckets.items():
            cdk.CfnOutput(self, f"{logical.capitalize()}BucketName", value=bucket.bucket_name)


@contextlib.contextmanager
def _packaging_leaves_no_trace() -> Iterator[None]:
    """Chalice packages the app in-process: it imports `app`/`chalicelib` from the source dir and copies the stage's
    environment variables (CDK tokens here) into os.environ. Undo both, so a synth inside a longer-lived process (a
    test session, a notebook) does not leave it pointing at unresolved tokens or at the packaged copy of the app."""
    saved_env, saved_path = dict(os.environ), list(sys.path)
    saved_modules = {name for name in sys.modules if name == "app" or name.split(".")[0] == "chalicelib"}
    try:
        yield
    finally:
        os.environ.clear()
        os.environ.update(saved_env)
        sys.path[:] = saved_path
        for name in [n for n in sys.modules if (n == "app" or n.split(".")[0] == "chalicelib") and n not in saved_modules]:
            del sys.modules[name]
