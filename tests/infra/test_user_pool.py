"""The user pool's app client allows exactly the sign-in flows the app calls, and no OAuth; and who sends the
pool's emails (sign-up codes, password resets): Amazon SES when `make deploy` is given
SES_FROM and SES_IDENTITY_ARN, otherwise Cognito's default sender with a warning at deploy time, because self
sign-up depends on that email and the default sender allows only a few dozen a day. Storage-only stacks: no app
packaging, so these synthesise in seconds."""
from __future__ import annotations

import os
import re
import subprocess
from pathlib import Path

import pytest

os.environ.setdefault("JSII_SILENCE_WARNING_END_OF_LIFE_NODE_VERSION", "20")

from drem_infra import resources  # noqa: E402

pytestmark = pytest.mark.infra

REPO_ROOT = Path(__file__).resolve().parents[2]
SENDER = "drem <drem@example.org>"
IDENTITY = "arn:aws:ses:eu-west-1:123456789012:identity/example.org"


STORAGE_ADAPTERS = REPO_ROOT / "functions" / "chalicelib" / "storage"
# Every way the code could sign in or be sent to a hosted UI / OAuth endpoint.
_AUTH_FLOW_ARGUMENT = re.compile(r"AuthFlow=\"([A-Z_]+)\"")
_OAUTH_USE = re.compile(r"/oauth2/|/login\?client_id|amazoncognito\.com|response_type=(code|token)")


def _synth_template(tmp_path: Path, **email: str):
    import aws_cdk as cdk
    from aws_cdk.assertions import Annotations, Match, Template

    from drem_infra.stack import DremStack

    app = cdk.App(outdir=str(tmp_path / "cdk.out"))
    stack = DremStack(app, "drem-email", stage="email", **email)
    template = Template.from_stack(stack)
    warnings = [str(w.entry.data) for w in Annotations.from_stack(stack).find_warning("*", Match.any_value())]
    return template, warnings


def _synth(tmp_path: Path, **email: str):
    template, warnings = _synth_template(tmp_path, **email)
    [pool] = template.find_resources("AWS::Cognito::UserPool").values()
    return pool["Properties"], warnings


def _code_files() -> list[Path]:
    roots = [REPO_ROOT / "functions" / "chalicelib", REPO_ROOT / "web", REPO_ROOT / "local", REPO_ROOT / "cars"]
    return [path for root in roots for path in root.rglob("*") if path.suffix in (".py", ".html", ".js")
            and "vendor" not in path.parts and "node_modules" not in path.parts]


def test_the_web_client_allows_exactly_the_flows_the_app_calls_and_no_oauth(tmp_path):
    called = {flow for path in STORAGE_ADAPTERS.glob("*.py") for flow in _AUTH_FLOW_ARGUMENT.findall(path.read_text())}
    template, _ = _synth_template(tmp_path)
    [client] = [c["Properties"] for c in template.find_resources("AWS::Cognito::UserPoolClient").values()]

    assert called == {"USER_PASSWORD_AUTH", "REFRESH_TOKEN_AUTH"}  # what chalicelib.storage signs in with today
    assert sorted(client["ExplicitAuthFlows"]) == sorted(f"ALLOW_{flow}" for flow in called)
    # No hosted UI anywhere in the code, so the client has no OAuth at all: no implicit grant, no example.com.
    assert [str(p) for p in _code_files() if _OAUTH_USE.search(p.read_text(errors="replace"))] == []
    assert client["AllowedOAuthFlowsUserPoolClient"] is False
    assert not {"AllowedOAuthFlows", "AllowedOAuthScopes", "CallbackURLs", "LogoutURLs"} & set(client)
    assert not template.find_resources("AWS::Cognito::UserPoolDomain")  # no hosted UI domain either


def test_without_ses_cognito_sends_and_the_deploy_warns_when_racers_sign_up_themselves(tmp_path):
    from drem_infra.stack import DEFAULT_SENDER_WARNING

    pool, warnings = _synth(tmp_path)

    assert "EmailConfiguration" not in pool  # Cognito's default sender, as before
    assert resources.USER_POOL.self_sign_up
    assert [w for w in warnings if w.startswith(DEFAULT_SENDER_WARNING)] != []
    assert "SES_FROM" in DEFAULT_SENDER_WARNING and "SES_IDENTITY_ARN" in DEFAULT_SENDER_WARNING


def test_with_ses_the_pool_sends_from_the_verified_identity_and_nothing_warns(tmp_path):
    pool, warnings = _synth(tmp_path, ses_from=SENDER, ses_identity_arn=IDENTITY)

    assert pool["EmailConfiguration"] == {"EmailSendingAccount": "DEVELOPER", "From": SENDER, "SourceArn": IDENTITY}
    assert not [w for w in warnings if "SES_FROM" in w]


@pytest.mark.parametrize(("email", "complaint"), [
    ({"ses_from": SENDER}, "go together"),
    ({"ses_identity_arn": IDENTITY}, "go together"),
    ({"ses_from": "drem at example.org", "ses_identity_arn": IDENTITY}, "is not an email address"),
    ({"ses_from": SENDER, "ses_identity_arn": "arn:aws:iam::123456789012:role/ses"}, "is not an SES identity ARN"),
])
def test_a_half_or_wrong_ses_option_stops_the_synth_with_what_to_fix(tmp_path, email, complaint):
    with pytest.raises(ValueError, match=complaint):
        _synth(tmp_path, **email)


def test_make_deploy_passes_the_ses_options_to_cdk():
    dry_run = subprocess.run(["make", "-n", "deploy", "STAGE=mail", f"SES_FROM={SENDER}",
                              f"SES_IDENTITY_ARN={IDENTITY}"], cwd=REPO_ROOT, capture_output=True, text=True,
                             timeout=60)
    assert dry_run.returncode == 0, dry_run.stderr
    deploys = [line for line in dry_run.stdout.splitlines() if "cdk deploy drem-mail" in line]
    assert deploys and all(f"-c ses_from='{SENDER}' -c ses_identity_arn={IDENTITY}" in line for line in deploys)
