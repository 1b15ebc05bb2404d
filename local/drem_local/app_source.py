"""The one way the local stack and the CLI reach the Chalice app's code (app.py and chalicelib/).

chalicelib is deliberately not installed into site-packages: Chalice bundles it from functions/ and imports it from
there, and so do we. drem is installed editable from its clone, so functions/ sits beside local/, this package's
folder, in the repository.
Every `drem` command that needs the app's domain code calls `use_app_source()` first (cli.main does it for all), so
the installed command works from any directory, not only where pytest's `pythonpath` happens to add functions/.
"""
from __future__ import annotations

import sys
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[2]
FUNCTIONS_DIR = REPO_ROOT / "functions"


def use_app_source() -> Path:
    """Make `import chalicelib` (and `import app`) resolve to functions/; idempotent. Returns functions/."""
    if not (FUNCTIONS_DIR / "chalicelib").is_dir():
        raise RuntimeError(f"drem's app code is not at {FUNCTIONS_DIR}/chalicelib: reinstall drem from its clone "
                           "(make install)")
    if str(FUNCTIONS_DIR) not in sys.path:
        sys.path.insert(0, str(FUNCTIONS_DIR))
    return FUNCTIONS_DIR
