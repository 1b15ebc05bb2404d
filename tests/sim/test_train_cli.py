"""`drem train` and `drem sim drive` through the real `drem` entry point."""
from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import urllib.request
from pathlib import Path

import pytest

from chalicelib.formats.model_archive.report import ArchiveStatus
from chalicelib.formats.model_archive.verdict import inspect_archive
from drem_local.cli import main
from tests import user_processes
from tests.waiting import wait_until

pytestmark = pytest.mark.sim


def test_train_turns_recorded_runs_into_an_archive(tmp_path: Path, capsys) -> None:
    assert main(["sim", "record", "--track", "drem_oval", "--laps", "1", "--out", str(tmp_path / "runs")]) == 0
    assert main(["train", "--runs", str(tmp_path / "runs"), "--out", str(tmp_path / "model"), "--name", "cli_bc",
                 "--epochs", "1", "--seed", "2"]) == 0

    out = capsys.readouterr()
    archive = tmp_path / "model" / "cli_bc.tar.gz"
    assert f"archive      {archive}" in out.out
    assert "epoch 1/1 [" in out.err  # the progress bar
    assert inspect_archive(archive).status == ArchiveStatus.AVAILABLE
    assert (tmp_path / "model" / "loss_curve.png").stat().st_size > 1000
    assert json.loads((tmp_path / "model" / "lineage.json").read_text())["seed"] == 2


def test_train_without_usable_runs_is_a_clear_error(tmp_path: Path, capsys) -> None:
    (tmp_path / "empty").mkdir()
    assert main(["train", "--runs", str(tmp_path / "empty"), "--out", str(tmp_path / "model")]) == 2
    assert f"no run folders under {tmp_path / 'empty'}" in capsys.readouterr().out


def test_drive_serves_the_page_until_interrupted(tmp_path: Path) -> None:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    command = [sys.executable, "-m", "drem_local.cli", "sim", "drive", "--track", "drem_oval", "--port", str(port),
               "--out", str(tmp_path)]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               env={**os.environ, "PYTHONUNBUFFERED": "1"}, preexec_fn=user_processes.from_a_shell)
    try:
        assert f"driving drem_oval at http://127.0.0.1:{port}/" in process.stdout.readline()
        def steps() -> int:
            with urllib.request.urlopen(f"http://127.0.0.1:{port}/state", timeout=5) as response:
                return int(json.loads(response.read())["steps"])

        first = steps()
        wait_until(lambda: steps() > first, 60, "the simulation to step on by itself (it runs in real time)")
    finally:
        process.send_signal(signal.SIGINT)
        try:
            _, err = process.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            pytest.fail(f"drem sim drive did not stop on Ctrl-C within 30 s: {user_processes.state(process.pid)}")
    assert process.returncode == 0, err


def test_drive_upload_without_a_local_stack_is_refused(capsys, monkeypatch, tmp_path: Path) -> None:
    monkeypatch.delenv("AWS_ENDPOINT_URL", raising=False)
    assert main(["sim", "drive", "--upload", "--out", str(tmp_path)]) == 2
    assert "AWS_ENDPOINT_URL" in capsys.readouterr().err
