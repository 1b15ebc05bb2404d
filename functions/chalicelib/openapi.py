"""The OpenAPI 3.1 document of drem's JSON API, generated from the route declarations (`chalicelib.auth.access`).

Every `/api/...` route and `/healthz` is in it; HTML pages are not. Each operation says who may call it
(`x-drem-allow`: "public", "signed in" or the list of roles) and which credential schemes apply; public operations
have `security: []`. Request/response schemas come from the pydantic models a route declares (`body=`, `query=`,
`response=`); a route declared without them still appears, with its path parameters and the shared error shape.
"""
from __future__ import annotations

import re
import typing
from collections.abc import Iterable
from typing import Any

from chalice import Chalice
from pydantic import BaseModel, TypeAdapter
from pydantic.json_schema import models_json_schema

from chalicelib.auth.access import Allow, DeclaredRoute, declared_routes
from chalicelib.auth.cookies import SESSION_COOKIE
from chalicelib.core.principals import DEVICE_ROLES, USER_ROLES

OPENAPI_VERSION = "3.1.0"
REF_TEMPLATE = "#/components/schemas/{model}"
ERROR_STATUSES = {"400": "Invalid input (the error names the field)", "401": "No or invalid credentials",
                  "403": "Not allowed for this caller (wrong role or missing CSRF token)",
                  "404": "Not found (or hidden from this caller)", "409": "Conflicts with the current state"}
# Answered by any operation that writes (every method but GET): the storage server refuses a write it cannot make
# durable (chalicelib.storage.aws_errors → http_errors), before storing any of it.
WRITE_ERROR_STATUSES = {"507": "drem's data disk is full (or read-only): the write was refused and nothing of it "
                               "stored; the message names the disk and what to do (free space, then try again)"}
_PATH_PARAM = re.compile(r"{([^}]+)}")

ERROR_SCHEMA: dict[str, Any] = {
    "type": "object",
    "description": "Every error answer of the JSON API (chalicelib.http_errors).",
    "required": ["error"],
    "properties": {"error": {
        "type": "object",
        "required": ["code", "message"],
        "properties": {
            "code": {"type": "string", "description": "the error's kind, e.g. InvalidInput, NotFound"},
            "message": {"type": "string", "description": "safe to show to the user"},
            "field": {"type": ["string", "null"], "description": "the input field at fault, if one is"},
            "fields": {"type": "object", "additionalProperties": {"type": "string"}},
            "requestId": {"type": ["string", "null"]},
        },
    }},
}

SECURITY_SCHEMES: dict[str, Any] = {
    "bearerAuth": {"type": "http", "scheme": "bearer", "bearerFormat": "JWT",
                   "description": "A Cognito access token: `Authorization: Bearer <token>`. Exempt from CSRF."},
    "cookieAuth": {"type": "apiKey", "in": "cookie", "name": SESSION_COOKIE,
                   "description": "The browser session cookie; state-changing requests also need the "
                                  "`X-CSRF-Token` header (or `csrf_token` form field) equal to the `drem_csrf` "
                                  "cookie (bound to the session) and no `Origin` of another site."},
    "deviceAuth": {"type": "apiKey", "in": "header", "name": "Authorization",
                   "description": "A car's or timer's credential: `Authorization: Device <device_id>.<secret>`."},
}


def is_api_path(path: str) -> bool:
    return path.startswith("/api/") or path == "/healthz"


def api_routes(app: Chalice) -> list[DeclaredRoute]:
    return [r for r in declared_routes(app) if is_api_path(r.path)]


def allow_label(allow: Allow) -> str | list[str]:
    """x-drem-allow: "public", "signed in", or the sorted role names."""
    if allow.public:
        return "public"
    if allow.signed_in:
        return "signed in"
    return sorted(role.value for role in allow.roles)


def security_for(allow: Allow) -> list[dict[str, list[str]]]:
    if allow.public:
        return []
    schemes: list[dict[str, list[str]]] = []
    if allow.signed_in or allow.roles & USER_ROLES:
        schemes += [{"bearerAuth": []}, {"cookieAuth": []}]
    if allow.roles & DEVICE_ROLES:
        schemes.append({"deviceAuth": []})
    return schemes


def path_parameters(path: str) -> list[str]:
    return _PATH_PARAM.findall(path)


def build_document(app: Chalice, *, title: str = "drem API", version: str = "1") -> dict[str, Any]:
    routes = api_routes(app)
    schemas: dict[str, Any] = {"Error": ERROR_SCHEMA}
    refs = _model_refs(routes, schemas)
    paths: dict[str, dict[str, Any]] = {}
    operation_ids: set[str] = set()
    for declared in routes:
        operation = _operation(declared, refs, schemas, operation_ids)
        paths.setdefault(declared.path, {})[declared.method.lower()] = operation
    for path, operations in paths.items():
        names = path_parameters(path)
        if names:
            operations["parameters"] = [{"name": name, "in": "path", "required": True, "schema": {"type": "string"}}
                                        for name in names]
    return {
        "openapi": OPENAPI_VERSION,
        "info": {"title": title, "version": version,
                 "description": "DeepRacer Event Manager JSON API. `x-drem-allow` on each operation says who may "
                                "call it; per-object rules (a racer's own models) are enforced by the service."},
        "paths": paths,
        "components": {
            "schemas": schemas,
            "responses": {status: _error_response(text)
                          for status, text in {**ERROR_STATUSES, **WRITE_ERROR_STATUSES}.items()},
            "securitySchemes": SECURITY_SCHEMES,
        },
    }


def _error_response(description: str) -> dict[str, Any]:
    return {"description": description,
            "content": {"application/json": {"schema": {"$ref": "#/components/schemas/Error"}}}}


def _operation(declared: DeclaredRoute, refs: dict[tuple[type, str], dict[str, Any]], schemas: dict[str, Any],
               operation_ids: set[str]) -> dict[str, Any]:
    docs = declared.docs
    operation: dict[str, Any] = {
        "operationId": _unique_operation_id(declared, operation_ids),
        "summary": docs.summary or declared.view_name.rsplit(".", 1)[-1],
        "tags": list(docs.tags) or [_default_tag(declared.path)],
        "x-drem-allow": allow_label(declared.allow),
        "security": security_for(declared.allow),
    }
    if docs.description:
        operation["description"] = docs.description
    if docs.query is not None:
        operation["parameters"] = _query_parameters(docs.query, schemas)
    if docs.body is not None:
        operation["requestBody"] = {"required": True,
                                    "content": {"application/json": {"schema": refs[(docs.body, "validation")]}}}
    success: dict[str, Any] = {"description": "OK" if docs.status_code != 201 else "Created"}
    if docs.response is not None:
        success["content"] = {"application/json": {"schema": _response_schema(docs.response, refs, schemas)}}
    responses: dict[str, Any] = {str(docs.status_code): success}
    if docs.conditional:
        responses["304"] = {"description": "Not modified since the version named by If-None-Match (empty body)"}
    errors = [*ERROR_STATUSES, *(WRITE_ERROR_STATUSES if declared.method.upper() not in ("GET", "HEAD") else ())]
    responses.update({status: {"$ref": f"#/components/responses/{status}"} for status in errors})
    operation["responses"] = responses
    return operation


def _model_refs(routes: Iterable[DeclaredRoute], schemas: dict[str, Any]) -> dict[tuple[type, str], dict[str, Any]]:
    """Schemas of every declared body/response model at once, so pydantic resolves name clashes across them."""
    wanted: list[tuple[type[BaseModel], typing.Literal["validation", "serialization"]]] = []
    for declared in routes:
        docs = declared.docs
        if docs.body is not None:
            wanted.append((docs.body, "validation"))
        for model in _response_models(docs.response):
            wanted.append((model, "serialization"))
    unique = list(dict.fromkeys(wanted))
    if not unique:
        return {}
    by_key, top = models_json_schema(unique, ref_template=REF_TEMPLATE)
    schemas.update(top.get("$defs", {}))
    return {key: schema for key, schema in by_key.items()}


def _response_models(response: Any) -> list[type[BaseModel]]:
    if isinstance(response, type) and issubclass(response, BaseModel):
        return [response]
    args = typing.get_args(response)
    if typing.get_origin(response) is list and args and isinstance(args[0], type) and issubclass(args[0], BaseModel):
        return [args[0]]
    return []


def _response_schema(response: Any, refs: dict[tuple[type, str], dict[str, Any]],
                     schemas: dict[str, Any]) -> dict[str, Any]:
    models = _response_models(response)
    if models and typing.get_origin(response) is list:
        return {"type": "array", "items": refs[(models[0], "serialization")]}
    if models:
        return refs[(models[0], "serialization")]
    return _hoisted(TypeAdapter(response).json_schema(ref_template=REF_TEMPLATE, mode="serialization"), schemas)


def _query_parameters(model: type[BaseModel], schemas: dict[str, Any]) -> list[dict[str, Any]]:
    schema = _hoisted(model.model_json_schema(ref_template=REF_TEMPLATE), schemas)
    required = set(schema.get("required", []))
    parameters = []
    for name, field_schema in schema.get("properties", {}).items():
        parameter: dict[str, Any] = {"name": name, "in": "query", "required": name in required,
                                     "schema": field_schema}
        if "description" in field_schema:
            parameter["description"] = field_schema["description"]
        parameters.append(parameter)
    return parameters


def _hoisted(schema: dict[str, Any], schemas: dict[str, Any]) -> dict[str, Any]:
    """Move a schema's `$defs` into components (its refs already point there)."""
    schema = dict(schema)
    schemas.update(schema.pop("$defs", {}))
    return schema


def _default_tag(path: str) -> str:
    parts = [p for p in path.split("/") if p and p != "api"]
    return parts[0] if parts else "api"


def _unique_operation_id(declared: DeclaredRoute, taken: set[str]) -> str:
    base = declared.view_name.rsplit(".", 1)[-1]
    candidate = base if base not in taken else f"{base}_{declared.method.lower()}"
    suffix = 2
    while candidate in taken:
        candidate, suffix = f"{base}_{suffix}", suffix + 1
    taken.add(candidate)
    return candidate


# --- the human-readable listing (GET /api/docs) is read from the same document, so the two cannot disagree ---

def operation_rows(document: dict[str, Any]) -> list[dict[str, Any]]:
    """One row per operation: method, path, who may call it, summary and the request body's fields."""
    schemas = document.get("components", {}).get("schemas", {})
    rows = []
    for path, operations in document.get("paths", {}).items():
        for method, operation in operations.items():
            if method == "parameters":
                continue
            allow = operation["x-drem-allow"]
            rows.append({"method": method.upper(), "path": path, "summary": operation.get("summary", ""),
                         "allow": allow if isinstance(allow, str) else ", ".join(allow),
                         "body_fields": _body_fields(operation, schemas),
                         "query_fields": [p["name"] for p in operation.get("parameters", []) if p["in"] == "query"]})
    return sorted(rows, key=lambda row: (row["path"], row["method"]))


def _body_fields(operation: dict[str, Any], schemas: dict[str, Any]) -> list[dict[str, Any]]:
    schema = operation.get("requestBody", {}).get("content", {}).get("application/json", {}).get("schema")
    schema = _resolve(schema, schemas)
    if not schema:
        return []
    required = set(schema.get("required", []))
    return [{"name": name, "type": _type_label(_resolve(field, schemas) or field), "required": name in required,
             "description": field.get("description", "")}
            for name, field in schema.get("properties", {}).items()]


def _resolve(schema: dict[str, Any] | None, schemas: dict[str, Any]) -> dict[str, Any] | None:
    if schema and "$ref" in schema:
        return schemas.get(schema["$ref"].rsplit("/", 1)[-1])
    return schema


def _type_label(schema: dict[str, Any]) -> str:
    if "enum" in schema:
        return " | ".join(repr(v) for v in schema["enum"])
    if "type" in schema:
        kind = schema["type"]
        if kind == "array":
            return f"array of {_type_label(schema.get('items', {}))}"
        return kind if isinstance(kind, str) else " | ".join(kind)
    for combinator in ("anyOf", "oneOf"):
        if combinator in schema:
            return " | ".join(_type_label(option) for option in schema[combinator])
    if "$ref" in schema:
        return schema["$ref"].rsplit("/", 1)[-1]
    return schema.get("title", "any")
