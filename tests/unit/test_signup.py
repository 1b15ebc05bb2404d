"""Self sign-up: DREM's username rules, countries, passwords, the unconfirmed → confirmed journey, code errors."""
from __future__ import annotations

import pytest
from botocore.exceptions import ClientError
from botocore.stub import Stubber

from chalicelib.core.errors import AccountNotReady, InvalidInput
from chalicelib.domain.countries import COUNTRY_CODES, normalise_country_code
from chalicelib.domain.names import USERNAME_CHARS_MESSAGE, USERNAME_LENGTH_MESSAGE
from chalicelib.storage.users import CognitoUserDirectory, translate_account_error
from tests.unit.conftest import PASSWORD
from tests.unit.users_helpers import call, error_message, groups_claim, sign_up_body

pytestmark = pytest.mark.unit


@pytest.mark.parametrize(("username", "message"), [
    ("a", USERNAME_LENGTH_MESSAGE),
    ("a" * 21, USERNAME_LENGTH_MESSAGE),
    ("fast racer", USERNAME_CHARS_MESSAGE),
    ("<script>", USERNAME_CHARS_MESSAGE),
    (".racer", "A sign-in name cannot start or end with '.', '_' or '-'."),
    ("racer_", "A sign-in name cannot start or end with '.', '_' or '-'."),
    ("-racer", "A sign-in name cannot start or end with '.', '_' or '-'."),
    ("fast._racer", "A sign-in name cannot have two of '.', '_' or '-' in a row."),
    ("fast__racer", "A sign-in name cannot have two of '.', '_' or '-' in a row."),
])
def test_each_sign_up_username_rule_has_its_own_message(client, username, message):
    status, body = call(client, "POST", "/api/signup", sign_up_body(username))
    assert status == 400
    assert error_message(body) == message
    assert body["error"]["field"] == "username"


def test_usernames_that_follow_every_rule_are_accepted(client):
    # "fast-racer" too: the registration desk accepts '-', so self sign-up must (issue 13, item 5).
    for username in ("ab", "Fast.Racer_9", "a" * 20, "fast-racer"):
        status, body = call(client, "POST", "/api/signup", sign_up_body(username))
        assert status == 201, body


def test_country_must_be_a_real_iso_code(client):
    assert len(COUNTRY_CODES) == 249
    assert normalise_country_code(" gb ") == "GB"
    status, body = call(client, "POST", "/api/signup", sign_up_body(country_code="UK"))
    assert status == 400
    assert body["error"]["field"] == "country_code"
    assert "'UK' is not an ISO 3166-1 alpha-2 country code" in error_message(body)


def test_weak_password_and_bad_email_are_explained(client):
    status, body = call(client, "POST", "/api/signup", sign_up_body(password="alllowercase"))
    assert (status, body["error"]["field"]) == (400, "password")
    assert "At least 8 characters" in error_message(body)
    status, body = call(client, "POST", "/api/signup", sign_up_body(email="not-an-email"))
    assert (status, body["error"]["field"]) == (400, "email")


def test_local_sign_up_is_ready_at_once_as_racer_and_no_code_confirms_anything(client, users):
    status, body = call(client, "POST", "/api/signup", sign_up_body("new.racer", country_code="de"))
    assert status == 201, body
    assert body["confirmed"] is True and "sign in now" in body["message"]

    # The old hole: moto confirmed any code. Locally no code exists, so every code is wrong.
    status, body = call(client, "POST", "/api/signup/confirm", {"username": "new.racer", "code": "123456"})
    assert status == 400 and body["error"]["field"] == "code"

    tokens = users.sign_in("new.racer")
    assert groups_claim(tokens["AccessToken"]) == ["racer"]
    status, profile = call(client, "GET", "/api/me/profile", token=tokens["AccessToken"])
    assert status == 200 and profile["country_code"] == "DE" and profile["username"] == "new.racer"


def test_on_aws_sign_up_waits_for_the_emailed_code_and_a_guess_does_not_confirm(aws_mode, client, users):
    from chalicelib import services

    status, body = call(client, "POST", "/api/signup", sign_up_body("new.racer"))
    assert status == 201 and body["confirmed"] is False and "confirmation code" in body["message"]

    status, body = call(client, "POST", "/api/signup/confirm", {"username": "new.racer", "code": "123456"})
    assert status == 400 and "code is wrong" in error_message(body)
    with pytest.raises(AccountNotReady, match="not confirmed"):
        services.identity_provider().sign_in("new.racer", PASSWORD)


def test_taken_name_is_a_conflict(client):
    assert call(client, "POST", "/api/signup", sign_up_body("taken"))[0] == 201
    status, body = call(client, "POST", "/api/signup", sign_up_body("taken"))
    assert status == 409
    assert error_message(body) == "The user name 'taken' is taken."


def _client_error(code: str) -> ClientError:
    return ClientError({"Error": {"Code": code, "Message": "whatever Cognito says"}}, "ConfirmSignUp")


def test_wrong_and_expired_codes_get_clear_messages():
    wrong = translate_account_error(_client_error("CodeMismatchException"), "new.racer")
    expired = translate_account_error(_client_error("ExpiredCodeException"), "new.racer")
    assert isinstance(wrong, InvalidInput) and wrong.field == "code"
    assert wrong.message == "That confirmation code is wrong; check the latest email and try again."
    assert isinstance(expired, InvalidInput) and "expired" in expired.message


def test_confirm_with_a_wrong_code_through_the_adapter():
    import boto3

    cognito = boto3.client("cognito-idp", region_name="us-east-1")
    directory = CognitoUserDirectory(cognito, "us-east-1_pool", "client-id")
    with Stubber(cognito) as stub:
        stub.add_client_error("confirm_sign_up", service_error_code="CodeMismatchException",
                              expected_params={"ClientId": "client-id", "Username": "new.racer",
                                               "ConfirmationCode": "000000"})
        with pytest.raises(InvalidInput, match="confirmation code is wrong") as raised:
            directory.confirm_sign_up("new.racer", "000000")
    assert raised.value.field == "code"


def test_confirm_needs_a_code(client):
    status, body = call(client, "POST", "/api/signup/confirm", {"username": "x"})
    assert status == 400 and body["error"]["field"] == "code"


def test_signing_up_again_finishes_a_sign_up_cut_off_before_its_profile_and_group(client, aws_clients, stack):
    aws_clients.cognito.sign_up(ClientId=stack.user_pool_client_id, Username="cut.off", Password=PASSWORD,
                                UserAttributes=[{"Name": "email", "Value": "cut.off@example.test"},
                                                {"Name": "custom:countryCode", "Value": "SE"}])
    status, body = call(client, "POST", "/api/signup", sign_up_body("cut.off"))
    assert status == 201, body
    assert body["message"].startswith("This sign-up was already started.")
    assert body["confirmed"] is True  # a local stack confirms sign-ups itself: no email could ever arrive
    groups = aws_clients.cognito.admin_list_groups_for_user(UserPoolId=stack.user_pool_id, Username="cut.off")
    assert [g["GroupName"] for g in groups["Groups"]] == ["racer"]
    assert call(client, "GET", "/api/profiles/cut.off")[0] == 200
