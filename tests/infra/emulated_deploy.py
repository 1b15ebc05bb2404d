"""`cdk deploy` of a synthesised drem template into moto's CloudFormation, as far as moto goes.

What a real deploy does, and what stands in for each step here:
1. `cdk bootstrap` made the assets bucket and the `/cdk-bootstrap/<qualifier>/version` parameter the template's
   BootstrapVersion parameter reads: `bootstrap()` makes both.
2. cdk-assets uploads every file asset of `<stack>.assets.json` to its destination: `publish_assets()`.
3. CloudFormation runs the `AWS::Serverless-2016-10-31` transform, then creates the resources. moto runs no
   transforms (moto/cloudformation/responses.py answers every GetTemplateSummary with `"DeclaredTransforms": []`),
   so `sam_function_as_lambda()` rewrites each `AWS::Serverless::Function` into the `AWS::Lambda::Function` the SAM
   translator makes of it (aws/serverless-application-model, samtranslator/model/sam_resources.py
   `SamFunction._construct_lambda_function`: CodeUri -> Code, Tracing -> TracingConfig, Tags map -> list plus
   `lambda:createdBy: SAM`; with a Role given, no role is generated). Anything else SAM would translate (the
   `AWS::Serverless::Api`) stays untranslated and is skipped.
4. moto's CloudFormation creates only the types it has a model for: moto/cloudformation/parsing.py builds
   `get_model_map()` from `CloudFormationModel.__subclasses__()` of the service modules imported at its top;
   `parse_resource` warns "not supported by moto's CloudFormation implementation" and creates nothing for any other
   type, and `ResourceMap.validate_outputs` fails the whole stack when an output reads an attribute of such a
   resource. So the unsupported resources, everything that refers to them, and the outputs that read them are taken
   out before the template is sent (`deployable_subset()`), and the caller prints and checks that list.
5. moto has no CloudFormation model for Cognito (moto/cognitoidp/models.py defines no CloudFormationModel), yet the
   user pool is what sign-in needs: `provide_cognito()` creates the pool, its client and groups from the template's
   own properties through the Cognito API (the names CloudFormation's Cognito resources pass to CreateUserPool,
   CreateUserPoolClient and CreateGroup) and substitutes their ids wherever the template refers to them.
6. Nor for Secrets Manager (moto/secretsmanager/models.py defines no CloudFormationModel), whose generated secrets the
   functions and the live tasks share: `provide_secrets()` creates each through the API with a value GetRandomPassword
   makes from the template's own GenerateSecretString (what CloudFormation's AWS::SecretsManager::Secret does; its Ref
   is the ARN), and `substitute` resolves the `{{resolve:secretsmanager:<arn>:SecretString:::}}` dynamic references
   to its value, as CloudFormation does at deploy time.
"""
from __future__ import annotations

import copy
import io
import json
import re
import uuid
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

BOOTSTRAP_QUALIFIER = "hnb659fds"  # CDK's default qualifier (cdk.json sets no other)
# The bootstrap template version the CDK CLI of infra_cdk/package.json deploys; the template's rule wants >= 6.
BOOTSTRAP_VERSION = "30"
_SUB_NAME = re.compile(r"\$\{(?!!)([A-Za-z0-9]+)(?:\.[A-Za-z0-9.]+)?\}")


def moto_supported_types() -> set[str]:
    """The resource types moto's CloudFormation creates (the same map `parse_resource` looks types up in)."""
    from moto.cloudformation.parsing import get_model_map

    return set(get_model_map())


def references(node: Any) -> set[str]:
    """Logical ids a template fragment refers to: Ref, Fn::GetAtt and Fn::Sub `${Name}` / `${Name.Attr}`."""
    found: set[str] = set()
    if isinstance(node, dict):
        for key, value in node.items():
            if key == "Ref" and isinstance(value, str):
                found.add(value)
            elif key == "Fn::GetAtt":
                found.add(value[0] if isinstance(value, list) else str(value).split(".")[0])
            elif key == "Fn::Sub":
                text = value[0] if isinstance(value, list) else value
                local = set(value[1]) if isinstance(value, list) else set()
                found |= {name for name in _SUB_NAME.findall(text) if name not in local}
                if isinstance(value, list):
                    found |= references(value[1])
            else:
                found |= references(value)
    elif isinstance(node, list):
        for item in node:
            found |= references(item)
    return {name for name in found if not name.startswith("AWS::")}


def _depends_on(resource: dict[str, Any]) -> set[str]:
    depends = resource.get("DependsOn", [])
    return {depends} if isinstance(depends, str) else set(depends)


# --- step 1 and 2: bootstrap and assets ------------------------------------------------------------------------------

def assets_bucket(account: str, region: str) -> str:
    return f"cdk-{BOOTSTRAP_QUALIFIER}-assets-{account}-{region}"


def bootstrap(ssm: Any, s3: Any, account: str, region: str) -> None:
    s3.create_bucket(Bucket=assets_bucket(account, region))
    ssm.put_parameter(Name=f"/cdk-bootstrap/{BOOTSTRAP_QUALIFIER}/version", Value=BOOTSTRAP_VERSION, Type="String")


def publish_assets(s3: Any, cloud_assembly: Path, stack_artifact: str, account: str, region: str) -> dict[str, Path]:
    """Upload the file assets of `<stack_artifact>.assets.json` as cdk-assets does; {object key: local file}."""
    manifest = json.loads((cloud_assembly / f"{stack_artifact}.assets.json").read_text())
    published = {}
    for asset in manifest["files"].values():
        source = cloud_assembly / asset["source"]["path"]
        packaging = asset["source"].get("packaging", "file")
        if packaging == "zip":  # a directory asset: cdk-assets uploads it zipped
            assert source.is_dir(), f"unexpected asset {asset}"
            data = _zipped(source)
        else:
            assert packaging == "file" and source.is_file(), f"unexpected asset {asset}"
            data = source.read_bytes()
        for destination in asset["destinations"].values():
            bucket = destination["bucketName"].replace("${AWS::AccountId}", account).replace("${AWS::Region}", region)
            s3.put_object(Bucket=bucket, Key=destination["objectKey"], Body=data)
            published[destination["objectKey"]] = source
    # Container images (manifest["dockerImages"]) are not built: moto runs no containers, and a service using one
    # is either skipped (unsupported type) or created without ever pulling it.
    return published


def _zipped(directory: Path) -> bytes:
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as archive:
        for path in sorted(p for p in directory.rglob("*") if p.is_file()):
            archive.write(path, path.relative_to(directory).as_posix())
    return buffer.getvalue()


# --- step 3: the SAM transform of a function -------------------------------------------------------------------------

_SAM_FUNCTION_PASSTHROUGH = {"Architectures", "Environment", "Handler", "MemorySize", "Role", "Runtime", "Timeout",
                             "LoggingConfig", "Description", "Layers", "ReservedConcurrentExecutions"}


def sam_function_as_lambda(resource: dict[str, Any]) -> dict[str, Any]:
    props = dict(resource["Properties"])
    unknown = set(props) - _SAM_FUNCTION_PASSTHROUGH - {"CodeUri", "Tracing", "Tags"}
    # Events, Policies, AutoPublishAlias... make the translator add resources this stand-in does not: refuse them.
    assert not unknown, f"the SAM stand-in does not translate {sorted(unknown)}"
    code = props.pop("CodeUri")
    lambda_props = {key: value for key, value in props.items() if key in _SAM_FUNCTION_PASSTHROUGH}
    lambda_props["Code"] = {"S3Bucket": code["Bucket"], "S3Key": code["Key"]}
    if "Tracing" in props:
        lambda_props["TracingConfig"] = {"Mode": props["Tracing"]}
    lambda_props["Tags"] = [{"Key": "lambda:createdBy", "Value": "SAM"},
                            *({"Key": k, "Value": v} for k, v in props.get("Tags", {}).items())]
    translated = {key: value for key, value in resource.items() if key != "Properties"}
    translated.update(Type="AWS::Lambda::Function", Properties=lambda_props)
    return translated


# --- step 5: Cognito through its API ---------------------------------------------------------------------------------

@dataclass
class Provided:
    """Resources made outside moto's CloudFormation: logical id -> (Ref value, {attribute: value})."""
    refs: dict[str, str] = field(default_factory=dict)
    attributes: dict[str, dict[str, str]] = field(default_factory=dict)
    types: dict[str, str] = field(default_factory=dict)
    secret_values: dict[str, str] = field(default_factory=dict)  # ARN -> the secret's string


_SECRET_REFERENCE = re.compile(r"\{\{resolve:secretsmanager:(arn:[^:]+:secretsmanager:[^:]+:[^:]+:secret:[^:}]+)"
                               r":SecretString:::\}\}")


def _resolved(text: str, provided: Provided) -> str:
    return _SECRET_REFERENCE.sub(lambda m: provided.secret_values.get(m.group(1), m.group(0)), text)


def substitute(node: Any, provided: Provided) -> Any:
    """`node` with every Ref / Fn::GetAtt / Fn::Sub name of a provided resource replaced by its value."""
    if isinstance(node, dict):
        if set(node) == {"Ref"} and node["Ref"] in provided.refs:
            return provided.refs[node["Ref"]]
        if set(node) == {"Fn::GetAtt"}:
            name, attribute = node["Fn::GetAtt"] if isinstance(node["Fn::GetAtt"], list) else \
                node["Fn::GetAtt"].split(".", 1)
            if name in provided.refs:
                return provided.attributes[name][attribute]
        if set(node) == {"Fn::Sub"} and isinstance(node["Fn::Sub"], str):
            def value(match: re.Match) -> str:
                name, _, attribute = match.group(0)[2:-1].partition(".")
                if name not in provided.refs:
                    return match.group(0)
                return provided.attributes[name][attribute] if attribute else provided.refs[name]
            return {"Fn::Sub": re.sub(r"\$\{[A-Za-z0-9.]+\}", value, node["Fn::Sub"])}
        if set(node) == {"Fn::Join"}:
            separator, parts = node["Fn::Join"]
            parts = substitute(parts, provided)
            if isinstance(parts, list) and all(isinstance(part, str) for part in parts):
                return _resolved(separator.join(parts), provided)  # a dynamic reference is resolved once joined
            return {"Fn::Join": [separator, parts]}
        return {key: substitute(value, provided) for key, value in node.items()}
    if isinstance(node, list):
        return [substitute(item, provided) for item in node]
    if isinstance(node, str):
        return _resolved(node, provided)
    return node


def provide_secrets(secretsmanager: Any, resources: dict[str, Any], provided: Provided) -> Provided:
    """Create the template's generated secrets through the API, into `provided` (which it returns)."""
    for logical_id, resource in resources.items():
        if resource["Type"] != "AWS::SecretsManager::Secret":
            continue
        props = resource.get("Properties", {})
        generate = dict(props.get("GenerateSecretString", {}))
        assert not {"SecretStringTemplate", "GenerateStringKey"} & set(generate), "only plain generated strings"
        value = secretsmanager.get_random_password(**generate)["RandomPassword"]
        # Without a name in the template CloudFormation names it after the logical id with a unique suffix.
        arn = secretsmanager.create_secret(Name=f"{logical_id}-{uuid.uuid4().hex[:12]}", SecretString=value,
                                           Description=props.get("Description", ""))["ARN"]
        provided.refs[logical_id] = arn
        provided.attributes[logical_id] = {}
        provided.types[logical_id] = resource["Type"]
        provided.secret_values[arn] = value
    return provided


def provide_cognito(cognito: Any, resources: dict[str, Any], region: str) -> Provided:
    """Create the template's user pools, clients and groups (in dependency order) with their own properties."""
    provided = Provided()
    order = ("AWS::Cognito::UserPool", "AWS::Cognito::UserPoolClient", "AWS::Cognito::UserPoolGroup")
    for resource_type in order:
        for logical_id, resource in resources.items():
            if resource["Type"] != resource_type:
                continue
            props = substitute(resource.get("Properties", {}), provided)
            assert not references(props), f"{logical_id} refers to {references(props)}, not created yet"
            if resource_type == "AWS::Cognito::UserPool":
                pool = cognito.create_user_pool(PoolName=props.pop("UserPoolName"), **props)["UserPool"]
                provided.refs[logical_id] = pool["Id"]
                provided.attributes[logical_id] = {
                    "Arn": pool["Arn"], "ProviderName": f"cognito-idp.{region}.amazonaws.com/{pool['Id']}",
                    "ProviderURL": f"https://cognito-idp.{region}.amazonaws.com/{pool['Id']}"}
            elif resource_type == "AWS::Cognito::UserPoolClient":
                client = cognito.create_user_pool_client(**props)["UserPoolClient"]
                provided.refs[logical_id] = client["ClientId"]
                provided.attributes[logical_id] = {"ClientId": client["ClientId"], "Name": client["ClientName"]}
            else:
                group = cognito.create_group(**props)["Group"]
                provided.refs[logical_id] = group["GroupName"]
                provided.attributes[logical_id] = {}
            provided.types[logical_id] = resource_type
    return provided


# --- step 4: what moto can create ------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Subset:
    template: dict[str, Any]
    # logical id -> why it is not created: "unsupported <type>" or "needs <logical id>"
    skipped: dict[str, str]
    dropped_outputs: list[str]
    translated: list[str]


def deployable_subset(template: dict[str, Any], provided: Provided, supported: set[str]) -> Subset:
    template = copy.deepcopy(template)
    template.pop("Transform", None)
    resources = {lid: r for lid, r in template["Resources"].items() if lid not in provided.refs}
    translated = [lid for lid, r in resources.items() if r["Type"] == "AWS::Serverless::Function"]
    for logical_id in translated:
        resources[logical_id] = sam_function_as_lambda(resources[logical_id])
    resources = substitute(resources, provided)
    skipped = {lid: f"unsupported {r['Type']}" for lid, r in resources.items() if r["Type"] not in supported}
    changed = True
    while changed:  # whatever needs a skipped resource cannot be created either
        changed = False
        for logical_id, resource in resources.items():
            if logical_id in skipped:
                continue
            needs = sorted((references(resource) | _depends_on(resource)) & set(skipped))
            if needs:
                skipped[logical_id] = f"needs {needs[0]}"
                changed = True
    template["Resources"] = {lid: r for lid, r in resources.items() if lid not in skipped}
    outputs = substitute(template.get("Outputs", {}), provided)
    dropped = sorted(name for name, output in outputs.items() if references(output) & set(skipped))
    template["Outputs"] = {name: output for name, output in outputs.items() if name not in dropped}
    return Subset(template, skipped, dropped, translated)
