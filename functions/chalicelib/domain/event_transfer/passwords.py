"""Passwords of the accounts an import creates: generated ones, the pool's policy, and the `--password-file`."""
from __future__ import annotations

import json
import secrets
import string

from chalicelib.domain.errors import InvalidInput

_SYMBOLS = "!#%*+-=?@^_"


def temporary_password(length: int = 16) -> str:
    """Meets the pool's policy: at least 8 characters with lower, upper, digit and symbol."""
    classes = [string.ascii_lowercase, string.ascii_uppercase, string.digits, _SYMBOLS]
    chars = [secrets.choice(c) for c in classes] + [secrets.choice("".join(classes)) for _ in range(length - 4)]
    secrets.SystemRandom().shuffle(chars)
    return "".join(chars)


def password_problem(password: str) -> str | None:
    checks = [(len(password) >= 8, "is shorter than 8 characters"),
              (any(c.islower() for c in password), "has no lower-case letter"),
              (any(c.isupper() for c in password), "has no upper-case letter"),
              (any(c.isdigit() for c in password), "has no digit"),
              (any(not c.isalnum() for c in password), "has no symbol")]
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
