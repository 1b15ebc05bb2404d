"""Where an AWS deployment of drem is, as `make deploy` records it: `.drem-aws/<stage>.json`.

`cdk deploy --outputs-file` writes the stack's outputs; `drem aws record` turns them into this file, which
`drem aws admin`, `drem export --aws` / `drem import --aws` and `drem car activate --aws` / `drem timer --aws` read, so
nobody copies table names, pool ids or URLs into `DREM_*` variables or flags by hand. It holds names and URLs, never
credentials. The car agent reads its `public_url` itself (drem_cars.deployment_record: a car has no drem_local), so
that field's name and meaning must not change.
"""
from __future__ import annotations

import json
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from drem_infra import resources

DEFAULT_DIR = Path(".drem-aws")


class DeploymentError(RuntimeError):
    """The deployment record is missing or does not describe a drem stack; the message says what to run."""


@dataclass(frozen=True)
class Deployment:
    stage: str
    region: str
    public_url: str
    user_pool_id: str
    user_pool_client_id: str
    tables: dict[str, str] = field(default_factory=dict)
    buckets: dict[str, str] = field(default_factory=dict)
    distribution_url: str = ""

    @classmethod
    def from_cdk_outputs(cls, outputs: dict[str, Any], stage: str) -> Deployment:
        """From `cdk deploy --outputs-file` JSON ({"drem-<stage>": {"UserPoolId": ..., ...}})."""
        stack = outputs.get(f"drem-{stage}")
        if not isinstance(stack, dict):
            raise DeploymentError(f"the outputs hold no stack drem-{stage} (found: {', '.join(outputs) or 'none'})")
        try:
            return cls(
                stage=stage, region=stack["Region"], user_pool_id=stack["UserPoolId"],
                user_pool_client_id=stack["UserPoolClientId"],
                tables={t.logical: stack[f"{t.logical.capitalize()}TableName"] for t in resources.TABLES},
                buckets={b.logical: stack[f"{b.logical.capitalize()}BucketName"] for b in resources.BUCKETS},
                distribution_url=stack.get("DistributionUrl", ""),
                public_url=stack.get("PublicUrl") or stack.get("DistributionUrl", ""),
            )
        except KeyError as exc:
            raise DeploymentError(f"stack drem-{stage} has no output {exc.args[0]}: deploy the current version "
                                  "with `make deploy`") from None

    @classmethod
    def load(cls, stage: str, directory: Path = DEFAULT_DIR) -> Deployment:
        path = directory / f"{stage}.json"
        try:
            data = json.loads(path.read_text())
            return cls(**data)
        except FileNotFoundError:
            raise DeploymentError(f"{path} not found: deploy with `make deploy STAGE={stage}` (it writes this file), "
                                  "or run this where you deployed from") from None
        except (ValueError, TypeError) as exc:
            raise DeploymentError(f"{path} is not a drem deployment record ({exc})") from None

    def save(self, directory: Path = DEFAULT_DIR) -> Path:
        directory.mkdir(parents=True, exist_ok=True)
        path = directory / f"{self.stage}.json"
        tmp = path.with_suffix(".tmp")
        tmp.write_text(json.dumps(asdict(self), indent=2, sort_keys=True) + "\n")
        os.replace(tmp, path)
        return path

    def environment(self) -> dict[str, str]:
        """The app's environment contract for this deployment (what `drem export --aws` and scripts read)."""
        env = resources.stage_environment(self.stage, self.user_pool_id, self.user_pool_client_id,
                                          self.tables, self.buckets)
        env.update(AWS_REGION=self.region, DREM_PUBLIC_URL=self.public_url)
        return env
