"""Who sends the user pool's emails (sign-up codes, password resets): Amazon SES when `make deploy` is given
SES_FROM and SES_IDENTITY_ARN, otherwise Cognito's default sender with a warning at deploy time, because self
sign-up depends on that email and the default sender allows only a few dozen a day. Storage-only stacks: no app
packaging, so these synthesise in seconds."""
from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

os.environ.setdefault("JSII_SILENCE_WARNING_END_OF_LIFE_NODE_VERSION", "20")

from drem_infra import resources  # noqa: E402

pytestmark = pytest.mark.infra

REPO_ROOT = Path(__file__).resolve().parents[2]
SENDER = "drem <drem@example.org>"
IDENTITY = "arn:aws:ses:eu-west-1:123456789012:identity/example.org"


def _synth(tmp_path: Path, **email: str):
    import aws_cdk as cdk
    from aws_cdk.assertions import Annotations, Match, Template

    from drem_infra.stack import DremStack

    app = cdk.App(outdir=str(tmp_path / "cdk.out"))
    stack = DremStack(app, "drem-email", stage="email", **email)
    template = Template.from_stack(stack)
    [pool] = template.find_resources("AWS::Cognito::UserPool").values()
    warnings = [str(w.entry.data) for w in Annotations.from_stack(stack).find_warning("*", Match.any_value())]
    return pool["Properties"], warnings


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
