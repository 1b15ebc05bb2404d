"""Settings every test layer shares: a fake AWS identity that can never reach a real account."""
from __future__ import annotations

import logging
import os
from pathlib import Path

import pytest

pytest_plugins = ["tests.stack_fixtures"]

REPO_ROOT = Path(__file__).resolve().parent.parent
TRACKS_DIR = REPO_ROOT.parent / "shared" / "deepracer-tracks"

os.environ.update(
    AWS_DEFAULT_REGION="us-east-1",
    AWS_REGION="us-east-1",
    AWS_ACCESS_KEY_ID="testing",
    AWS_SECRET_ACCESS_KEY="testing",
    AWS_SECURITY_TOKEN="testing",
    AWS_SESSION_TOKEN="testing",
    AWS_ACCOUNT_ID_ENDPOINT_MODE="disabled",
)
# In-process tests must never talk to a server left configured by the shell.
for _name in [n for n in os.environ if n.startswith("AWS_ENDPOINT_URL")]:
    del os.environ[_name]
logging.getLogger("werkzeug").setLevel(logging.ERROR)


@pytest.fixture(scope="session")
def repo_root() -> Path:
    return REPO_ROOT


@pytest.fixture(scope="session")
def tracks_dir() -> Path:
    if not TRACKS_DIR.is_dir():
        pytest.fail(f"shared DeepRacer tracks not found at {TRACKS_DIR}")
    return TRACKS_DIR

