"""The deployed role may make exactly the AWS calls the storage adapters make: derived from their source (every
boto3 operation name they use), checked against the synthesised role both ways. A call without a permission is a
502 under IAM on event day; a permission without a call is an attacker's head start."""
from __future__ import annotations

import ast
from pathlib import Path

import botocore.session
import pytest
from botocore import xform_name

from drem_infra import permissions, resources

pytestmark = pytest.mark.infra

STORAGE_DIR = Path(__file__).resolve().parents[2] / "functions" / "chalicelib" / "storage"
# Not callers: the CLI's adapter for `drem export/import --aws` (it runs with the operator's own credentials, never in
# Lambda) and the error translator, which lists operation-name prefixes to tell reads from writes.
CLI_ONLY = {"event_archive.py", "aws_errors.py"}
SERVICES = ("dynamodb", "s3", "cognito-idp", "ssm")
# Client methods that are not API operations but sign a request the role must be allowed to make.
PRESIGNED = {"generate_presigned_post": ("s3", "PutObject"), "generate_presigned_url": ("s3", "GetObject")}
# How an S3 operation is authorised (HeadObject is GetObject; CopyObject reads and writes).
S3_AUTHORISED_AS = {"HeadObject": ("GetObject",), "CopyObject": ("GetObject", "PutObject")}
DYNAMODB_AUTHORISED_AS = {"TransactWriteItems": ("PutItem", "UpdateItem", "DeleteItem", "ConditionCheckItem")}
# aws_errors' helpers that make one fixed call for the adapter that calls them (the others take the operation name).
HELPER_OPERATIONS = {"batch_items": "batch_get_item"}


def adapter_calls() -> dict[str, set[str]]:
    """{service: {OperationName}} for every operation name the Lambda's storage adapters mention."""
    session = botocore.session.get_session()
    operations = {svc: {xform_name(op): op for op in session.get_service_model(svc).operation_names}
                  for svc in SERVICES}
    calls: dict[str, set[str]] = {svc: set() for svc in SERVICES}
    for path in sorted(STORAGE_DIR.glob("*.py")):
        if path.name in CLI_ONLY:
            continue
        for name in _operation_names(ast.parse(path.read_text())):
            if name in PRESIGNED:
                service, operation = PRESIGNED[name]
                calls[service].add(operation)
            for service, ops in operations.items():
                if name in ops:
                    calls[service].add(ops[name])
    return calls


def _operation_names(tree: ast.AST):
    """Names the adapters hand to boto3: `client.op(...)` called on a client attribute, and every string constant
    (operation names reach the adapters' `_call(...)` wrappers and `get_paginator(...)` as strings, sometimes via a
    variable). Attribute calls on other receivers are the adapters' own methods (`devices.get_device`), not AWS."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and isinstance(node.value, str):
            yield node.value
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in HELPER_OPERATIONS:
            yield HELPER_OPERATIONS[node.func.id]
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute):
            receiver = ast.unparse(node.func.value)
            if any(word in receiver for word in ("client", "cognito", "dynamodb", "s3")):
                yield node.func.attr


def required_actions(calls: dict[str, set[str]]) -> set[str]:
    needed = set()
    for operation in calls["dynamodb"]:
        needed |= {f"dynamodb:{a}" for a in DYNAMODB_AUTHORISED_AS.get(operation, (operation,))}
    for operation in calls["s3"]:
        needed |= {f"s3:{a}" for a in S3_AUTHORISED_AS.get(operation, (operation,))}
    needed |= {f"cognito-idp:{op}" for op in calls["cognito-idp"] - permissions.COGNITO_CALLS_WITHOUT_IAM}
    needed |= {f"ssm:{op}" for op in calls["ssm"]}
    return needed


@pytest.fixture(scope="module")
def role_statements(app_template) -> list[dict]:
    functions = app_template.find_resources("AWS::Serverless::Function").values()
    assert {str(f["Properties"]["Role"]) for f in functions} == {str({"Fn::GetAtt": ["DefaultRole", "Arn"]})}, \
        "the functions share one role"
    inline = app_template.find_resources("AWS::IAM::Role")["DefaultRole"]["Properties"]["Policies"]
    attached = [p["Properties"]["PolicyDocument"] for p in app_template.find_resources("AWS::IAM::Policy").values()
                if {"Ref": "DefaultRole"} in p["Properties"].get("Roles", [])]
    return [s for doc in [p["PolicyDocument"] for p in inline] + attached for s in doc["Statement"]]


def _actions(statement: dict) -> list[str]:
    return statement["Action"] if isinstance(statement["Action"], list) else [statement["Action"]]


def test_the_scan_finds_what_the_adapters_are_known_to_call():
    calls = adapter_calls()
    # Spot checks that the derivation itself works (a scan finding nothing would make the next test vacuous).
    assert {"PutItem", "Query", "TransactWriteItems"} <= calls["dynamodb"]
    assert {"AdminDisableUser", "AdminEnableUser", "AdminUserGlobalSignOut", "InitiateAuth"} <= calls["cognito-idp"]
    assert {"PutObject", "GetObject"} <= calls["s3"]


def test_every_call_the_adapters_make_is_granted_and_nothing_else(role_statements):
    granted = {a for s in role_statements if s["Effect"] == "Allow" for a in _actions(s)}
    needed = required_actions(adapter_calls())
    # ListBucket: lets a missing object answer 404, not 403 (see permissions.py); logs: the functions' own.
    infrastructure = {"s3:ListBucket", *permissions.LOG_ACTIONS}

    assert needed - granted == set(), "calls the role may not make"
    assert granted - needed - infrastructure == set(), "grants no adapter call needs"
    assert not any("*" in a for a in granted), "no wildcard actions"


def test_grants_are_scoped_to_the_stacks_own_resources(role_statements, app_template):
    tables = app_template.find_resources("AWS::DynamoDB::Table")
    buckets = app_template.find_resources("AWS::S3::Bucket")
    for statement in role_statements:
        resources_ = statement["Resource"] if isinstance(statement["Resource"], list) else [statement["Resource"]]
        assert "*" not in resources_ and not any(isinstance(r, str) and ":*:" in r for r in resources_), statement
        text = str(resources_)
        if any(a.startswith("dynamodb:") for a in _actions(statement)):
            assert all(logical_id in text for logical_id in tables)
        if any(a.startswith("logs:") for a in _actions(statement)):
            assert "Logs" in text and "arn:*:logs" not in text
    bucket_grants = str([s["Resource"] for s in role_statements if any(a.startswith("s3:") for a in _actions(s))])
    for spec in resources.BUCKETS:
        logical_id = next(b for b in buckets if b.startswith(f"{spec.logical.capitalize()}Bucket"))
        # Only buckets the adapters use (the models bucket, and the runs bucket since the learning booth).
        assert (logical_id in bucket_grants) == (spec.logical in permissions.BUCKET_OBJECT_ACTIONS), spec.logical


def test_every_function_logs_into_a_group_that_expires_and_has_alarms(app_template):
    functions = app_template.find_resources("AWS::Serverless::Function")
    groups = app_template.find_resources("AWS::Logs::LogGroup")
    alarms = [a["Properties"] for a in app_template.find_resources("AWS::CloudWatch::Alarm").values()]
    for logical_id, function in functions.items():
        target = function["Properties"]["LoggingConfig"]["LogGroup"]["Ref"]
        assert groups[target]["Properties"]["RetentionInDays"] > 0
        watched = {a["MetricName"] for a in alarms if str(a["Dimensions"]).count(logical_id)}
        assert watched == {"Errors", "Throttles"}, logical_id


def test_the_api_stage_is_throttled(app_template):
    api = next(iter(app_template.find_resources("AWS::Serverless::Api").values()))["Properties"]
    settings = api["MethodSettings"][0]
    assert settings["ThrottlingRateLimit"] > 0 and settings["ThrottlingBurstLimit"] >= settings["ThrottlingRateLimit"]


# --- the live-page server's task role ---------------------------------------------------------------------------

FUNCTIONS_DIR = STORAGE_DIR.parents[1]
# Where the live regions read their data: the routes the live server renders the same HTML as, and the server itself
# (live/drem_live/, once it exists: its own reads join the derivation, so a new one without a grant fails here).
LIVE_READERS = (FUNCTIONS_DIR / "chalicelib" / "routes" / "public_pages.py",
                *sorted((FUNCTIONS_DIR.parent / "live" / "drem_live").rglob("*.py")))


def _storage_classes(tree: ast.Module) -> dict[str, str]:
    """{adapter class name: its chalicelib.storage module} as a module imports them."""
    return {alias.name: node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)
            and (node.module or "").startswith("chalicelib.storage.") for alias in node.names}


def _adapters_built(scope: ast.AST, classes: dict[str, str]) -> set[tuple[str, str]]:
    """{(storage module, table logical name)} for every adapter built in `scope` on `….table("<logical>")`."""
    built = set()
    for node in ast.walk(scope):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in classes:
            tables = {a.args[0].value for a in ast.walk(node) if isinstance(a, ast.Call)
                      and isinstance(a.func, ast.Attribute) and a.func.attr == "table"
                      and a.args and isinstance(a.args[0], ast.Constant)}
            built |= {(classes[node.func.id], t) for t in tables}
    return built


def _services_tables() -> dict[str, set[tuple[str, str]]]:
    """{services function: {(storage module, table logical name)}} from chalicelib/services.py, following calls to
    other services functions (e.g. a service built on race_store())."""
    tree = ast.parse((FUNCTIONS_DIR / "chalicelib" / "services.py").read_text())
    classes = _storage_classes(tree)
    functions = [n for n in tree.body if isinstance(n, ast.FunctionDef)]
    direct = {f.name: _adapters_built(f, classes) for f in functions}
    calls = {f.name: {n.func.id for n in ast.walk(f) if isinstance(n, ast.Call) and isinstance(n.func, ast.Name)}
             for f in functions}

    def resolve(name: str, seen: frozenset[str] = frozenset()) -> set[tuple[str, str]]:
        found = set(direct.get(name, ()))
        for callee in calls.get(name, set()) - seen - {name}:
            found |= resolve(callee, seen | {name})
        return found

    return {name: resolve(name) for name in direct}


SESSIONS_MODULE = "chalicelib.auth.sessions"


def _session_backends_used() -> set[str]:
    """The session backends chalicelib.auth.sessions calls (`_installed().session_store()`, ...): the composition root
    installs services functions of the same names, so a reader resolving a session reads what they read."""
    tree = ast.parse((FUNCTIONS_DIR / "chalicelib" / "auth" / "sessions.py").read_text())
    return {node.attr for node in ast.walk(tree) if isinstance(node, ast.Attribute)
            and isinstance(node.value, ast.Call) and isinstance(node.value.func, ast.Name)
            and node.value.func.id == "_installed"}


def live_reads() -> dict[str, set[str]]:
    """{table logical name: {dynamodb:Action}}: the read operations of the storage adapters the live readers use
    (behind each `services.x()` they call, or built by themselves), limited to the reads the live server may make."""
    services_tables = _services_tables()
    session = botocore.session.get_session()
    operations = {xform_name(op): op for op in session.get_service_model("dynamodb").operation_names}
    reads: dict[str, set[str]] = {}
    for path in LIVE_READERS:
        tree = ast.parse(path.read_text())
        used = {node.attr for node in ast.walk(tree) if isinstance(node, ast.Attribute)
                and isinstance(node.value, ast.Name) and node.value.id == "services"}
        if any(isinstance(node, ast.ImportFrom) and node.module == SESSIONS_MODULE for node in ast.walk(tree)):
            used |= _session_backends_used()  # e.g. the staff preview resolving a session cookie
        adapters = {pair for name in used for pair in services_tables.get(name, ())}
        adapters |= _adapters_built(tree, _storage_classes(tree))
        for module, table in adapters:
            source = FUNCTIONS_DIR / (module.replace(".", "/") + ".py")
            actions = {f"dynamodb:{operations[n]}" for n in _operation_names(ast.parse(source.read_text()))
                       if n in operations}
            reads.setdefault(table, set()).update(actions & permissions.LIVE_READ_ACTIONS)
    return reads


@pytest.fixture(scope="module")
def task_role_statements(app_template) -> list[dict]:
    # The live pages' task (the learning booth's has the functions' role: tests/infra/test_booth_service.py).
    [task] = [t for name, t in app_template.find_resources("AWS::ECS::TaskDefinition").items()
              if not name.startswith("Booth")]
    role_id = task["Properties"]["TaskRoleArn"]["Fn::GetAtt"][0]
    role = app_template.find_resources("AWS::IAM::Role")[role_id]["Properties"]
    inline = [p["PolicyDocument"] for p in role.get("Policies", [])]
    attached = [p["Properties"]["PolicyDocument"] for p in app_template.find_resources("AWS::IAM::Policy").values()
                if {"Ref": role_id} in p["Properties"].get("Roles", [])]
    return [s for doc in inline + attached for s in doc["Statement"]]


def test_the_live_derivation_finds_the_boards_events_and_races():
    reads = live_reads()
    # Spot checks that the derivation works (finding nothing would make the next test vacuous).
    assert "dynamodb:GetItem" in reads["leaderboards"] and "dynamodb:GetItem" in reads["events"]
    assert reads["races"] >= {"dynamodb:GetItem"}
    # The staff preview of a car's camera resolves the session cookie: the user's revocation mark, and nothing else
    # of the sessions table (no write, no scan).
    assert reads["sessions"] == {"dynamodb:GetItem"}


def test_the_live_task_role_reads_exactly_the_tables_the_live_pages_read(task_role_statements, app_template):
    tables = app_template.find_resources("AWS::DynamoDB::Table")
    logical = {table_id: spec.logical for table_id in tables for spec in resources.TABLES
               if table_id.startswith(f"{spec.logical.capitalize()}Table")}
    granted: dict[str, set[str]] = {}
    for statement in task_role_statements:
        assert statement["Effect"] == "Allow"
        for resource in statement["Resource"] if isinstance(statement["Resource"], list) else [statement["Resource"]]:
            # Only whole-table ARNs of the stack's own tables: no wildcard, no other service.
            assert isinstance(resource, dict) and resource["Fn::GetAtt"][1] == "Arn", resource
            granted.setdefault(logical[resource["Fn::GetAtt"][0]], set()).update(_actions(statement))

    assert granted == live_reads()
    assert all(a in permissions.LIVE_READ_ACTIONS for actions in granted.values() for a in actions), "reads only"
