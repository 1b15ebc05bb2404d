"""`drem league push` as a racer runs it: the installed `drem`, from outside the repository, with the files the racer
has (a DROA logs archive whose names hold ':'; a console logs download without model_metadata.json plus the
console's model download). The CLI only packs and uploads; the live stack assembles and ranks. (A model that drem
re-drives, pushed the same way, is tests/integration/test_event_day_cli.py's drem sample.)"""
from __future__ import annotations

import io
import json
import re
import tarfile
from pathlib import Path

import pytest
import requests

from tests.cli.test_installed_cli import drem, ok
from tests.unit.league_helpers import DISCRETE_METADATA, console_old_export, droa_export, tar_gz_of

pytestmark = pytest.mark.integration


def _model_download(path: Path) -> Path:
    """The console's model download: model_metadata.json and agent/model.pb at the root (deepracer-formats.md §1.2)."""
    with tarfile.open(path, "w:gz") as archive:
        for name, data in (("model_metadata.json", json.dumps(DISCRETE_METADATA).encode()),
                           ("agent/model.pb", b"\x08\x01frozen-graph-placeholder")):
            info = tarfile.TarInfo(name)
            info.size = len(data)
            archive.addfile(info, io.BytesIO(data))
    return path


def test_dry_run_lists_only_the_files_the_server_reads(tmp_path: Path) -> None:
    folder = droa_export(tmp_path / "indy", world="Spain_track", eval_world="Spain_track", laps=[(31000, 100)])
    archive = tar_gz_of(folder, tmp_path / "indy.tar.gz", top="indy")
    model = _model_download(tmp_path / "indy-model.tar.gz")
    listed = ok(drem("league", "push", str(archive), str(model), "--track", "Spain_track", "--dry-run",
                     cwd=tmp_path)).splitlines()
    assert "metrics/evaluation/2026-03-07T17:52:00.898Z-deepracerindy-evaluation-9oJ3QbS0SYm7Iag.json" in listed
    assert "model_metadata.json" in listed and "agent/model.pb" not in listed
    assert listed[-1].startswith(f"{len(listed) - 1} files") and "for indy on Spain_track" in listed[-1]


def test_console_logs_and_model_download_pushed_together(live_stack, tmp_path: Path) -> None:
    logs = console_old_export(tmp_path / "console-logs", world="reinvent_base", laps=[(14321, 100), (9000, 40)])
    (logs / "model/model_metadata.json").unlink()  # the console's logs download has none
    env = {"DREM_API": live_stack.url, "DREM_USERNAME": live_stack.admin_username,
           "DREM_PASSWORD": live_stack.admin_password}
    alone = drem("league", "push", str(logs), "--track", "reinvent_base", cwd=tmp_path, env=env)
    assert alone.returncode == 1 and "model/model_metadata.json: missing" in alone.stderr
    assert "model download" in alone.stderr
    model = _model_download(tmp_path / "console-model.tar.gz")
    # Its agent/model.pb is a placeholder, not a graph: no car could load it (the upload says NOT_VALID), so drem
    # cannot re-drive it, and says so before anything is ranked.
    refused = drem("league", "push", str(logs), str(model), "--track", "reinvent_base", cwd=tmp_path, env=env)
    assert refused.returncode == 1 and "was not accepted as a model" in refused.stderr, refused.stderr
    assert "a stock car cannot load this model" in refused.stderr
    assert "--self-reported" in refused.stderr
    pushed = ok(drem("league", "push", str(logs), str(model), "--track", "reinvent_base", "--self-reported",
                     cwd=tmp_path, env=env))
    assert "pushed console-logs" in pushed and "1/2 laps, best 14.321 s" in pushed
    board = requests.get(live_stack.url + "/api/league/reinvent_base", timeout=10).json()
    assert any(ranked["entry"]["best_lap_s"] == 14.321 for ranked in board["entries"]), board


def test_league_pull_names_racers_by_display_name_and_tells_two_bjorns_apart(live_stack, tmp_path: Path) -> None:
    """Issue 31: `drem league pull` printed sign-in names. Now the table's racer column shows display names, two
    racers both called Björn as "Björn (cli_bjorn_a)" and "björn (cli_bjorn_b)" (the board page's rule)."""
    url = live_stack.url
    env = {"DREM_API": url, "DREM_USERNAME": live_stack.admin_username, "DREM_PASSWORD": live_stack.admin_password}
    bearer = {"Authorization": "Bearer " + requests.post(url + "/api/auth/token", timeout=10, json={
        "username": live_stack.admin_username, "password": live_stack.admin_password}).json()["access_token"]}
    racers = {"cli_bjorn_a": "Björn", "cli_bjorn_b": "björn", "cli_yamada": "山田太郎"}
    for index, (username, name) in enumerate(racers.items()):
        made = requests.post(url + "/api/users", headers=bearer, timeout=15, json={
            "username": username, "email": f"{username}@example.test", "country_code": "SE", "display_name": name})
        assert made.status_code in (200, 201), made.text
        logs = droa_export(tmp_path / username, world="AWS_track", eval_world="AWS_track",
                           laps=[(40000 + 1000 * index, 100)])
        ok(drem("league", "push", str(logs), "--track", "AWS_track", "--racer", username, "--self-reported",
                cwd=tmp_path, env=env))

    table = ok(drem("league", "pull", "--track", "AWS_track", cwd=tmp_path, env=env)).splitlines()
    shown = [re.split(r"\s{2,}", line.strip())[1] for line in table[2:] if line.strip()]
    assert shown == ["Björn (cli_bjorn_a)", "björn (cli_bjorn_b)", "山田太郎"], table
