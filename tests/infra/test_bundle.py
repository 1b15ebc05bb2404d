"""The Lambda bundle that `drem build` + `chalice package` produce imports cleanly in a Lambda-like interpreter:
only the zip's contents plus what the Python Lambda runtime provides (boto3 and its dependencies)."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import zipfile
from pathlib import Path

import pytest

from tests.infra.conftest import functions_dir_exclusively

pytestmark = pytest.mark.infra

REPO_ROOT = Path(__file__).resolve().parents[2]
FUNCTIONS_DIR = REPO_ROOT / "functions"
HTMX_SOURCE = REPO_ROOT / "web" / "drem_web" / "static" / "vendor" / "htmx.min.js"
# What the AWS Lambda Python runtime ships besides the standard library.
LAMBDA_RUNTIME_PACKAGES = ("boto3", "botocore", "s3transfer", "jmespath", "dateutil", "urllib3", "six")
NEVER_IN_BUNDLE = ("moto/", "aws_cdk/", "boto3/", "botocore/", "drem_infra/stack.py", "drem_infra/live_pages.py",
                   "drem_local/", "tests/")

IMPORT_EVERYTHING = textwrap.dedent("""
    import importlib, json, sys, traceback
    bundle, runtime, modules = sys.argv[1], sys.argv[2], json.loads(sys.argv[3])
    sys.path[:0] = [bundle, runtime]
    failures = {}
    for name in modules:
        try:
            importlib.import_module(name)
        except BaseException:
            failures[name] = traceback.format_exc(limit=-3)
    leaked = sorted({m.__file__ for m in list(sys.modules.values())
                     if getattr(m, "__file__", None) and "site-packages" in m.__file__})
    print(json.dumps({"failures": failures, "leaked": leaked}))
""")


def _modules_in(names: list[str], top_levels: tuple[str, ...]) -> list[str]:
    modules = []
    for name in names:
        if not name.endswith(".py") or name.split("/", 1)[0] not in top_levels:
            continue
        parts = name[:-3].split("/")
        if parts[-1] == "__init__":
            parts = parts[:-1]
        modules.append(".".join(parts))
    return sorted(modules)


@pytest.fixture(scope="module")
def bundle(tmp_path_factory, lambda_build):
    work = tmp_path_factory.mktemp("bundle")
    with functions_dir_exclusively():  # `chalice package` writes functions/.chalice/ (another worker may synth)
        package = subprocess.run([str(Path(sys.executable).with_name("chalice")), "package", str(work / "out")],
                                 cwd=FUNCTIONS_DIR, capture_output=True, text=True, timeout=300,
                                 env={**os.environ, "AWS_DEFAULT_REGION": os.environ.get("AWS_DEFAULT_REGION",
                                                                                         "us-east-1")})
    assert package.returncode == 0, f"chalice package failed:\n{package.stdout}\n{package.stderr}"
    unzipped = work / "unzipped"
    with zipfile.ZipFile(work / "out" / "deployment.zip") as archive:
        names = archive.namelist()
        archive.extractall(unzipped)
    return unzipped, names, json.loads((work / "out" / "sam.json").read_text())


@pytest.fixture(scope="module")
def lambda_runtime(tmp_path_factory):
    """A directory holding only the packages Lambda provides, linked from this venv."""
    import importlib.util
    runtime = tmp_path_factory.mktemp("lambda-runtime")
    for name in LAMBDA_RUNTIME_PACKAGES:
        spec = importlib.util.find_spec(name)
        assert spec is not None and spec.origin, f"{name} is not installed in the test venv"
        source = Path(spec.origin)
        source = source.parent if source.name == "__init__.py" else source
        (runtime / source.name).symlink_to(source)
    return runtime


def test_app_and_every_backend_module_import_in_a_lambda_like_interpreter(bundle, lambda_runtime):
    unzipped, names, _ = bundle
    modules = ["app", *_modules_in(names, ("chalicelib", "drem_infra", "drem_leaderboard", "drem_archive", "drem_web"))]

    # -I: ignore PYTHON* env and the user site; -S: no site-packages at all, so only the bundle can satisfy imports.
    result = subprocess.run(
        [sys.executable, "-I", "-S", "-c", IMPORT_EVERYTHING, str(unzipped), str(lambda_runtime), json.dumps(modules)],
        cwd=unzipped, capture_output=True, text=True, timeout=120,
        env={"AWS_DEFAULT_REGION": "us-east-1", "AWS_ACCESS_KEY_ID": "testing", "AWS_SECRET_ACCESS_KEY": "testing",
             "PATH": os.environ.get("PATH", "")},
    )
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout.strip().splitlines()[-1])

    failures = "\n".join(f"--- {name}\n{trace}" for name, trace in report["failures"].items())
    assert not report["failures"], f"{len(report['failures'])} of {len(modules)} modules fail to import:\n{failures}"
    assert report["leaked"] == [], "imports reached outside the bundle and the Lambda runtime"
    assert any(m.startswith("chalicelib.") for m in modules)


def test_bundle_carries_the_shared_packages_and_nothing_dev_only(bundle):
    _, names, _ = bundle

    assert "app.py" in names
    assert "drem_infra/resources.py" in names
    assert any(n.startswith("drem_leaderboard/") for n in names)
    assert "drem_archive/member_names.py" in names  # the archive vetting every upload goes through
    assert any(n.startswith("drem_web/templates/") for n in names)
    if HTMX_SOURCE.is_file():
        assert "drem_web/static/vendor/htmx.min.js" in names
    for forbidden in NEVER_IN_BUNDLE:
        assert not [n for n in names if n.startswith(forbidden) or n == forbidden], f"{forbidden} is in the bundle"
    assert any(n.startswith("pydantic_core/") and n.endswith(".so") for n in names), "no manylinux pydantic_core"


def test_packaged_functions_run_on_the_interpreter_version_of_the_bundle(bundle):
    _, _, sam = bundle
    functions = [r for r in sam["Resources"].values() if r["Type"] == "AWS::Serverless::Function"]

    assert functions
    runtime = f"python{sys.version_info.major}.{sys.version_info.minor}"
    assert {f["Properties"]["Runtime"] for f in functions} == {runtime}
    assert {f["Properties"]["Environment"]["Variables"]["DREM_STAGE"] for f in functions} == {"dev"}
