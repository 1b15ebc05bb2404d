"""One `drem build` per test session for the infra tests: it vendors the shared packages and installs the Lambda
wheels of requirements/lambda.txt into functions/vendor/ (the only step that downloads; packaging and synth don't)."""
from __future__ import annotations

import fcntl
import json
import os
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

os.environ.setdefault("JSII_SILENCE_WARNING_END_OF_LIFE_NODE_VERSION", "20")

REPO_ROOT = Path(__file__).resolve().parents[2]
FUNCTIONS_DIR = REPO_ROOT / "functions"
STAGE = "test"
# The app module the session had imported before the synth (tests/infra/test_cdk_synth.py checks it is untouched).
BEFORE_SYNTH: dict = {}
# Where the synth wrote its cloud assembly (cdk.out: templates and asset manifests, the Lambda bundle among them).
SYNTH_OUTDIR: dict[str, Path] = {}
# What `make deploy` passes on its second deploy (CloudFront's domain, or the custom domain).
PUBLIC_URL = "https://drem.example.org"


# One lock and one "built" mark per test run, shared by the pytest-xdist workers (`make test` runs one per core):
# functions/ is one folder, so `drem build` (which replaces functions/vendor/) runs once, and no worker packages or
# synthesises the app while another is writing there.
_RUN = Path(tempfile.gettempdir()) / f"drem-infra-tests-{os.environ.get('PYTEST_XDIST_TESTRUNUID', os.getpid())}"


@contextmanager
def functions_dir_exclusively() -> Iterator[Path]:
    _RUN.mkdir(exist_ok=True)
    with open(_RUN / "lock", "w") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        yield FUNCTIONS_DIR


@pytest.fixture(scope="session")
def lambda_build() -> Path:
    with functions_dir_exclusively():
        if not (_RUN / "built").exists():
            drem = Path(sys.executable).with_name("drem")
            build = subprocess.run([str(drem), "build"], cwd=REPO_ROOT, capture_output=True, text=True, timeout=600)
            assert build.returncode == 0, f"drem build failed:\n{build.stdout}\n{build.stderr}"
            (_RUN / "built").touch()
    return FUNCTIONS_DIR


# Anything that tried to reach a package index during synth would fail against this.
OFFLINE = {"PIP_NO_INDEX": "1", "PIP_INDEX_URL": "http://127.0.0.1:9/simple", "PIP_EXTRA_INDEX_URL": "",
           "PIP_FIND_LINKS": "", "UV_OFFLINE": "1"}


STACKS = ("drem-storage", "drem-app", "drem-cloudfront")


def _synthesise(outdir: Path, lambda_build: Path) -> None:
    """The storage-only stack and the real app's stack (functions/ as `drem build` left it), synthesised offline into
    `outdir`, in this process (as `cdk synth` runs the CDK app: the tests check it leaves the process untouched)."""
    import aws_cdk as cdk

    from drem_infra.stack import DremStack

    assert not (lambda_build / "requirements.txt").exists(), "Chalice would download requirements at synth"
    import app as app_before_synth  # as any earlier test of the session would have (the synth must not disturb it)
    BEFORE_SYNTH["app"] = app_before_synth
    work = outdir.parent
    work.mkdir(parents=True, exist_ok=True)
    cwd, saved_env = os.getcwd(), dict(os.environ)
    os.chdir(work)  # the Chalice construct writes chalice.out/ into the working directory
    os.environ.update(OFFLINE)
    try:
        app = cdk.App(outdir=str(outdir))
        # The Chalice construct runs `chalice package` over functions/ (its .chalice/deployments zip cache too) when
        # the stack is built, not at synth: another worker packaging at the same time left a half-written zip
        # ("File is not a zip file"), so the whole construction holds the lock.
        with functions_dir_exclusively():
            DremStack(app, STACKS[0], stage=STAGE)
            # With the learning booth (`make deploy BOOTH=1`): every infra test, the emulated deploy included, sees it.
            DremStack(app, STACKS[1], stage=STAGE, functions_dir=lambda_build, public_url=PUBLIC_URL, booth=True)
            # `make deploy` without a domain: the public URL is CloudFront's, known only once the distribution exists.
            DremStack(app, STACKS[2], stage=STAGE, functions_dir=lambda_build)
            app.synth()
    finally:
        os.chdir(cwd)
        os.environ.clear()
        os.environ.update(saved_env)


def _run_dir(tmp_path_factory) -> Path:
    """A folder every pytest-xdist worker of this run shares (pytest removes it with the run's other old temp dirs)."""
    base = tmp_path_factory.getbasetemp()
    return base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base


@pytest.fixture(scope="session")
def synthesised_in_this_process(tmp_path_factory, lambda_build) -> None:
    """For the tests of what a synth leaves behind in its process: synthesise here unless this process already did."""
    if "app" not in BEFORE_SYNTH:
        _synthesise(tmp_path_factory.mktemp("cdk-here") / "cdk.out", lambda_build)


@pytest.fixture(scope="session")
def templates(tmp_path_factory, lambda_build):
    """The three stacks' templates, synthesised once per test run: the first worker to get here synthesises into a
    folder all workers share (a synth costs ~20 s of CPU; each worker used to make its own), the others read it."""
    from aws_cdk.assertions import Template

    shared = _run_dir(tmp_path_factory) / "infra-synth"
    outdir = shared / "cdk.out"
    with open(_run_lock_path(), "w") as handle:  # not the functions/ lock: the synth itself takes that one
        fcntl.flock(handle, fcntl.LOCK_EX)
        if not (shared / "done").exists():
            _synthesise(outdir, lambda_build)
            (shared / "done").touch()
    SYNTH_OUTDIR["app"] = outdir
    return tuple(Template.from_json(json.loads((outdir / f"{name}.template.json").read_text())) for name in STACKS)


def _run_lock_path() -> Path:
    _RUN.mkdir(exist_ok=True)
    return _RUN / "synth.lock"


@pytest.fixture(scope="session")
def cloud_assembly(templates) -> Path:
    """The synth's cdk.out: what `cdk deploy` uploads (asset manifests, the Lambda bundle) and deploys."""
    return SYNTH_OUTDIR["app"]


@pytest.fixture(scope="session")
def template(templates):
    return templates[0]


@pytest.fixture(scope="session")
def app_template(templates):
    return templates[1]


@pytest.fixture(scope="session")
def cloudfront_template(templates):
    """The app's stack deployed without a public URL or domain (the functions read CloudFront's at run time)."""
    return templates[2]

