"""`drem build`: vendor everything the Lambda bundle needs into functions/vendor/.

Chalice ships only app.py, chalicelib/ and the contents of vendor/, so the shared packages that live elsewhere in
the repo are copied there before `chalice package` or `cdk synth`. Each copy replaces the previous one entirely,
so a deleted or renamed module never lingers in a deployment.

The third-party packages come from requirements/lambda.txt (exact versions and hashes of manylinux wheels for the
bundle's Python): pip installs them into vendor/ here, once, so packaging and synth never resolve or download
anything (the functions folder has no requirements.txt for Chalice to fetch). A stamp records which lock filled
vendor/; `cdk synth` refuses a stale one instead of downloading.
"""
from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from drem_infra.lambda_bundle import (
    DEPENDENCY_STAMP,
    LAMBDA_LOCK,
    dependencies_current,
    lock_digest,
    python_version,
    vendor_packages,
)
from drem_local.app_source import FUNCTIONS_DIR

HELP = ("copy drem_infra, drem_leaderboard, drem_web and the PDF fonts into functions/vendor/ for the Lambda bundle")

HTMX_RELATIVE = Path("static/vendor/htmx.min.js")
# Lambda's python3.11 runs on x86_64 Amazon Linux 2 (glibc 2.26): manylinux2014 (glibc 2.17) wheels, which the lock
# was resolved for. Chalice picks the function's runtime from the Python that packages it, so the wheels are for this
# interpreter's version.
LAMBDA_PLATFORMS = ("manylinux2014_x86_64",)


class BuildError(RuntimeError):
    """The bundle could not be built; the message says why and what to do."""


def vendor_dependencies(functions_dir: Path = FUNCTIONS_DIR, lock: Path = LAMBDA_LOCK) -> list[str]:
    """Install the lock's wheels for Lambda into vendor/ (replacing the previous set); returns the top-level names."""
    import json

    vendor = functions_dir / "vendor"
    vendor.mkdir(parents=True, exist_ok=True)
    stamp = vendor / DEPENDENCY_STAMP
    with tempfile.TemporaryDirectory(prefix="drem-lambda-deps-") as scratch:
        target = Path(scratch) / "site"
        command = [sys.executable, "-m", "pip", "install", "--quiet", "--disable-pip-version-check", "--no-compile",
                   "--target", str(target), "--implementation", "cp", "--python-version", python_version(),
                   "--only-binary=:all:", "--no-deps", "--require-hashes", "-r", str(lock)]
        for platform in LAMBDA_PLATFORMS:
            command[4:4] = ["--platform", platform]
        done = subprocess.run(command, capture_output=True, text=True)
        if done.returncode != 0:
            raise BuildError(f"installing {lock.name} for Lambda failed:\n{done.stderr.strip()[-2000:]}")
        try:
            previous = json.loads(stamp.read_text()).get("installed", [])
        except (OSError, ValueError):
            previous = []
        for name in previous:
            _remove(vendor / name)
        installed = sorted(p.name for p in target.iterdir() if p.name not in ("bin", "__pycache__"))
        for name in installed:
            _remove(vendor / name)
            shutil.move(str(target / name), vendor / name)
    stamp.write_text(json.dumps({"lock_sha256": lock_digest(lock), "python": python_version(),
                                 "installed": installed}, indent=1) + "\n")
    return installed


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    elif path.exists() or path.is_symlink():
        path.unlink()


def vendor_fonts(functions_dir: Path = FUNCTIONS_DIR) -> Path:
    """Copy the fonts the PDFs embed (installed from Debian packages, never committed) to vendor/drem_fonts/, which
    lands at the bundle root where `chalicelib.formats.pdf_fonts` looks first."""
    from chalicelib.formats.pdf_fonts import FONT_FILES, font_path

    fonts = {name: font_path(name).read_bytes() for name in sorted(set(FONT_FILES.values()))}  # before the rmtree
    target = functions_dir / "vendor" / "drem_fonts"
    if target.exists():
        shutil.rmtree(target)
    target.mkdir(parents=True)
    for name, data in fonts.items():
        (target / name).write_bytes(data)
    return target


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--functions-dir", type=Path, default=FUNCTIONS_DIR,
                        help="the Chalice project to vendor into (default: %(default)s)")


def run(args: argparse.Namespace) -> int:
    from chalicelib.core.errors import ServiceUnavailable

    try:
        copied = vendor_packages(args.functions_dir)
        if dependencies_current(args.functions_dir):
            print(f"dependencies in {args.functions_dir / 'vendor'} match {LAMBDA_LOCK.name}: nothing to install")
        else:
            installed = vendor_dependencies(args.functions_dir)
            print(f"vendored {len(installed)} dependency folders from {LAMBDA_LOCK.name} (Lambda wheels)")
        copied.append(vendor_fonts(args.functions_dir))
    except (FileNotFoundError, BuildError, ServiceUnavailable) as exc:
        print(f"drem build: {exc}", file=sys.stderr)
        return 1
    for target in copied:
        files = sum(1 for p in target.rglob("*") if p.is_file())
        print(f"vendored {target.name}: {files} files -> {target}")
    htmx = args.functions_dir / "vendor" / "drem_web" / HTMX_RELATIVE
    if not htmx.is_file():
        print(f"drem build: warning: {HTMX_RELATIVE} is missing, pages will load without htmx; "
              "run `make install` (npm ci + copy) first", file=sys.stderr)
    return 0
