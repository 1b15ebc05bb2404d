"""Per-object access rules ("racer A may change only racer A's model").

Route declarations (`chalicelib.auth.access.route(..., allow=...)`) answer "who may call this URL at all". Whether the
caller may touch *this* object depends on data the route does not have, so services check it here, after loading
the object, and raise `Forbidden` the same way everywhere.
"""
from __future__ import annotations

from collections.abc import Iterable

from chalicelib.core.errors import Forbidden
from chalicelib.core.principals import Principal, Role


def require_owner_or_role(principal: Principal, owner_sub: str, roles: Iterable[Role]) -> None:
    """Allow the owner of an object, or anyone holding one of `roles` (e.g. staff acting for a racer)."""
    if principal.sub is not None and principal.sub == owner_sub:
        return
    if principal.roles & frozenset(roles):
        return
    raise Forbidden("This belongs to another user.")
