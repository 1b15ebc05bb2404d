"""The local app server must run the source tree's packages even when a `drem build` left copies in functions/vendor."""
from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

pytestmark = pytest.mark.unit


def test_stale_vendor_copy_does_not_shadow_the_source_tree(repo_root, tmp_path):
    vendor = repo_root / "functions" / "vendor"
    script = textwrap.dedent(f"""
        import sys
        sys.path.append({str(vendor)!r})   # what Chalice's CLIFactory does
        from drem_local import appserver
        appserver._prefer_installed_packages()
        import drem_leaderboard.ranking, drem_web.render
        for mod in (drem_leaderboard.ranking, drem_web.render):
            assert "functions/vendor" not in mod.__file__, mod.__file__
        print("ok")
    """)
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "ok"
