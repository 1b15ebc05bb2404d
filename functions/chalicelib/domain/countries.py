"""ISO 3166-1 alpha-2 country codes and their English names, for `custom:countryCode` and the country pickers.

The list comes from pycountry (a maintained copy of the ISO 3166 data, Debian's iso-codes), not from a hand list.
"""
from __future__ import annotations

from typing import Any

import pycountry

from chalicelib.core.errors import InvalidInput


def _short_name(country: Any) -> str:  # a pycountry record: its fields are set at run time
    # pycountry's `common_name` where ISO's is long or formal ("Bolivia" for "Bolivia, Plurinational State of").
    return str(getattr(country, "common_name", None) or country.name)


COUNTRY_NAMES: dict[str, str] = {c.alpha_2: _short_name(c) for c in pycountry.countries}
COUNTRY_CODES: frozenset[str] = frozenset(COUNTRY_NAMES)
# (code, "Sweden (SE)") sorted by name: a <select> finds a country as its name is typed.
COUNTRY_CHOICES: tuple[tuple[str, str], ...] = tuple(
    (code, f"{name} ({code})") for code, name in sorted(COUNTRY_NAMES.items(), key=lambda item: item[1].casefold()))


def _names_of(country: Any) -> set[str]:
    return {str(name) for name in (country.name, getattr(country, "common_name", None),
                                   getattr(country, "official_name", None)) if name}


# What a person may type in a country picker, casefolded → code: the code, every name pycountry knows ("Bolivia",
# "Bolivia, Plurinational State of") and the picker's own label ("Sweden (SE)").
_TYPED: dict[str, str] = {
    typed.casefold(): c.alpha_2
    for c in pycountry.countries
    for typed in (c.alpha_2, f"{_short_name(c)} ({c.alpha_2})", *_names_of(c))
}


def country_label(code: str | None) -> str:
    """"Sweden (SE)" for a known code; anything else (what someone typed and got refused) comes back unchanged."""
    value = code or ""
    name = COUNTRY_NAMES.get(value.upper())
    return f"{name} ({value.upper()})" if name else value


def country_code_from_text(text: str, *, field: str = "country_code") -> str:
    """The alpha-2 code of what was typed in a country picker: a code ("se"), a name ("sweden") or a label ("Sweden
    (SE)"), ignoring case and spaces around it. Anything else is InvalidInput naming the field: no guessing."""
    code = _TYPED.get(" ".join(text.split()).casefold())
    if code is None:
        raise InvalidInput(unknown_country_message(text), field=field)
    return code


def unknown_country_message(text: str) -> str:
    """What a country picker says when what was typed names no country."""
    typed = " ".join(text.split())
    if not typed:
        return "Choose a country: type its name or its two-letter code, e.g. Sweden or SE."
    return f"No country is called {typed!r}: type its name or its two-letter code (e.g. Sweden or SE) and pick it " \
           "from the list."


def country_name(code: str | None) -> str:
    return COUNTRY_NAMES.get((code or "").upper(), code or "")


def normalise_country_code(value: str, *, field: str = "country_code") -> str:
    """The upper-case alpha-2 code, or InvalidInput naming the field (e.g. 'UK' is not a code: Britain is 'GB')."""
    code = value.strip().upper()
    if code not in COUNTRY_CODES:
        raise InvalidInput(f"{value!r} is not an ISO 3166-1 alpha-2 country code (e.g. GB, US, DE, SE).",
                           field=field)
    return code
