"""ISO 3166-1 alpha-2 country codes and their English names, for `custom:countryCode` and the country pickers.

The list comes from pycountry (a maintained copy of the ISO 3166 data, Debian's iso-codes), not from a hand list.
"""
from __future__ import annotations

from typing import Any

import pycountry

from chalicelib.domain.errors import InvalidInput


def _short_name(country: Any) -> str:  # a pycountry record: its fields are set at run time
    # pycountry's `common_name` where ISO's is long or formal ("Bolivia" for "Bolivia, Plurinational State of").
    return str(getattr(country, "common_name", None) or country.name)


COUNTRY_NAMES: dict[str, str] = {c.alpha_2: _short_name(c) for c in pycountry.countries}
COUNTRY_CODES: frozenset[str] = frozenset(COUNTRY_NAMES)
# (code, "Sweden (SE)") sorted by name: a <select> finds a country as its name is typed.
COUNTRY_CHOICES: tuple[tuple[str, str], ...] = tuple(
    (code, f"{name} ({code})") for code, name in sorted(COUNTRY_NAMES.items(), key=lambda item: item[1].casefold()))


def country_name(code: str | None) -> str:
    return COUNTRY_NAMES.get((code or "").upper(), code or "")


def normalise_country_code(value: str, *, field: str = "country_code") -> str:
    """The upper-case alpha-2 code, or InvalidInput naming the field (e.g. 'UK' is not a code: Britain is 'GB')."""
    code = value.strip().upper()
    if code not in COUNTRY_CODES:
        raise InvalidInput(f"{value!r} is not an ISO 3166-1 alpha-2 country code (e.g. GB, US, DE, SE).",
                           field=field)
    return code
