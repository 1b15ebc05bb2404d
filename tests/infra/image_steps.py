"""A container image's steps without Docker, for the infra tests of the images `cdk deploy` builds (live/Dockerfile,
booth/Dockerfile): the build context as `cdk synth` staged it, its lock installed the way the Dockerfile installs it
(hashed wheels only, no resolving), and its COPY lines laid out under a stand-in root with its PYTHONPATH."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[2]
UV = REPO_ROOT / ".tools" / "bin" / "uv"


def staged_context(cdk_out: Path, stack_name: str, dockerfile: str) -> tuple[Path, dict]:
    """The staged build context of the stack's image built from `dockerfile`, and its asset source entry."""
    manifest = json.loads((cdk_out / f"{stack_name}.assets.json").read_text())
    [image] = [i for i in manifest["dockerImages"].values() if i["source"]["dockerFile"] == dockerfile]
    return cdk_out / image["source"]["directory"], image["source"]


def storage_stack_with_live_pages(cdk_out: Path, stage: str):  # noqa: ANN201 - CDK types, imported lazily
    """(app, stack, live): a storage-only stack (the app's Chalice packaging has nothing to do with the images) with
    the live pages behind a stand-in CloudFront distribution, ready for more constructs and `app.synth()`."""
    import aws_cdk as cdk
    from aws_cdk import aws_cloudfront as cloudfront
    from aws_cdk import aws_cloudfront_origins as origins

    from drem_infra import live_pages
    from drem_infra.stack import DremStack

    app = cdk.App(outdir=str(cdk_out))
    stack = DremStack(app, f"drem-{stage}", stage=stage)
    live = live_pages.LivePages(stack, "Live", stage=stage, environment=stack.app_environment(), tables=stack.tables,
                                wake_secret=stack._live_wake_secret())
    live.serve_through(cloudfront.Distribution(stack, "Distribution", default_behavior=cloudfront.BehaviorOptions(
        origin=origins.HttpOrigin("example.org"))))
    return app, stack, live


def hashed_pins(lock: str) -> dict[str, str]:
    """The lock's packages and versions; fails if a pinned package has no sha256 hash on the line after it."""
    pinned = [line for line in lock.splitlines() if "==" in line and not line.startswith((" ", "#"))]
    unhashed = [line for line in pinned if "--hash=sha256:" not in lock.split(line, 1)[1].split("\n", 2)[1]]
    assert pinned and not unhashed, unhashed
    return {line.split("==")[0]: line.split("==")[1].split()[0] for line in pinned}


def install_lock(lock: Path, venv: Path, *find_links: Path) -> Path:
    """A fresh venv holding exactly the lock's wheels (`pip install --require-hashes --no-deps --only-binary`);
    `find_links` for wheels no index serves here. Returns the venv's python."""
    subprocess.run([str(UV), "venv", "--quiet", "--python", sys.executable, str(venv)], check=True, timeout=120)
    links = [arg for folder in find_links for arg in ("--find-links", str(folder))]
    install = subprocess.run([str(UV), "pip", "install", "--quiet", "--python", str(venv / "bin" / "python"),
                              "--require-hashes", "--no-deps", "--only-binary", ":all:", *links, "-r", str(lock)],
                             capture_output=True, text=True, timeout=900)
    assert install.returncode == 0, install.stderr
    return venv / "bin" / "python"


def lay_out(context: Path, dockerfile: str, root: Path) -> str:
    """Copy what the Dockerfile's COPY lines copy (the lock aside) to `root` standing in for the image's `/`; returns
    its ENV PYTHONPATH with those paths under `root`."""
    inside = lambda path: root / path.lstrip("/")  # noqa: E731 - the image's absolute paths under the stand-in root
    pythonpath = ""
    for line in (context / dockerfile).read_text().splitlines():
        if line.startswith("COPY ") and "requirements/" not in line:
            *sources, destination = line.split()[1:]
            for source in sources:
                target = inside(destination) / Path(source).name if destination.endswith("/") else inside(destination)
                target.parent.mkdir(parents=True, exist_ok=True)
                copy = shutil.copytree if (context / source).is_dir() else shutil.copy
                copy(context / source, target)
        elif line.startswith("ENV PYTHONPATH="):
            pythonpath = os.pathsep.join(str(inside(p)) for p in line.split("=", 1)[1].split(":"))
    return pythonpath
