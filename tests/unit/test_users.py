"""Staff registration, user listing, roles, disabling and self-delete, through the JSON API with real moto tokens."""
from __future__ import annotations

import pytest

from chalicelib.core.errors import InvalidCredentials
from tests.unit.conftest import PASSWORD
from tests.unit.users_helpers import call, error_message, groups_claim, sign_up_body

pytestmark = pytest.mark.unit


def _register(client, token, username="walk_in-1", **changes):
    body = {"username": username, "email": f"{username}@example.test", "country_code": "NL", **changes}
    return call(client, "POST", "/api/users", body, token=token)


def test_registration_staff_create_a_racer_with_a_temporary_password(client, users, aws_clients, stack):
    staff = users.access_token("desk", ("registration",))
    status, body = _register(client, staff)
    assert status == 201, body
    assert body["username"] == "walk_in-1" and body["role"] == "racer"
    temporary = body["temporary_password"]

    reply = aws_clients.cognito.initiate_auth(
        AuthFlow="USER_PASSWORD_AUTH", ClientId=stack.user_pool_client_id,
        AuthParameters={"USERNAME": "walk_in-1", "PASSWORD": temporary})
    assert reply["ChallengeName"] == "NEW_PASSWORD_REQUIRED"
    groups = aws_clients.cognito.admin_list_groups_for_user(UserPoolId=stack.user_pool_id, Username="walk_in-1")
    assert [g["GroupName"] for g in groups["Groups"]] == ["racer"]

    status, profile = call(client, "GET", "/api/profiles/walk_in-1")
    assert status == 200 and profile["country_code"] == "NL"


def test_racers_and_anonymous_cannot_register_others(client, users):
    racer = users.access_token("racer1", ("racer",))
    assert _register(client, racer)[0] == 403
    assert call(client, "POST", "/api/users", {"username": "x", "email": "x@example.test", "country_code": "NL"})[0] \
        in (401, 403)


def test_a_taken_name_is_a_409_that_says_so(client, users):
    admin = users.access_token("boss", ("admin",))
    assert _register(client, admin, "dup")[0] == 201
    status, body = _register(client, admin, "dup", email="someone-else@example.test")
    assert status == 409
    assert error_message(body) == "The user name 'dup' is taken."


def _crash_after_the_account_step(aws_clients, stack, username: str) -> None:
    """What an interrupted registration leaves: the Cognito account only (no profile, no racer group)."""
    aws_clients.cognito.admin_create_user(
        UserPoolId=stack.user_pool_id, Username=username, TemporaryPassword="Lost-Password-1!",
        MessageAction="SUPPRESS",
        UserAttributes=[{"Name": "email", "Value": f"{username}@example.test"},
                        {"Name": "custom:countryCode", "Value": "NL"}, {"Name": "email_verified", "Value": "true"}])


def test_registering_again_finishes_an_interrupted_registration_and_shows_a_new_password(client, users, aws_clients,
                                                                                        stack):
    admin = users.access_token("boss", ("admin",))
    _crash_after_the_account_step(aws_clients, stack, "half")

    status, body = _register(client, admin, "half")
    assert status == 201, body
    assert body["resumed"] is True and body["role"] == "racer"
    reply = aws_clients.cognito.initiate_auth(
        AuthFlow="USER_PASSWORD_AUTH", ClientId=stack.user_pool_client_id,
        AuthParameters={"USERNAME": "half", "PASSWORD": body["temporary_password"]})
    assert reply["ChallengeName"] == "NEW_PASSWORD_REQUIRED"
    groups = aws_clients.cognito.admin_list_groups_for_user(UserPoolId=stack.user_pool_id, Username="half")
    assert [g["GroupName"] for g in groups["Groups"]] == ["racer"]
    assert call(client, "GET", "/api/profiles/half")[0] == 200
    # A retry whose first answer was lost (the registration had finished) also shows a password that works.
    status, again = _register(client, admin, "half")
    assert status == 201 and again["temporary_password"] != body["temporary_password"]


def test_a_racer_who_has_signed_in_is_never_re_registered(client, users):
    admin = users.access_token("boss", ("admin",))
    users.create("settled", ("racer",))  # a confirmed account with its own password
    status, body = _register(client, admin, "settled", email="settled@example.test")
    assert status == 409 and error_message(body) == "The user name 'settled' is taken."


def test_start_up_repair_finishes_interrupted_registrations(client, users, aws_clients, stack):
    from chalicelib import services

    users.create("complete", ("racer",))
    _crash_after_the_account_step(aws_clients, stack, "cutoff")

    assert services.user_service().finish_interrupted_registrations() == ["cutoff"]
    groups = aws_clients.cognito.admin_list_groups_for_user(UserPoolId=stack.user_pool_id, Username="cutoff")
    assert [g["GroupName"] for g in groups["Groups"]] == ["racer"]
    assert call(client, "GET", "/api/profiles/cutoff")[0] == 200
    assert services.user_service().finish_interrupted_registrations() == []


def test_staff_username_rule_and_country_are_checked(client, users):
    admin = users.access_token("boss", ("admin",))
    status, body = _register(client, admin, "space name")
    assert status == 400 and body["error"]["field"] == "username"
    assert "letters a–z and A–Z, digits, '.', '_' and '-'" in error_message(body)
    status, body = _register(client, admin, "ok-name", country_code="XX")
    assert status == 400 and body["error"]["field"] == "country_code"


def test_listing_searches_by_prefix_and_pages(client, users):
    admin = users.access_token("boss", ("admin",))
    for name in ("team-a1", "team-a2", "team-a3", "other"):
        users.create(name, ("racer",))
    status, body = call(client, "GET", "/api/users?prefix=team-", token=admin)
    assert status == 200
    assert sorted(u["username"] for u in body["users"]) == ["team-a1", "team-a2", "team-a3"]
    assert "temporary_password" not in body["users"][0]

    seen, next_token = [], None
    for _ in range(5):
        query = "/api/users?limit=2" + (f"&next={next_token}" if next_token else "")
        status, body = call(client, "GET", query, token=admin)
        assert status == 200 and len(body["users"]) <= 2
        seen += [u["username"] for u in body["users"]]
        next_token = body["next_token"]
        if not next_token:
            break
    assert sorted(seen) == ["boss", "other", "team-a1", "team-a2", "team-a3"]


def test_who_may_list_users(client, users):
    for name, group in (("op", "operator"), ("desk", "registration")):
        assert call(client, "GET", "/api/users", token=users.access_token(name, (group,)))[0] == 200
    for name, group in (("mic", "commentator"), ("r1", "racer")):
        assert call(client, "GET", "/api/users", token=users.access_token(name, (group,)))[0] == 403
    status, body = call(client, "GET", "/api/users?prefix=%22%20or", token=users.access_token("boss", ("admin",)))
    assert status == 400 and body["error"]["field"] == "prefix"


def test_role_change_leaves_exactly_one_group_and_the_new_token_carries_it(client, users, aws_clients, stack):
    admin = users.access_token("boss", ("admin",))
    users.create("multi", ("racer", "commentator"))
    status, body = call(client, "PUT", "/api/users/multi/role", {"role": "operator"}, token=admin)
    assert status == 200, body
    groups = aws_clients.cognito.admin_list_groups_for_user(UserPoolId=stack.user_pool_id, Username="multi")
    assert [g["GroupName"] for g in groups["Groups"]] == ["operator"]
    assert groups_claim(users.sign_in("multi")["AccessToken"]) == ["operator"]


def test_role_change_rules(client, users):
    admin = users.access_token("boss", ("admin",))
    users.create("someone", ("racer",))
    status, body = call(client, "PUT", "/api/users/someone/role", {"role": "car"}, token=admin)
    assert status == 400 and body["error"]["field"] == "role"
    assert call(client, "PUT", "/api/users/boss/role", {"role": "racer"}, token=admin)[0] == 403
    assert call(client, "PUT", "/api/users/nobody/role", {"role": "racer"}, token=admin)[0] == 404
    operator = users.access_token("op", ("operator",))
    assert call(client, "PUT", "/api/users/someone/role", {"role": "admin"}, token=operator)[0] == 403


def test_disabled_users_cannot_sign_in_until_enabled(client, users):
    from chalicelib import services

    admin = users.access_token("boss", ("admin",))
    users.create("troublemaker", ("racer",))
    status, body = call(client, "POST", "/api/users/troublemaker/disable", token=admin)
    assert status == 200 and body["enabled"] is False
    with pytest.raises(InvalidCredentials):
        services.identity_provider().sign_in("troublemaker", PASSWORD)
    assert call(client, "POST", "/api/users/troublemaker/enable", token=admin)[0] == 200
    assert services.identity_provider().sign_in("troublemaker", PASSWORD).access_token
    assert call(client, "POST", "/api/users/boss/disable", token=admin)[0] == 403


def test_self_delete_needs_the_username_or_password(client, users):
    token = users.access_token("careful", ("racer",))
    status, body = call(client, "DELETE", "/api/me", {"confirm": "not me"}, token=token)
    assert status == 400 and body["error"]["field"] == "confirm"
    assert users.sign_in("careful")["AccessToken"]
    status, body = call(client, "DELETE", "/api/me", {"confirm": PASSWORD}, token=token)
    assert status == 200 and body["deleted"] == "careful"


def test_self_delete_removes_the_account_and_anonymises_the_profile(client, users, aws_clients, stack):
    from chalicelib import services

    assert call(client, "POST", "/api/signup", sign_up_body("leaving"))[1]["confirmed"] is True  # local: at once
    token = users.sign_in("leaving")["AccessToken"]
    status, own = call(client, "PUT", "/api/me/profile", {"highlight_colour": "#FF0000"}, token=token)
    assert status == 200
    sub = own["sub"]

    status, body = call(client, "DELETE", "/api/me", {"confirm": "Leaving"}, token=token)
    assert status == 200, body
    with pytest.raises(aws_clients.cognito.exceptions.UserNotFoundException):
        aws_clients.cognito.admin_get_user(UserPoolId=stack.user_pool_id, Username="leaving")
    assert call(client, "GET", "/api/profiles/leaving")[0] == 404
    assert call(client, "GET", "/api/profiles/leaving/avatar.svg")[0] == 404
    # The access token is revoked with the account (chalicelib.auth.revocation): it cannot resurrect the profile.
    assert call(client, "GET", "/api/me/profile", token=token)[0] == 401

    shown = services.profile_service().public_by_sub(sub)
    assert shown.deleted and shown.username == f"Deleted racer {sub.replace('-', '')[:4]}"
    assert (shown.country_code, shown.highlight_colour, shown.avatar_url) == (None, None, None)


def test_self_delete_removes_the_racers_models(client, users, aws_clients, stack):
    from chalicelib import services
    from chalicelib.domain.racer_models import ModelRecord, ModelStatus, model_key

    token = users.access_token("modeller", ("racer",))
    sub = call(client, "GET", "/api/me", token=token)[1]["sub"]
    service = services.model_service()
    key = model_key(sub, "m1")
    aws_clients.s3.put_object(Bucket=stack.buckets["models"], Key=key, Body=b"archive")
    service.store.create(ModelRecord(model_id="m1", owner_sub=sub, owner_username="modeller", name="fast",
                                     status=ModelStatus.AVAILABLE, uploaded_at="2026-01-01T00:00:00Z",
                                     updated_at="2026-01-01T00:00:00Z", upload_key=f"uploads/{sub}/m1.tar.gz",
                                     s3_key=key))

    status, body = call(client, "DELETE", "/api/me", {"confirm": "modeller"}, token=token)
    assert status == 200 and body["items_erased"] == 1
    record = service.store.get(sub, "m1")
    assert record.status is ModelStatus.DELETED and record.owner_username.startswith("Deleted racer ")
    listed = aws_clients.s3.list_objects_v2(Bucket=stack.buckets["models"]).get("Contents", [])
    assert listed == []


def test_self_delete_also_erases_models_the_racer_had_already_deleted(client, users, aws_clients, stack):
    from chalicelib import services
    from chalicelib.domain.racer_models import ModelStatus
    from tests.unit.models_helpers import ModelsApi, onnx_archive
    from tests.unit.models_helpers import bearer as json_bearer

    token = users.access_token("binned", ("racer",))
    racer = ModelsApi(client, json_bearer(token))
    kept = racer.upload_and_complete("kept.tar.gz", onnx_archive(0.1))
    binned = racer.upload_and_complete("binned.tar.gz", onnx_archive(0.2))
    assert racer.delete(binned["model_id"]).status_code == 200  # soft delete: the archive stays in the bucket
    bucket = stack.buckets["models"]
    assert len(aws_clients.s3.list_objects_v2(Bucket=bucket).get("Contents", [])) >= 2
    sub = call(client, "GET", "/api/me", token=token)[1]["sub"]

    status, body = call(client, "DELETE", "/api/me", {"confirm": "binned"}, token=token)

    assert status == 200 and body["items_erased"] == 2, body
    assert aws_clients.s3.list_objects_v2(Bucket=bucket).get("Contents", []) == []
    store = services.model_service().store
    for model in (kept, binned):
        record = store.get(sub, model["model_id"])
        assert record.status is ModelStatus.DELETED and record.owner_username.startswith("Deleted racer ")


def test_the_running_repair_leaves_a_registration_that_may_still_be_in_flight_and_repairs_it_later(
        client, users, aws_clients, stack):
    from datetime import UTC, datetime, timedelta

    from chalicelib import services

    users.create("complete", ("racer",))
    _crash_after_the_account_step(aws_clients, stack, "storage-cut")  # a storage-only crash: the app never restarts
    service = services.user_service()

    assert service.finish_interrupted_registrations(older_than_s=30) == []  # created just now: maybe still running
    later = datetime.now(UTC) + timedelta(seconds=31)
    assert service.finish_interrupted_registrations(older_than_s=30, now=later) == ["storage-cut"]
    groups = aws_clients.cognito.admin_list_groups_for_user(UserPoolId=stack.user_pool_id, Username="storage-cut")
    assert [g["GroupName"] for g in groups["Groups"]] == ["racer"]
    assert service.finish_interrupted_registrations(older_than_s=30, now=later) == []
