"""Telling racers with the same display name apart (issue 31: two racers both called "Björn").

Display names are not unique (real names repeat); sign-in names are (case-insensitively). Wherever racers are shown
together (a board, a results table, a CSV, an event's certificates), a display name that another of them also goes by
(compared after NFC and case folding, so "björn", "Björn" and "Bjo\u0308rn" are the same name) is shown with the
racer's sign-in name after it: "Björn (bjorn_a)" and "Björn (bjorn_b)". A name nobody else there goes by is shown as
it is. Display names cannot contain parentheses, so a told-apart name never equals anyone's display name.
"""
from __future__ import annotations

import unicodedata
from collections import Counter
from collections.abc import Mapping


def name_key(name: str) -> str:
    """What two names are compared by: NFC, then case-folded ("Straße" and "STRASSE" are the same)."""
    return unicodedata.normalize("NFC", unicodedata.normalize("NFC", name).casefold())


def with_sign_in_name(display_name: str, sign_in_name: str) -> str:
    return f"{display_name} ({sign_in_name})"


def told_apart(names: Mapping[str, tuple[str, str]]) -> dict[str, str]:
    """{racer id: (display name, sign-in name)} of racers shown together → {racer id: the name to show}."""
    counts = Counter(name_key(display) for display, _ in names.values())
    return {racer: with_sign_in_name(display, sign_in) if counts[name_key(display)] > 1 else display
            for racer, (display, sign_in) in names.items()}
