"""What the deployed app may do on AWS: exactly the calls its storage adapters make, and nothing else.

tests/infra/test_iam_policy.py derives the calls from functions/chalicelib/storage/ and checks the synthesised role
against this table both ways (every call covered, no grant without a call), so a new adapter call without a
permission (a 502 under IAM) or a permission nobody uses fails in CI, not on event day.
Pure data (no aws_cdk import): stack.py builds the IAM statements from it.
"""
from __future__ import annotations

# DynamoDB actions on every table (and its indexes, for Query). TransactWriteItems has no IAM action of its own: it
# needs the item-level actions it performs (Put/Update/Delete/ConditionCheck) on each table it touches.
TABLE_ACTIONS: tuple[str, ...] = (
    "dynamodb:BatchGetItem",
    "dynamodb:ConditionCheckItem",
    "dynamodb:DeleteItem",
    "dynamodb:DescribeTable",
    "dynamodb:GetItem",
    "dynamodb:PutItem",
    "dynamodb:Query",
    "dynamodb:Scan",
    "dynamodb:UpdateItem",
)

# S3 object actions, per bucket logical name. Presigned POSTs (browser uploads) and GETs (cars) are signed with the
# role, so the role itself needs PutObject/GetObject. HeadObject is authorised as GetObject; CopyObject needs both.
BUCKET_OBJECT_ACTIONS: dict[str, tuple[str, ...]] = {
    "models": ("s3:DeleteObject", "s3:GetObject", "s3:PutObject"),
    # The learning booth's run artifacts (frames, controls, metadata, top-down picture): written, read, linked.
    "runs": ("s3:GetObject", "s3:PutObject"),
}
# ListBucket lets HeadObject/GetObject of a missing key answer 404 (NoSuchKey) instead of 403, which the upload
# completion relies on to say "the file never arrived".
BUCKET_ACTIONS: dict[str, tuple[str, ...]] = {
    "models": ("s3:ListBucket",),
    "runs": ("s3:ListBucket",),  # a run finalised before its controls arrived says so (404), not AccessDenied
}

# The Cognito admin API the app calls with its role. The user-facing calls (InitiateAuth, SignUp, ConfirmSignUp,
# RespondToAuthChallenge, ChangePassword, GlobalSignOut, DeleteUser, GetUser) are authorised by the user's own
# tokens or are public, and IAM does not evaluate them.
USER_POOL_ACTIONS: tuple[str, ...] = (
    "cognito-idp:AdminAddUserToGroup",
    "cognito-idp:AdminConfirmSignUp",  # (only a local stack confirms sign-ups itself; kept so the code path works)
    "cognito-idp:AdminCreateUser",
    "cognito-idp:AdminDeleteUser",
    "cognito-idp:AdminDisableUser",
    "cognito-idp:AdminEnableUser",
    "cognito-idp:AdminGetUser",
    "cognito-idp:AdminListGroupsForUser",
    "cognito-idp:AdminRemoveUserFromGroup",
    "cognito-idp:AdminSetUserPassword",  # a resumed staff registration hands out a new temporary password
    "cognito-idp:AdminUserGlobalSignOut",
    "cognito-idp:ListUsers",
    "cognito-idp:ListUsersInGroup",  # the registration repair reads the role groups' member lists
)
COGNITO_CALLS_WITHOUT_IAM: frozenset[str] = frozenset({
    "ChangePassword", "ConfirmSignUp", "DeleteUser", "GetUser", "GlobalSignOut", "InitiateAuth",
    "RespondToAuthChallenge", "SignUp",
})

# The functions read the stack's public URL from its one SSM parameter (chalicelib.storage.parameters).
PARAMETER_ACTIONS: tuple[str, ...] = ("ssm:GetParameter",)

# Lambda writes its logs through these, into log groups the stack creates (with retention) and names.
LOG_ACTIONS: tuple[str, ...] = ("logs:CreateLogStream", "logs:PutLogEvents")

# The live-page server's task role (drem_infra.live_pages): it renders the live regions from the materialised boards
# and overlays (leaderboards), the event (events) and the race behind an overlay (races), checks a car's credential
# when it sends its camera (fleet), checks that a staff session previewing a car's camera was not signed out or
# demoted since its token was issued (sessions: the user's revocation mark, one GetItem), and only reads. Per table
# logical name; tests/infra/test_iam_policy.py derives the same set from the live routes' reads and fails on any drift.
LIVE_TABLE_ACTIONS: dict[str, tuple[str, ...]] = {
    "events": ("dynamodb:GetItem",),
    "fleet": ("dynamodb:GetItem", "dynamodb:Query"),  # a car sending its camera: its credential and device record
    "leaderboards": ("dynamodb:BatchGetItem", "dynamodb:GetItem"),  # the adapter reads a big board's state parts
    "races": ("dynamodb:GetItem", "dynamodb:Query"),
    "sessions": ("dynamodb:GetItem",),  # a staff preview: the revocation mark of the session's user
}
# The read calls the live server may make at all (its contract: GetItem/Query/BatchGetItem through the adapters).
LIVE_READ_ACTIONS: frozenset[str] = frozenset({"dynamodb:GetItem", "dynamodb:Query", "dynamodb:BatchGetItem"})
