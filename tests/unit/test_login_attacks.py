"""Attacks on sign-in, tried as a racer on the venue WiFi would: editing the new-password step to take over another
account, and `next=` links that bounce a freshly signed-in user to another site."""
from __future__ import annotations

import base64
import json
from urllib.parse import quote

import pytest

from tests.unit.conftest import PASSWORD

pytestmark = pytest.mark.unit

TEMPORARY = "Temporary-Pass-1"
ATTACKER_CHOICE = "Attacker-Owns-9"


def _login(browser, username: str, password: str = PASSWORD, next_path: str = "/"):
    browser.get("/login")
    return browser.post("/login", {"username": username, "password": password, "next": next_path,
                                   "csrf_token": browser.csrf_token})


def _set_new_password(browser, password: str = ATTACKER_CHOICE):
    return browser.post("/login/new-password", {"new_password": password, "confirm_password": password,
                                                "csrf_token": browser.csrf_token})


@pytest.fixture
def racer_with_temporary_password(users):
    users.create("admin", ("admin",))
    users.create("mallory", ("racer",), password=TEMPORARY, temporary=True)
    return "mallory"


def _admin_password_still_works(users) -> bool:
    try:
        users.sign_in("admin")
    except Exception:
        return False
    return True


def test_challenge_cookie_holds_no_username_or_session(browser, racer_with_temporary_password):
    _login(browser, "mallory", TEMPORARY)

    value = browser.cookies["drem_challenge"]
    assert "mallory" not in value
    with pytest.raises(ValueError):  # the old cookie was base64 JSON; now it is an opaque random id
        json.loads(base64.urlsafe_b64decode(value + "=="))


def test_editing_the_challenge_cookie_cannot_set_the_admins_password(browser, users,
                                                                      racer_with_temporary_password):
    _login(browser, "mallory", TEMPORARY)
    # The pre-fix cookie format, naming the admin, with a real Cognito session of the attacker's own step.
    own_session = users.clients.cognito.initiate_auth(
        AuthFlow="USER_PASSWORD_AUTH", ClientId=users.outputs.user_pool_client_id,
        AuthParameters={"USERNAME": "mallory", "PASSWORD": TEMPORARY})["Session"]
    browser.cookies["drem_challenge"] = base64.urlsafe_b64encode(
        json.dumps({"username": "admin", "session": own_session}).encode()).decode()

    response = _set_new_password(browser)

    assert response.status_code == 200 and "has expired" in response.body.decode()
    assert _admin_password_still_works(users)
    assert "drem_session" not in browser.cookies


def test_a_guessed_or_foreign_challenge_id_is_refused(browser, users, racer_with_temporary_password):
    _login(browser, "mallory", TEMPORARY)
    browser.cookies["drem_challenge"] = "x" * 43

    assert "has expired" in _set_new_password(browser).body.decode()
    assert _admin_password_still_works(users)


def test_a_used_challenge_cannot_be_replayed(browser, users, racer_with_temporary_password):
    _login(browser, "mallory", TEMPORARY)
    used_id = browser.cookies["drem_challenge"]
    assert _set_new_password(browser).status_code == 303

    browser.cookies.clear()
    browser.get("/login")
    browser.cookies["drem_challenge"] = used_id
    response = _set_new_password(browser, "Another-Pass-7")

    assert "has expired" in response.body.decode()
    assert users.sign_in("mallory", ATTACKER_CHOICE)["AccessToken"]


def test_local_cognito_binds_the_challenge_session_to_its_user(users, racer_with_temporary_password):
    # Even straight at the (patched) local Cognito, a session of mallory's cannot set admin's password: real
    # Cognito answers "Invalid session for the user", and so does drem's local one.
    from botocore.exceptions import ClientError

    cognito, client_id = users.clients.cognito, users.outputs.user_pool_client_id
    session = cognito.initiate_auth(AuthFlow="USER_PASSWORD_AUTH", ClientId=client_id,
                                    AuthParameters={"USERNAME": "mallory", "PASSWORD": TEMPORARY})["Session"]
    with pytest.raises(ClientError) as refused:
        cognito.respond_to_auth_challenge(ClientId=client_id, ChallengeName="NEW_PASSWORD_REQUIRED", Session=session,
                                          ChallengeResponses={"USERNAME": "admin", "NEW_PASSWORD": ATTACKER_CHOICE})
    assert refused.value.response["Error"]["Code"] == "NotAuthorizedException"
    assert _admin_password_still_works(users)


OPEN_REDIRECTS = [
    "//evil.example/x", "https://evil.example", "http:evil.example", "javascript:alert(1)", "/\\evil.example",
    "\\\\evil.example", "/\t/evil.example", "/%09/evil.example", "/%5Cevil.example", "/%2F%2Fevil.example",
    "/%252F%252Fevil.example", "%2F%2Fevil.example", "/\n/evil.example", "/%0D%0ALocation:%20//evil.example",
    " //evil.example", "///evil.example", "/ /evil.example", "evil.example",
]


@pytest.mark.parametrize("next_path", OPEN_REDIRECTS)
def test_sign_in_never_redirects_off_site(browser, users, next_path):
    users.create("carol")

    page = browser.get("/login?next=" + quote(next_path, safe=""))
    posted = _login(browser, "carol", next_path=next_path)

    assert 'name="next" value="/"' in page.body.decode()
    assert posted.status_code == 303 and posted.headers["Location"] == "/"


@pytest.mark.parametrize("next_path", ["/api/me", "/races?event=e-1&x=%2F", "/console/users#top"])
def test_sign_in_still_returns_to_same_site_pages(browser, users, next_path):
    users.create("carol")

    assert _login(browser, "carol", next_path=next_path).headers["Location"] == next_path
