"""Passwords of the accounts an import creates: the pool's policy (generated ones come from it too,
`PasswordPolicy.random_password`), and the `--password-file`."""
from __future__ import annotations

import json

from chalicelib.core.errors import InvalidInput
from drem_infra import resources


def password_problem(password: str) -> str | None:
    policy = resources.USER_POOL.password_policy
    checks = [(len(password) >= policy.minimum_length, f"is shorter than {policy.minimum_length} characters"),
              (not policy.require_lowercase or any(c.islower() for c in password), "has no lower-case letter"),
              (not policy.require_uppercase or any(c.isupper() for c in password), "has no upper-case letter"),
              (not policy.require_digits or any(c.isdigit() for c in password), "has no digit"),
              (not policy.require_symbols or any(not c.isalnum() for c in password), "has no symbol")]
    return next((problem for ok, problem in checks if not ok), None)


def parse_password_file(text: str) -> dict[str, str]:
    """`{"username": "password", ...}` JSON, or lines `username password` (blank lines and # comments skipped)."""
    stripped = text.strip()
    if stripped.startswith("{"):
        try:
            data = json.loads(stripped)
        except (ValueError, RecursionError):
            raise InvalidInput("The password file is not valid JSON.", field="password_file") from None
        if not isinstance(data, dict) or not all(isinstance(k, str) and isinstance(v, str) for k, v in data.items()):
            raise InvalidInput("The password file must map usernames to password strings.", field="password_file")
        return data
    passwords: dict[str, str] = {}
    for number, line in enumerate(text.splitlines(), 1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        parts = line.split(None, 1)
        if len(parts) != 2:
            raise InvalidInput(f"Password file line {number}: use 'username password'.", field="password_file")
        passwords[parts[0]] = parts[1].strip()
    return passwords
