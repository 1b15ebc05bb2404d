"""The two names of a racer: the sign-in name (simple, ASCII, unique whatever its case) and the display name (the
racer's real name in any script, shown on boards, overlays, PDFs and statistics).

One rule each, used by the registration desk and self sign-up alike, so a name one accepts the other never refuses.
"""
from __future__ import annotations

import re
import unicodedata

import regex  # type: ignore[import-untyped]  # no stubs in the dev lock; one call, typed below

from chalicelib.core.errors import InvalidInput

USERNAME_MIN, USERNAME_MAX = 2, 20
DISPLAY_NAME_MAX = 40
USERNAME_LENGTH_MESSAGE = f"A sign-in name has {USERNAME_MIN} to {USERNAME_MAX} characters."
USERNAME_CHARS_MESSAGE = ("A sign-in name may contain only the letters a–z and A–Z, digits, '.', '_' and '-'; "
                          "write your name as you spell it under Display name.")
_USERNAME_CHARS = re.compile(r"^[a-zA-Z0-9._-]+$")

# Characters that reorder text around them (the "Trojan Source" set, plus the Arabic letter mark): a name holding
# one could show as something else on the big screen. Refused with their own message, before the general rule.
_BIDI_CONTROLS = frozenset("\u061c\u200e\u200f\u202a\u202b\u202c\u202d\u202e\u2066\u2067\u2068\u2069")
# Apostrophes and hyphens people write in names (O'Brien, O’Brien, Jean-Luc with U+2010), the middle dot of Catalan
# (l·l) and the Japanese middle dot (・); '.' and '_' because racers' handles use them (Zoë.Müller, Björn_Andersson).
_NAME_PUNCTUATION = frozenset("'’‘-‐‑·・._")
_GRAPHEME = regex.compile(r"\X")


def check_sign_in_name(username: str) -> str:
    """The sign-in name rule of self sign-up and the desk, one message per broken rule."""
    if not USERNAME_MIN <= len(username) <= USERNAME_MAX:
        raise InvalidInput(USERNAME_LENGTH_MESSAGE, field="username")
    if not _USERNAME_CHARS.match(username):
        raise InvalidInput(USERNAME_CHARS_MESSAGE, field="username")
    if username[0] in "._-" or username[-1] in "._-":
        raise InvalidInput("A sign-in name cannot start or end with '.', '_' or '-'.", field="username")
    if re.search(r"[._-]{2}", username):
        raise InvalidInput("A sign-in name cannot have two of '.', '_' or '-' in a row.", field="username")
    return username


def grapheme_count(text: str) -> int:
    """User-perceived characters: 'é' written as e + U+0301 is one, so is a Hangul syllable spelt in jamo."""
    clusters: list[str] = _GRAPHEME.findall(text)
    return len(clusters)


def check_display_name(value: str) -> str:
    """A racer's name as they write it: letters and marks of any script, digits, spaces, apostrophes, hyphens.

    NFC-normalised (so 'é' typed either way is stored, compared and drawn the same), runs of spaces collapsed."""
    name = " ".join(unicodedata.normalize("NFC", value).split())
    if any(c in _BIDI_CONTROLS for c in value):
        raise InvalidInput("A display name cannot contain text-direction control characters; type the name "
                           "as it is written.", field="display_name")
    if not 1 <= grapheme_count(name) <= DISPLAY_NAME_MAX:
        raise InvalidInput(f"A display name has 1 to {DISPLAY_NAME_MAX} characters.", field="display_name")
    for char in name:
        category = unicodedata.category(char)
        if not (category[0] in "LM" or category == "Nd" or char == " " or char in _NAME_PUNCTUATION):
            raise InvalidInput("A display name may contain letters and accents of any script, digits, spaces, "
                               "apostrophes, hyphens, '.' and '_'.", field="display_name")
    if unicodedata.category(name[0])[0] == "M":
        raise InvalidInput("A display name cannot start with an accent on its own.", field="display_name")
    return name

