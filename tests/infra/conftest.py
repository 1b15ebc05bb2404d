"""One `drem build` per test session for the infra tests: it vendors the shared packages and installs the Lambda
wheels of requirements/lambda.txt into functions/vendor/ (the only step that downloads; packaging and synth don't)."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[2]
FUNCTIONS_DIR = REPO_ROOT / "functions"


@pytest.fixture(scope="session")
def lambda_build() -> Path:
    drem = Path(sys.executable).with_name("drem")
    build = subprocess.run([str(drem), "build"], cwd=REPO_ROOT, capture_output=True, text=True, timeout=600)
    assert build.returncode == 0, f"drem build failed:\n{build.stdout}\n{build.stderr}"
    return FUNCTIONS_DIR
