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


# The tiers, slowest files first. `make test` hands whole files to its workers in collection order
# (--dist loadfile --no-loadscope-reorder), so the long stack and browser files start early and the many short unit
# files fill the gaps at the end; xdist's own order (most tests first) left a 50 s single-test file running alone last.
SLOWEST_TIERS_FIRST = ("browser", "integration", "infra", "install", "cli", "cars", "sim", "unit", "domain")


def _tier_rank(item: pytest.Item) -> int:
    path, tests = Path(str(item.path)), REPO_ROOT / "tests"
    tier = path.relative_to(tests).parts[0] if path.is_relative_to(tests) else ""
    return SLOWEST_TIERS_FIRST.index(tier) if tier in SLOWEST_TIERS_FIRST else len(SLOWEST_TIERS_FIRST)


@pytest.hookimpl(trylast=True)
def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    items.sort(key=_tier_rank)  # stable: each file keeps its own order


@pytest.fixture(scope="session")
def repo_root() -> Path:
    return REPO_ROOT


@pytest.fixture(scope="session")
def tracks_dir() -> Path:
    if not TRACKS_DIR.is_dir():
        pytest.fail(f"shared DeepRacer tracks not found at {TRACKS_DIR}")
    return TRACKS_DIR

