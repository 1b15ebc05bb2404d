"""`drem car activate --aws` and `drem timer --aws`: a car or timer finds the deployment the way `drem export --aws`
does, in `.drem-aws/STAGE.json` as `make deploy` writes it (through `drem aws record`), instead of being given its URL.

Run as a user runs them: the installed `drem`, as a subprocess, from a folder outside the repository. The record is
written by the real `drem aws record` from CDK outputs whose public URL is the local stack's (standing in for
CloudFront's); what a user would notice is checked: the activation succeeds against that URL, `drem car status`
shows the server's view of the device through it, the timer says where it posts and its heartbeats arrive, and a
missing record says which file was looked for and what writes it.
"""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from drem_local.api_client import ApiClient
from tests.cli.test_installed_cli import drem, ok

pytestmark = pytest.mark.integration



def record_deployment(folder: Path, stage: str, public_url: str, outputs) -> None:
    """What `make deploy STAGE=stage` leaves in `folder`: `cdk deploy --outputs-file`, then `drem aws record`."""
    stack = {"Stage": stage, "Region": outputs.region, "UserPoolId": outputs.user_pool_id,
             "UserPoolClientId": outputs.user_pool_client_id,
             "DistributionUrl": "https://d111111abcdef8.cloudfront.net", "PublicUrl": public_url}
    stack.update({f"{k.capitalize()}TableName": v for k, v in outputs.tables.items()})
    stack.update({f"{k.capitalize()}BucketName": v for k, v in outputs.buckets.items()})
    (folder / ".drem-aws").mkdir(exist_ok=True)
    cdk_outputs = folder / ".drem-aws" / f"{stage}.cdk-outputs.json"
    cdk_outputs.write_text(json.dumps({f"drem-{stage}": stack}))
    ok(drem("aws", "record", "--stage", stage, "--outputs", str(cdk_outputs), cwd=folder))
    assert json.loads((folder / ".drem-aws" / f"{stage}.json").read_text())["public_url"] == public_url


@pytest.fixture(scope="module")
def admin(live_stack) -> ApiClient:
    api = ApiClient(live_stack.url)
    api.sign_in(live_stack.admin_username, live_stack.admin_password)
    return api


def activation_code(admin: ApiClient, hostname: str, kind: str) -> tuple[str, str]:
    """(fleet id, code): what staff hand the device (the console's Fleets page, or `drem cars activate-code`)."""
    fleet_id = admin.post("/api/fleets", {"name": f"fleet of {hostname}"})["fleet_id"]
    return fleet_id, admin.post("/api/devices/activation-codes",
                                {"fleet_id": fleet_id, "hostname": hostname, "device_kind": kind})["code"]


def test_a_car_activates_against_the_public_url_make_deploy_recorded(live_stack, admin, tmp_path: Path) -> None:
    deployed_from = tmp_path / "laptop"
    deployed_from.mkdir()
    record_deployment(deployed_from, "eventday", live_stack.url, live_stack.outputs)
    config = tmp_path / "car-config"
    _, code = activation_code(admin, "aws-car-1", "car")

    activated = ok(drem("car", "--config-dir", str(config), "activate", "--aws", "--stage", "eventday",
                        "--code", code, "--hostname", "aws-car-1", cwd=deployed_from))

    assert f"activated car aws-car-1 at {live_stack.url} as " in activated
    status = json.loads(ok(drem("car", "--config-dir", str(config), "status", cwd=deployed_from)))
    assert status["api"] == live_stack.url and status["hostname"] == "aws-car-1"
    assert status["server"]["device_id"] == status["device_id"], status  # the server answered as this car


def test_the_stage_defaults_to_drem_stage_as_for_export(live_stack, admin, tmp_path: Path) -> None:
    record_deployment(tmp_path, "fromenv", live_stack.url, live_stack.outputs)
    _, code = activation_code(admin, "aws-car-2", "car")

    activated = ok(drem("car", "--config-dir", str(tmp_path / "config"), "activate", "--aws", "--code", code,
                        "--hostname", "aws-car-2", cwd=tmp_path, env={"DREM_STAGE": "fromenv"}))

    assert f"activated car aws-car-2 at {live_stack.url} as " in activated


def test_a_timer_activates_and_posts_to_the_recorded_url_even_after_it_moved(live_stack, admin, tmp_path: Path):
    record_deployment(tmp_path, "timing", live_stack.url, live_stack.outputs)
    config = tmp_path / "timer-config"
    fleet_id, code = activation_code(admin, "aws-timer-1", "timer")
    ok(drem("car", "--config-dir", str(config), "activate", "--aws", "--stage", "timing", "--kind", "timer",
            "--code", code, "--hostname", "aws-timer-1", cwd=tmp_path))
    assert json.loads(ok(drem("car", "--config-dir", str(config), "status", cwd=tmp_path)))["server"][
        "last_seen_ms"] is None, "no heartbeat yet"
    event = admin.post("/api/events", {"name": "AWS Timer Cup", "event_type": "OFFICIAL_TRACK_RACE",
                                       "date": "2026-11-24", "country_code": "SE",
                                       "tracks": [{"track_id": "1", "fleet_id": fleet_id}]})
    # The deployment is now reached under another name (as after adding a custom domain): the same server.
    moved = live_stack.url.replace("127.0.0.1", "localhost")
    assert moved != live_stack.url
    record_deployment(tmp_path, "timing", moved, live_stack.outputs)

    # A laptop has no GPIO: gpiozero's mock pins stand in for the strips, the agent talks to the real stack.
    timed = ok(drem("timer", "--config-dir", str(config), "--aws", "--stage", "timing", "--event", event["event_id"],
                    "--seconds", "2", cwd=tmp_path, env={"GPIOZERO_PIN_FACTORY": "mock"}))

    assert f"posting to {moved}" in timed and "crossings queued 0" in timed, timed
    status = json.loads(ok(drem("car", "--config-dir", str(config), "status", cwd=tmp_path)))
    assert status["server"]["last_seen_ms"] is not None, "the timer's heartbeat reached the server"
    assert status["api"] == live_stack.url, "--aws overrides the saved URL for this run only"


def test_without_a_record_both_say_which_file_they_looked_for_and_what_writes_it(tmp_path: Path) -> None:
    expected = tmp_path / ".drem-aws" / "nowhere.json"
    car = drem("car", "--config-dir", str(tmp_path / "c"), "activate", "--aws", "--stage", "nowhere",
               "--code", "ABCD-EFGH", cwd=tmp_path)
    timer = drem("timer", "--config-dir", str(tmp_path / "c"), "--aws", "--stage", "nowhere", "--event", "e1",
                 cwd=tmp_path)
    default = drem("car", "--config-dir", str(tmp_path / "c"), "activate", "--aws", "--code", "ABCD-EFGH",
                   cwd=tmp_path)

    for result, command in ((car, "drem car activate"), (timer, "drem timer")):
        assert result.returncode == 1 and "Traceback" not in result.stderr, result.stderr
        assert result.stderr.startswith(f"{command}: no deployment record for stage 'nowhere'"), result.stderr
        assert f"looked for {expected}" in result.stderr and "make deploy STAGE=nowhere" in result.stderr
    assert default.returncode == 1 and f"looked for {tmp_path / '.drem-aws' / 'dev.json'}" in default.stderr
    assert "make deploy STAGE=dev" in default.stderr
    assert not (tmp_path / "c" / "credential.json").exists()


def test_a_record_without_a_public_url_is_refused(tmp_path: Path) -> None:
    (tmp_path / ".drem-aws").mkdir()
    (tmp_path / ".drem-aws" / "old.json").write_text(json.dumps({"stage": "old", "region": "eu-west-1"}))

    result = drem("car", "--config-dir", str(tmp_path / "c"), "activate", "--aws", "--stage", "old",
                  "--code", "ABCD-EFGH", cwd=tmp_path)

    assert result.returncode == 1 and "Traceback" not in result.stderr
    assert "holds no public URL" in result.stderr and "make deploy STAGE=old" in result.stderr


def test_activate_takes_exactly_one_of_api_and_aws(tmp_path: Path) -> None:
    neither = drem("car", "activate", "--code", "ABCD-EFGH", cwd=tmp_path)
    both = drem("car", "activate", "--code", "ABCD-EFGH", "--api", "http://127.0.0.1:9", "--aws", cwd=tmp_path)
    stage_alone = drem("car", "--config-dir", str(tmp_path / "c"), "activate", "--code", "ABCD-EFGH",
                       "--api", "http://127.0.0.1:9", "--stage", "dev", cwd=tmp_path)

    assert neither.returncode == 2 and "one of the arguments --api --aws is required" in neither.stderr
    assert both.returncode == 2 and "not allowed with argument" in both.stderr
    assert stage_alone.returncode == 1 and "--stage goes with --aws" in stage_alone.stderr
