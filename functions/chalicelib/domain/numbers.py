"""Whole numbers typed by people (query strings, path parts, form fields), read without trusting them.

`str.isdigit()` accepts '²' and '٣' (which `int()` then refuses or reads differently), and `int()` refuses strings
of more than 4,300 digits with a ValueError (CPython's int/str conversion limit): both used to end in a 500. Here
only ASCII digits count, the length is bounded before converting, and every refusal is an InvalidInput (400)."""
from __future__ import annotations

import re

from chalicelib.core.errors import InvalidInput


def whole_number(raw: str | None, *, field: str, message: str, maximum: int, minimum: int = 0) -> int:
    """`raw` as an int in [minimum, maximum], or InvalidInput(message, field)."""
    digits = len(str(maximum))
    text = raw.strip() if isinstance(raw, str) else ""
    if not re.fullmatch(rf"[0-9]{{1,{digits}}}", text):
        raise InvalidInput(message, field=field)
    value = int(text)
    if not minimum <= value <= maximum:
        raise InvalidInput(message, field=field)
    return value


MAX_LAP_NUMBER = 9_999  # far beyond any race; a lap id is its index in the race (0 is the first lap)


def lap_number(raw: str) -> int:
    return whole_number(raw, field="lap_id", message="The lap id is a whole number (0 is the first lap).",
                        maximum=MAX_LAP_NUMBER)
