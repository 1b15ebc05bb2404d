"""`drem users`: list, register, change the role of, disable or enable accounts, through the drem HTTP API."""
from __future__ import annotations

import argparse
import json
import sys
from urllib.parse import quote

HELP = "manage user accounts (list, create, role, disable, enable) through the drem API"
ROLES = ("admin", "operator", "commentator", "registration", "racer")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from drem_local.api_client import add_connection_arguments

    add_connection_arguments(parser)
    parser.add_argument("--json", action="store_true", help="print the API's JSON answer")
    actions = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    listing = actions.add_parser("list", help="list users (newest pages first as Cognito returns them)")
    listing.add_argument("--prefix", help="only usernames starting with this")
    create = actions.add_parser("create", help="register a racer; prints a temporary password once")
    # dest "target": --username is who signs in (the connection arguments), USERNAME is who is acted on.
    create.add_argument("target", metavar="USERNAME")
    create.add_argument("--email", required=True)
    create.add_argument("--country", required=True, help="ISO 3166-1 alpha-2 code, e.g. GB")
    create.add_argument("--display-name", default="",
                        help="the racer's name as they write it, in any script (default: the sign-in name)")
    role = actions.add_parser("role", help="make ROLE the user's only role")
    role.add_argument("target", metavar="USERNAME")
    role.add_argument("role", choices=ROLES)
    for name, what in (("disable", "stop a user from signing in"), ("enable", "let a disabled user sign in")):
        actions.add_parser(name, help=what).add_argument("target", metavar="USERNAME")


def run(args: argparse.Namespace) -> int:
    from drem_local.api_client import ApiClient, ApiError

    try:
        answer = _perform(ApiClient.from_args(args), args)
    except ApiError as exc:
        print(f"drem users {args.action}: {exc}", file=sys.stderr)
        return 1
    print(json.dumps(answer, indent=2) if args.json else describe(args.action, answer))
    return 0


def _perform(client, args: argparse.Namespace) -> dict:
    user = quote(getattr(args, "target", "") or "", safe="")
    if args.action == "list":
        return _all_pages(client, args.prefix)
    if args.action == "create":
        return client.request("POST", "/api/users",
                              json={"username": args.target, "email": args.email, "country_code": args.country,
                                    "display_name": args.display_name})
    if args.action == "role":
        return client.request("PUT", f"/api/users/{user}/role", json={"role": args.role})
    return client.request("POST", f"/api/users/{user}/{args.action}")


def _all_pages(client, prefix: str | None) -> dict:
    users, token = [], None
    while True:
        query = {k: v for k, v in (("prefix", prefix), ("next", token)) if v}
        page = client.request("GET", "/api/users", params=query)
        users += page["users"]
        token = page.get("next_token")
        if not token:
            return {"users": users}


def describe(action: str, answer: dict) -> str:
    if action == "list":
        if not answer["users"]:
            return "No users match."
        rows = [f"{u['username']:<24} {u.get('country_code') or '--':<3} {u['status']:<22} "
                f"{'enabled' if u['enabled'] else 'DISABLED'}  {u.get('email') or ''}" for u in answer["users"]]
        return "\n".join(rows)
    if action == "create":
        shown = answer.get("display_name") or answer["username"]
        named = f" for {shown}" if shown != answer["username"] else ""
        return (f"Created racer {answer['username']}{named} ({answer['country_code']}).\n"
                f"Temporary password (shown once; they choose their own at first sign-in): "
                f"{answer['temporary_password']}")
    if action == "role":
        return f"{answer['username']} is now {answer['role']}."
    return f"{answer['username']} is {'enabled' if answer['enabled'] else 'disabled'}."
