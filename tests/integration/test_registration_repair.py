"""Storage killed (kill -9) right after a registration's account reached the journal, before its role group: the
running app repairs the half-registered racer by itself, without being restarted and without anyone registering
them again at the desk.

The kill point is reproduced exactly: the account is created in storage as the registration's first write would
create it (no profile, no group), then storage alone is killed and restarted; the app keeps running throughout.
"""
from __future__ import annotations

import pytest

from drem_local.stack import StackConfig, free_port, start_stack
from drem_local.storage_keys import load, local_client
from tests.waiting import wait_until

pytestmark = [pytest.mark.integration, pytest.mark.durability]


@pytest.fixture
def stack(tmp_path, monkeypatch):
    monkeypatch.setenv("DREM_REGISTRATION_REPAIR_S", "1")
    monkeypatch.setenv("DREM_REGISTRATION_IN_FLIGHT_S", "2")
    config = StackConfig(state_dir=tmp_path / "state", app_port=free_port(), storage_port=free_port(),
                         live_port=free_port())
    running = start_stack(config, "admin", "Repair-Admin-Pass-1!", timeout=120)
    yield running
    running.stop()


def test_a_storage_only_crash_mid_registration_is_repaired_while_the_app_runs(stack) -> None:
    config, pool_id = stack.config, stack.outputs.user_pool_id
    cognito = local_client("cognito-idp", config.storage_url, load(config.state_dir))
    cognito.admin_create_user(
        UserPoolId=pool_id, Username="cut-off", TemporaryPassword="Lost-Password-1!", MessageAction="SUPPRESS",
        UserAttributes=[{"Name": "email", "Value": "cut-off@example.test"},
                        {"Name": "custom:countryCode", "Value": "NL"}, {"Name": "email_verified", "Value": "true"}])
    app_pid = stack.app.pid
    stack.storage.kill_hard()
    stack.restart_storage(120)
    cognito = local_client("cognito-idp", config.storage_url, load(config.state_dir))

    def groups() -> list[str]:
        try:
            reply = cognito.admin_list_groups_for_user(UserPoolId=pool_id, Username="cut-off")
        except Exception:
            return []
        return [group["GroupName"] for group in reply["Groups"]]

    assert wait_until(groups, 120, "the running app to give the cut-off account its racer group") == ["racer"]
    assert stack.app.pid == app_pid and stack.app.alive()  # repaired by the app that kept running
