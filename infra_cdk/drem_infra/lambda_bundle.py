"""What the Lambda bundle holds besides the app: drem's own packages copied into functions/vendor/, and the stamp
that says which lock's wheels are there.

Both `drem build` (drem_local.commands.build, which also installs the wheels) and the CDK app (infra_cdk/app.py,
which refuses a stale vendor/ and never downloads) use this module, so the CDK app needs nothing of the CLI.
Standard library only: the CDK app imports it before anything else is set up.
"""
from __future__ import annotations

import hashlib
import json
import shutil
import sys
from dataclasses import dataclass
from pathlib import Path

# drem is installed editable from its clone: infra_cdk/drem_infra/ sits in the repository beside functions/.
REPO_ROOT = Path(__file__).resolve().parents[2]
FUNCTIONS_DIR = REPO_ROOT / "functions"
LAMBDA_LOCK = REPO_ROOT / "requirements" / "lambda.txt"
# Which lock filled vendor/ with wheels (its sha256), and which top-level names those wheels installed.
DEPENDENCY_STAMP = ".drem-dependencies.json"


@dataclass(frozen=True)
class VendoredPackage:
    name: str
    source: Path
    # None copies the whole package; otherwise only these files (drem_infra's stack.py imports aws_cdk, which
    # Lambda neither has nor needs).
    only: tuple[str, ...] | None = None


def packages(repo_root: Path = REPO_ROOT) -> tuple[VendoredPackage, ...]:
    return (
        VendoredPackage("drem_infra", repo_root / "infra_cdk" / "drem_infra", only=("__init__.py", "resources.py")),
        VendoredPackage("drem_leaderboard", repo_root / "leaderboard" / "drem_leaderboard"),
        VendoredPackage("drem_archive", repo_root / "archive" / "drem_archive"),
        VendoredPackage("drem_web", repo_root / "web" / "drem_web"),
    )


def vendor_packages(functions_dir: Path = FUNCTIONS_DIR, repo_root: Path = REPO_ROOT) -> list[Path]:
    """Replace functions_dir/vendor/<package> with a fresh copy of each package; returns the copied dirs."""
    vendor = functions_dir / "vendor"
    vendor.mkdir(parents=True, exist_ok=True)
    copied = []
    for package in packages(repo_root):
        if not (package.source / "__init__.py").is_file():
            raise FileNotFoundError(f"package {package.name} not found at {package.source}")
        target = vendor / package.name
        if target.exists():
            shutil.rmtree(target)
        if package.only is None:
            shutil.copytree(package.source, target, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
        else:
            target.mkdir()
            for name in package.only:
                shutil.copy2(package.source / name, target / name)
        copied.append(target)
    return copied


def lock_digest(lock: Path = LAMBDA_LOCK) -> str:
    return hashlib.sha256(lock.read_bytes()).hexdigest()


def dependencies_current(functions_dir: Path = FUNCTIONS_DIR, lock: Path = LAMBDA_LOCK) -> bool:
    """True when vendor/ holds exactly the wheels of this lock for this Python (no download needed)."""
    stamp = functions_dir / "vendor" / DEPENDENCY_STAMP
    try:
        recorded = json.loads(stamp.read_text())
    except (OSError, ValueError):
        return False
    return recorded.get("lock_sha256") == lock_digest(lock) and recorded.get("python") == python_version()


def python_version() -> str:
    return f"{sys.version_info.major}.{sys.version_info.minor}"
