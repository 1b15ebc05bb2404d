"""`drem build`: vendor the packages the Lambda bundle needs into functions/vendor/.

Chalice ships only app.py, chalicelib/ and the contents of vendor/, so the shared packages that live elsewhere in
the repo are copied there before `chalice package` or `cdk synth`. Each copy replaces the previous one entirely,
so a deleted or renamed module never lingers in a deployment.
"""
from __future__ import annotations

import argparse
import shutil
import sys
from dataclasses import dataclass
from pathlib import Path

HELP = ("copy drem_infra, drem_leaderboard, drem_web and the PDF fonts into functions/vendor/ for the Lambda bundle")

REPO_ROOT = Path(__file__).resolve().parents[3]
FUNCTIONS_DIR = REPO_ROOT / "functions"
HTMX_RELATIVE = Path("static/vendor/htmx.min.js")


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


def vendor_fonts(functions_dir: Path = FUNCTIONS_DIR) -> Path:
    """Copy the fonts the PDFs embed (installed from Debian packages, never committed) to vendor/drem_fonts/, which
    lands at the bundle root where `chalicelib.domain.pdf_fonts` looks first."""
    from chalicelib.domain.pdf_fonts import FONT_FILES, font_path

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
    from chalicelib.domain.errors import ServiceUnavailable

    try:
        copied = vendor_packages(args.functions_dir)
        copied.append(vendor_fonts(args.functions_dir))
    except (FileNotFoundError, ServiceUnavailable) as exc:
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
