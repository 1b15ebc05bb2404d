"""Staff screens over HTTP (Chalice test client + moto): registration desk, user admin, all models and giving
models to cars. Each test checks what the page shows, what changed behind it, and who is refused."""
from __future__ import annotations

import json
from typing import Any
from urllib.parse import quote

import pytest
from markupsafe import escape

from chalicelib.domain.names import USERNAME_CHARS_MESSAGE, USERNAME_LENGTH_MESSAGE
from tests.unit.models_helpers import (
    ModelsApi,
    activate_device,
    archive_without_metadata,
    bearer,
    device_headers,
    make_fleet,
    onnx_archive,
)
from tests.unit.racer_console_helpers import body, field_error, post, signed_in, text

pytestmark = pytest.mark.unit

STAFF_PAGES = {"/console/registration": {"admin", "registration"}, "/console/users": {"admin"},
               "/console/models": {"admin", "operator"}}


@pytest.fixture
def app(client: Any, device_verifier: None) -> Any:
    return client


@pytest.mark.parametrize("role", ["racer", "registration", "commentator", "operator", "admin"])
def test_each_staff_page_opens_for_its_roles_and_is_a_403_page_for_the_others(app: Any, users: Any, role: str) -> None:
    person = signed_in(app, users, f"{role}-person", role)
    nav = body(person.get("/")).split('data-testid="nav-links">')[1].split("</nav>")[0]
    for path, allowed in STAFF_PAGES.items():
        reply = person.get(path)
        if role in allowed:
            assert reply.status_code == 200, path
            assert f'href="{path}"' in nav
        else:
            assert reply.status_code == 403, path
            assert "Not allowed" in text(reply) and "This needs the role" in text(reply)
            assert f'href="{path}"' not in nav


def test_desk_creates_a_racer_shows_the_password_once_and_resets_the_form(app: Any, users: Any, aws_clients: Any,
                                                                          stack: Any) -> None:
    desk = signed_in(app, users, "dana", "registration")
    reply = post(desk, "/console/registration", {"username": "kim-1", "email": "kim@example.test",
                                                 "country_code": "de"}, htmx=True)
    assert reply.status_code == 201 and reply.headers["Cache-Control"] == "no-store"
    assert "<html" not in body(reply)  # htmx gets the desk fragment only
    password = body(reply).split('data-testid="temporary-password">')[1].split("<")[0]
    assert "Account kim-1 is ready." in text(reply) and len(password) == 16
    assert 'name="username" type="text" value=""' in body(reply) and "autofocus" in body(reply)
    assert 'value="Germany (DE)"' in body(reply)  # the country stays for the next racer
    reply = users.clients.cognito.initiate_auth(  # the flow the app client allows (the app's own sign-in)
        ClientId=stack.user_pool_client_id, AuthFlow="USER_PASSWORD_AUTH",
        AuthParameters={"USERNAME": "kim-1", "PASSWORD": password})
    assert reply["ChallengeName"] == "NEW_PASSWORD_REQUIRED"  # the racer must choose their own
    groups = aws_clients.cognito.admin_list_groups_for_user(UserPoolId=stack.user_pool_id, Username="kim-1")
    assert [g["GroupName"] for g in groups["Groups"]] == ["racer"]
    assert password not in body(desk.get("/console/registration"))  # shown once


def test_desk_refusals_sit_next_to_their_field(app: Any, users: Any) -> None:
    desk = signed_in(app, users, "dana", "registration")
    post(desk, "/console/registration", {"username": "kim", "email": "kim@example.test", "country_code": "SE"})
    taken = post(desk, "/console/registration", {"username": "kim", "email": "k2@example.test", "country_code": "SE"})
    assert taken.status_code == 409 and field_error(taken, "username") == "The user name &#39;kim&#39; is taken."
    assert 'value="k2@example.test"' in body(taken)
    bad = post(desk, "/console/registration", {"username": "lee", "email": "not-an-email", "country_code": "SE"})
    assert bad.status_code == 400 and field_error(bad, "email").startswith("Enter a valid email address")
    spaced = post(desk, "/console/registration", {"username": "a b", "email": "ab@example.test", "country_code": "SE"})
    assert field_error(spaced, "username") == str(escape(USERNAME_CHARS_MESSAGE))
    # The desk's length limit is sign-up's: a name sign-up would refuse is refused here too, with its message.
    long = post(desk, "/console/registration", {"username": "Mary-Kate_Longname_Racer", "email": "mk@example.test",
                                               "country_code": "SE"})
    assert long.status_code == 400 and field_error(long, "username") == USERNAME_LENGTH_MESSAGE


def test_admin_searches_changes_a_role_and_disables_a_user(app: Any, users: Any, aws_clients: Any,
                                                           stack: Any) -> None:
    admin = signed_in(app, users, "root", "admin")
    for name in ("sam", "sara", "tom"):
        users.create(name, ("racer",))
    rows = admin.get("/console/users/rows?q=sa")
    assert [r.split('"')[0] for r in body(rows).split('data-username="')[1:]] == ["sam", "sara"]
    refused = admin.get("/console/users/rows?q=%3Cscript%3E")
    assert refused.status_code == 400 and "Search with the start of a username" in text(refused)

    changed = post(admin, "/console/users/sam/role", {"role": "operator"}, htmx=True)
    assert changed.status_code == 200 and '<option value="operator" selected>' in body(changed)
    groups = aws_clients.cognito.admin_list_groups_for_user(UserPoolId=stack.user_pool_id, Username="sam")
    assert [g["GroupName"] for g in groups["Groups"]] == ["operator"]
    nonsense = post(admin, "/console/users/sam/role", {"role": "car"}, htmx=True)
    assert nonsense.status_code == 400 and "Choose one of" in text(nonsense)

    disabled = post(admin, "/console/users/tom/disable", htmx=True)
    assert "disabled" in text(disabled) and ">Enable</button>" in body(disabled)
    assert not aws_clients.cognito.admin_get_user(UserPoolId=stack.user_pool_id, Username="tom")["Enabled"]
    enabled = post(admin, "/console/users/tom/enable", htmx=True)
    assert "enabled" in text(enabled) and ">Disable</button>" in body(enabled)

    self_change = post(admin, "/console/users/root/role", {"role": "racer"}, htmx=True)
    assert self_change.status_code == 403 and "You cannot change your own role" in text(self_change)


def test_operator_filters_all_models_by_racer_and_status(app: Any, users: Any) -> None:
    operator = signed_in(app, users, "olga", "operator")
    ada = ModelsApi(app, bearer(users.access_token("ada", ("racer",))))
    bob = ModelsApi(app, bearer(users.access_token("bob", ("racer",))))
    ada.upload_and_complete("ada-fast.tar.gz", onnx_archive())
    ada.upload_and_complete("ada-broken.tar.gz", archive_without_metadata())
    bob.upload_and_complete("bob-fast.tar.gz", onnx_archive(bias=0.5))

    def names(reply: Any) -> list[str]:
        return [r.split('"')[0] for r in body(reply).split('data-model-name="')[1:]]

    assert sorted(names(operator.get("/console/models/rows"))) == ["ada-broken", "ada-fast", "bob-fast"]
    assert sorted(names(operator.get("/console/models/rows?racer=ad"))) == ["ada-broken", "ada-fast"]
    assert names(operator.get("/console/models/rows?status=AVAILABLE&racer=bob")) == ["bob-fast"]
    wrong = operator.get("/console/models/rows?status=SHINY")
    assert wrong.status_code == 400 and "Input should be" in text(wrong)


def test_operator_gives_models_to_a_car_and_sees_its_progress(app: Any, users: Any) -> None:
    operator = signed_in(app, users, "olga", "operator")
    ada = ModelsApi(app, bearer(users.access_token("ada", ("racer",))))
    good = ada.upload_and_complete("ada-fast.tar.gz", onnx_archive())
    broken = ada.upload_and_complete("ada-broken.tar.gz", archive_without_metadata())
    car = activate_device("car-7", make_fleet("fleet-1"))

    page = operator.get("/console/models")
    assert "car-7 (offline)" in text(page) and f'value="{good["model_id"]}"' in body(page)
    # The sensor and training algorithm in words (the page showed "FRONT_FACING_CAMERA · behaviour_cloning").
    assert "Front camera · Behaviour cloning" in text(page) and "FRONT_FACING_CAMERA" not in text(page)
    assert f'value="{broken["model_id"]}"' not in body(page)  # only AVAILABLE models are offered

    no_car = post(operator, "/console/models/assign", {"model_ids": good["model_id"]}, htmx=True)
    assert no_car.status_code == 400 and "Choose a car." in text(no_car)
    not_valid = post(operator, "/console/models/assign", {"device_id": car.device_id,
                                                          "model_ids": broken["model_id"]}, htmx=True)
    assert not_valid.status_code == 409 and "only AVAILABLE models can be given to a car" in text(not_valid)

    # Not scrutineered yet: staff are asked first (and nothing is sent), then may send it anyway.
    asked = post(operator, "/console/models/assign", {"device_id": car.device_id, "model_ids": good["model_id"]},
                 htmx=True)
    assert asked.status_code == 200 and "Models sent to the car." not in text(asked)
    assert "ada – ada-fast: not scrutineered yet (its test drive is queued)" in text(asked)
    assert 'data-testid="send-anyway"' in body(asked)
    assert "ada-fast" not in text(operator.get(f"/console/models/car-status?device_id={car.device_id}"))
    sent = post(operator, "/console/models/assign", {"device_id": car.device_id, "model_ids": good["model_id"],
                                                     "confirmed": "yes"}, htmx=True)
    assert sent.status_code == 200 and "Models sent to the car." in text(sent)
    assert "ada-fast ada assigned" in text(sent) and 'hx-trigger="every 2s"' in body(sent)

    car_api = ModelsApi(app, device_headers(car.credential))
    reported = car_api.call("POST", "/api/devices/self/assignment/status",
                            {"model_id": good["model_id"], "status": "failed", "reason": "disk full"})
    assert reported.status_code == 200
    status = operator.get(f"/console/models/car-status?device_id={car.device_id}")
    assert "ada-fast ada failed disk full" in text(status)


def test_staff_see_a_check_a_crash_cut_short_and_start_it_again_now(app: Any, users: Any) -> None:
    from chalicelib import services
    from chalicelib.domain.racer_models import ModelStatus

    operator = signed_in(app, users, "olga", "operator")
    ada = ModelsApi(app, bearer(users.access_token("ada", ("racer",))))
    uploaded = ada.upload("ada-cut.tar.gz", onnx_archive())
    store = services.model_service().store
    record = store.get_by_id(uploaded["model_id"])
    # What a kill -9 of the app during the check leaves: UPLOADED, its check started long ago.
    store.replace(record.model_copy(update={"check_started_at": "2026-01-01T09:00:00.000000Z", "check_attempts": 1}),
                  expected_status=ModelStatus.UPLOADED)

    rows = operator.get("/console/models/rows")
    assert "ada-cut" in text(rows) and "Check interrupted; it restarts by itself" in text(rows)
    assert 'data-testid="check-again"' in body(rows)
    racer = signed_in(app, users, "bob", "racer")
    assert post(racer, f"/console/models/{uploaded['model_id']}/check", htmx=True).status_code == 403

    checked = post(operator, f"/console/models/{uploaded['model_id']}/check", htmx=True)
    assert checked.status_code == 200 and "ada-cut Ready to race" in text(checked).replace("ada ", ""), text(checked)
    assert store.get_by_id(uploaded["model_id"]).status is ModelStatus.AVAILABLE


def _named(app: Any, users: Any, username: str, display_name: str) -> ModelsApi:
    token = users.access_token(username, ("racer",))
    named = app.http.put("/api/me/profile", body=json.dumps({"display_name": display_name}),
                         headers={**bearer(token), "Content-Type": "application/json"})
    assert named.status_code == 200, named.body
    return ModelsApi(app, bearer(token))


def test_the_models_page_names_racers_by_display_name_and_tells_two_bjorns_apart(app: Any, users: Any) -> None:
    """Issue 31: the Models page named racers by sign-in name (its rows, the assign checkboxes and a car's table).
    Now by display name, "Björn (bjorn_a)" where two listed racers are both Björn, and the racer box finds them by
    either name."""
    operator = signed_in(app, users, "olga", "operator")
    uploaded = {username: _named(app, users, username, name).upload_and_complete(f"{username}-fast.tar.gz",
                                                                                  onnx_archive(bias))
                for bias, (username, name) in enumerate((("bjorn_a", "Björn"), ("bjorn_b", "björn"),
                                                         ("yamada", "山田太郎")))}
    car = activate_device("car-7", make_fleet("fleet-1"))

    def racers(reply: Any) -> list[str]:
        return sorted(cell.split("</td>")[0].strip() for cell in body(reply).split('data-testid="model-racer">')[1:])

    page = operator.get("/console/models")
    assert racers(page) == ["Björn (bjorn_a)", "björn (bjorn_b)", "山田太郎"], racers(page)
    assert "Björn (bjorn_a) – bjorn_a-fast" in text(page) and "山田太郎 – yamada-fast" in text(page)
    assert racers(operator.get(f"/console/models/rows?racer={quote('山田')}")) == ["山田太郎"]
    assert racers(operator.get(f"/console/models/rows?racer={quote('BJÖ')}")) == ["Björn (bjorn_a)", "björn (bjorn_b)"]
    assert racers(operator.get("/console/models/rows?racer=bjorn_b")) == ["björn (bjorn_b)"]

    staff = bearer(users.access_token("olga-api", ("operator",)))
    sent = app.http.put(f"/api/cars/{car.device_id}/models", headers={**staff, "Content-Type": "application/json"},
                        body=json.dumps({"model_ids": [uploaded["bjorn_a"]["model_id"],
                                                       uploaded["yamada"]["model_id"]]}))
    assert sent.status_code == 200, sent.body
    # Only one Björn on this car: plain "Björn", as the table lists them together.
    status = text(operator.get(f"/console/models/car-status?device_id={car.device_id}"))
    assert "bjorn_a-fast Björn assigned" in status and "yamada-fast 山田太郎 assigned" in status, status


def test_the_scrutineering_warning_names_racers_by_display_name(app: Any, users: Any) -> None:
    """Issue 31: the Models page's "Not every model passed scrutineering" warning said "bjorn_a – bjorn_a-fast" (the
    sign-in name). Now the display name, told apart as the page does when two racers in the warning are both Björn."""
    operator = signed_in(app, users, "olga", "operator")
    uploaded = {username: _named(app, users, username, name).upload_and_complete(f"{username}-fast.tar.gz",
                                                                                  onnx_archive(bias))
                for bias, (username, name) in enumerate((("bjorn_a", "Björn"), ("bjorn_b", "björn"),
                                                         ("yamada", "山田太郎")))}
    car = activate_device("car-7", make_fleet("fleet-1"))

    def warning(*usernames: str) -> str:
        asked = post(operator, "/console/models/assign",
                     {"device_id": car.device_id, "model_ids": [uploaded[u]["model_id"] for u in usernames]},
                     htmx=True)
        assert asked.status_code == 200 and 'data-testid="send-anyway"' in body(asked)
        return text(asked)

    both = warning("bjorn_a", "bjorn_b")
    assert "Björn (bjorn_a) – bjorn_a-fast: not scrutineered yet" in both
    assert "björn (bjorn_b) – bjorn_b-fast: not scrutineered yet" in both
    alone = warning("bjorn_a", "yamada")
    assert "Björn – bjorn_a-fast: not scrutineered yet" in alone and "山田太郎 – yamada-fast" in alone
