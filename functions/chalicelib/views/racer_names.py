"""How a page names the racers it lists together: by display name, told apart by sign-in name where two collide
(drem_leaderboard.names), from one batch profile read per page (ProfileService.public_by_subs), never one per row."""
from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping

from chalicelib.domain.profiles import PublicProfile
from drem_leaderboard.names import told_apart

# {sub: public profile} of many racers at once (ProfileService.public_by_subs): one batch read per page or poll.
ProfilesBySub = Callable[[list[str]], Mapping[str, PublicProfile]]


def shown_racer_names(owners: Iterable[tuple[str, str]], profiles: ProfilesBySub) -> dict[str, str]:
    """{sub: the name the page shows} for (sub, sign-in name) pairs: the display name, with the sign-in name after it
    when another racer on the page goes by the same one; a racer without a profile is named by the sign-in name."""
    signed_in = dict(owners)
    public = profiles(list(signed_in)) if signed_in else {}
    return told_apart({sub: (p.display_name or p.username, p.username) if (p := public.get(sub)) else (name, name)
                       for sub, name in signed_in.items()})
