"""ISO 3166-1 alpha-2 country codes (all 249 officially assigned codes), for `custom:countryCode`.

Kept as data here because Python has no built-in list and one frozenset is not worth a dependency. Source: the
ISO 3166 Maintenance Agency's officially assigned codes (2024); compare with tzdata's `iso3166.tab` when updating.
"""
from __future__ import annotations

from chalicelib.domain.errors import InvalidInput

COUNTRY_CODES: frozenset[str] = frozenset("""
AD AE AF AG AI AL AM AO AQ AR AS AT AU AW AX AZ
BA BB BD BE BF BG BH BI BJ BL BM BN BO BQ BR BS BT BV BW BY BZ
CA CC CD CF CG CH CI CK CL CM CN CO CR CU CV CW CX CY CZ
DE DJ DK DM DO DZ
EC EE EG EH ER ES ET
FI FJ FK FM FO FR
GA GB GD GE GF GG GH GI GL GM GN GP GQ GR GS GT GU GW GY
HK HM HN HR HT HU
ID IE IL IM IN IO IQ IR IS IT
JE JM JO JP
KE KG KH KI KM KN KP KR KW KY KZ
LA LB LC LI LK LR LS LT LU LV LY
MA MC MD ME MF MG MH MK ML MM MN MO MP MQ MR MS MT MU MV MW MX MY MZ
NA NC NE NF NG NI NL NO NP NR NU NZ
OM
PA PE PF PG PH PK PL PM PN PR PS PT PW PY
QA
RE RO RS RU RW
SA SB SC SD SE SG SH SI SJ SK SL SM SN SO SR SS ST SV SX SY SZ
TC TD TF TG TH TJ TK TL TM TN TO TR TT TV TW TZ
UA UG UM US UY UZ
VA VC VE VG VI VN VU
WF WS
YE YT
ZA ZM ZW
""".split())


def normalise_country_code(value: str, *, field: str = "country_code") -> str:
    """The upper-case alpha-2 code, or InvalidInput naming the field (e.g. 'UK' is not a code: Britain is 'GB')."""
    code = value.strip().upper()
    if code not in COUNTRY_CODES:
        raise InvalidInput(f"{value!r} is not an ISO 3166-1 alpha-2 country code (e.g. GB, US, DE, SE).",
                           field=field)
    return code
