"""`drem aws check`, which `make deploy` runs before building anything: the installed CLI from outside the repository,
on a laptop missing what a deploy needs (each problem one sentence saying what to do), and on one that has it all
(credentials checked against a local STS, moto's, never a real account)."""
from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

from drem_local import aws_preflight
from tests.cli.test_installed_cli import REPO_ROOT, drem

pytestmark = pytest.mark.integration


def fake_tools(folder: Path, *, node: str, docker_engine: str | None) -> dict[str, str]:
    """A PATH whose `node` prints `node` and whose `docker info` prints the engine's version (or fails: no engine)."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "node").write_text(f"#!/bin/sh\necho {node}\n")
    docker = f"echo {docker_engine}" if docker_engine else "echo 'Cannot connect to the Docker daemon' >&2; exit 1"
    (folder / "docker").write_text(f"#!/bin/sh\n{docker}\n")
    for tool in ("node", "docker"):
        (folder / tool).chmod(0o755)
    return {"PATH": f"{folder}:/usr/bin:/bin"}


def no_aws_configuration(home: Path) -> dict[str, str]:
    return {"HOME": str(home), "AWS_SHARED_CREDENTIALS_FILE": str(home / "none"), "AWS_CONFIG_FILE": str(home / "none"),
            "AWS_ACCESS_KEY_ID": "", "AWS_SECRET_ACCESS_KEY": "", "AWS_SESSION_TOKEN": "", "AWS_SECURITY_TOKEN": "",
            "AWS_REGION": "", "AWS_DEFAULT_REGION": "", "AWS_PROFILE": ""}


def run_check(tmp_path: Path, env: dict[str, str]) -> subprocess.CompletedProcess:
    outside = tmp_path / "laptop"
    outside.mkdir(exist_ok=True)
    full = {k: v for k, v in os.environ.items() if not k.startswith("AWS_") and k not in ("PYTHONPATH", "DREM_STAGE")}
    full.update({k: v for k, v in env.items() if v})  # an empty AWS_* is left out: botocore would read it as set
    return subprocess.run([str(REPO_ROOT / ".venv" / "bin" / "drem"), "aws", "check"], cwd=outside, env=full,
                          capture_output=True, text=True, timeout=120)


def test_a_laptop_missing_what_a_deploy_needs_hears_each_problem_in_one_sentence(tmp_path: Path) -> None:
    env = {**no_aws_configuration(tmp_path), **fake_tools(tmp_path / "bin", node="v20.11.1", docker_engine=None)}

    result = run_check(tmp_path, env)

    assert result.returncode == 1, result.stdout + result.stderr
    assert "Traceback" not in result.stderr
    lines = {line.split(":", 1)[0].removeprefix("NO").strip(): line for line in result.stdout.splitlines()
             if line.startswith("NO ")}
    assert set(lines) == {"credentials", "region", "node", "docker"}, result.stdout
    assert "run `aws configure`" in lines["credentials"]
    assert "export AWS_DEFAULT_REGION=" in lines["region"]
    assert "v20.11.1 is not supported" in lines["node"] and "Node.js 22 LTS" in lines["node"]
    assert "engine is not running" in lines["docker"]
    assert "4 problems to fix before deploying" in result.stderr


def test_a_laptop_with_everything_is_ready_to_deploy(tmp_path: Path) -> None:
    from moto.server import ThreadedMotoServer

    server = ThreadedMotoServer(ip_address="127.0.0.1", port=0)
    server.start()
    try:
        host, port = server.get_host_and_port()
        env = {**no_aws_configuration(tmp_path), **fake_tools(tmp_path / "bin", node="v22.12.0",
                                                                docker_engine="28.2.2"),
               "AWS_ACCESS_KEY_ID": "testing", "AWS_SECRET_ACCESS_KEY": "testing", "AWS_REGION": "eu-west-1",
               "AWS_ENDPOINT_URL_STS": f"http://{host}:{port}"}
        result = run_check(tmp_path, env)
    finally:
        server.stop()

    assert result.returncode == 0, result.stdout + result.stderr
    assert "ok  credentials: AWS account 123456789012" in result.stdout
    assert "ok  region: AWS region: eu-west-1." in result.stdout
    assert "Ready to deploy." in result.stdout


def test_missing_flag_images_and_fonts_are_named_with_what_to_run(tmp_path: Path, monkeypatch) -> None:
    (tmp_path / "static" / "vendor").mkdir(parents=True)
    assets = aws_preflight.web_assets(tmp_path / "static")
    assert not assets.ok and "The flag images and htmx are missing" in assets.sentence
    assert "`make install`" in assets.sentence

    import chalicelib.formats.pdf_fonts as pdf_fonts

    monkeypatch.setattr(pdf_fonts, "search_dirs", lambda: (tmp_path,))
    fonts = aws_preflight.pdf_fonts()
    assert not fonts.ok and "fonts-noto-core fonts-droid-fallback fonts-nanum" in fonts.sentence


def test_make_deploy_checks_before_it_builds_and_installs_no_torch(tmp_path: Path) -> None:
    """The deploy recipe, as make would run it: the check comes first, and the venv it syncs is the deploy lock."""
    planned = subprocess.run(["make", "-n", "--no-print-directory", "deploy", "STAGE=check", "WHEELS=/nonexistent"],
                             cwd=REPO_ROOT, capture_output=True, text=True, timeout=60,
                             env={**os.environ, "MAKEFLAGS": ""})
    commands = planned.stdout
    assert commands.index("drem aws check") < commands.index("drem build") < commands.index(".bin/cdk bootstrap")
    assert "/nonexistent" not in commands, "a wheel folder that does not exist is never handed to the installer"
    lock = (REPO_ROOT / "requirements" / "deploy.txt").read_text()
    assert "\naws-cdk-lib==" in lock and "\ntorch==" not in lock and "\npytest==" not in lock


def test_every_subcommand_help_mentions_check() -> None:
    result = drem("aws", "--help", cwd=Path("/tmp"))
    assert result.returncode == 0 and "check" in result.stdout
